"""python -m scenarios map {import, check, repair, show}: flux maps from FEM tools, whether the FMUs accept
them and a repaired map they do, and the machine at a glance."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scenarios.core.constants import U_DC_NOMINAL_V
from scenarios.maps.error import MapImportError

#: exit status for bad input, as the other subcommands
EXIT_BAD_INPUT = 2


def add_parser(sub) -> None:
    mp = sub.add_parser("map", help="flux maps: import a FEM tool's export to the contract CSV; show a machine")
    msub = mp.add_subparsers(dest="map_cmd", required=True)
    imp = msub.add_parser("import", help="SyR-e / Motor-CAD .mat or a contract CSV -> a contract CSV")
    imp.add_argument("file", type=Path)
    imp.add_argument("--out", type=Path, required=True, help="the contract CSV to write")
    show = msub.add_parser("show", help="flux linkages, inductances, reciprocity, envelope, MTPA/MTPV, "
                                        "efficiency map: map.png and map.md")
    chk = msub.add_parser("check", help="legal domain, reciprocity, noise, I_max coverage and the FMUs' own verdict: "
                                        "check.md and check.json (exit 0 accepted, 1 refused, 2 bad input)")
    chk.add_argument("file", type=Path)
    chk.add_argument("--I-max", type=float, default=None,
                     help="peak current limit, A (default: --drive's, the map's I_max_A, else what the grid covers)")
    chk.add_argument("--drive", type=Path, default=None, help="drive description (TOML) whose motor to use")
    chk.add_argument("--out", type=Path, default=None, help="folder (default out/map_check_<name>)")
    rep = msub.add_parser("repair", help="write a map the FMUs accept (crop to the legal sub-grid, or a monotone "
                                         "projection; half, quarter and circle-only maps completed), every change "
                                         "stated (exit 0 accepted, 1 still refused, 2 bad input)")
    rep.add_argument("file", type=Path)
    rep.add_argument("--out", type=Path, required=True, help="the contract CSV to write")
    rep.add_argument("--I-max", type=float, default=None, help="peak current limit, A (as for check)")
    rep.add_argument("--drive", type=Path, default=None, help="drive description (TOML) whose motor to use")
    show.add_argument("file", type=Path)
    show.add_argument("--u-dc", type=float, default=None,
                      help=f"DC-link voltage, V (default: the map's u_dc_V metadata, else {U_DC_NOMINAL_V:g})")
    show.add_argument("--I-max", type=float, default=None,
                      help="peak current limit, A (default: the map's I_max_A metadata, else what the grid covers)")
    show.add_argument("--out", type=Path, default=None, help="folder (default out/map_<name>)")
    show.add_argument("--drive", type=Path, default=None,
                      help="drive description (TOML) whose motor parameters to use (default: the map's metadata)")


def _outputs_writable(args) -> None:
    """The output folder (show; check's in check_map, once the map is read) or file (import,
    repair) refused (exit 2, --out) before any work when it cannot be written: a read-only folder,
    a FIFO or a device in the file's place."""
    from scenarios.core.boundary import check_writable, output_target
    from scenarios.core.paths import OUT_DIR
    if args.map_cmd in ("import", "repair"):
        output_target(args.out, "--out")
        check_writable(Path(args.out).parent, "--out")
        return
    if args.out is None:
        args.out = OUT_DIR / (f"map_check_{args.file.stem}" if args.map_cmd == "check" else f"map_{args.file.stem}")
    if args.map_cmd == "show":  # (check's folder is checked once the map is read: a refused map leaves none)
        check_writable(args.out, "--out")


def main(args: argparse.Namespace) -> int:
    _outputs_writable(args)
    try:
        if args.map_cmd == "import":
            from scenarios.maps.importer import import_map, write_contract_csv
            imported = import_map(args.file)
            if getattr(args, "check_metadata", None) is not None:  # never write what the loader refuses
                args.check_metadata(imported.metadata, args.file)
            write_contract_csv(imported, args.out)
            print(f"{args.file} ({imported.source_format}): {len(imported.i_d)} x {len(imported.i_q)} points")
            for n in imported.notes:
                print(f"  {n}")
            for w in imported.warnings:
                print(f"  warning: {w}")
            print(f"wrote {args.out}")
        elif args.map_cmd == "check":
            return _check(args)
        elif args.map_cmd == "repair":
            return _repair(args)
        else:
            from scenarios.core.paths import OUT_DIR
            from scenarios.maps.show import show_map
            out = args.out or OUT_DIR / f"map_{args.file.stem}"
            drive = _drive(args)
            s = show_map(args.file, out, u_dc=args.u_dc, I_max=args.I_max, build=args.build, drive=drive)
            for a in s.assumed:
                print(f"  assumed: {a}")
            print(f"wrote {out}/map.png, {out}/map.md ({s.wall_s:.1f} s)")
    except MapImportError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0


def _drive(args):
    """The --drive description, loaded by the caller (scenarios/__main__.py: drives sit above maps)."""
    return getattr(args, "drive_description", None)


def _check(args) -> int:
    from scenarios.core.paths import OUT_DIR
    from scenarios.maps.check import check_map
    out = args.out or OUT_DIR / f"map_check_{args.file.stem}"
    c = check_map(args.file, out, args.build, I_max=args.I_max, drive=_drive(args))
    print(f"{args.file}: {c.grid}, I_max {c.I_max_A:g} A{' (magnet-free)' if c.magnet_free else ''}; "
          f"grid covers the drive's currents: {'yes' if c.grid_covers_I_max else 'NO'}")
    for d in c.defects:
        if d["count"]:
            print(f"  {d['kind']}: {d['count']} ({d['within_I_max']} within the I_max circle, "
                  f"{d['within_drive_currents']} among the drive's currents, {d['within_refused_box']} where the "
                  "FMUs refuse), nearest zero current at "
                  f"i_d = {d['nearest_A'][0]:g} A, i_q = {d['nearest_A'][1]:g} A")
    print(f"  reciprocity: max {c.reciprocity_max_H * 1e6:.4g} uH ({100 * c.reciprocity_rel:.3g} %); noise "
          f"psi_d {c.noise_Wb['psi_d']:.3g} Wb, psi_q {c.noise_Wb['psi_q']:.3g} Wb")
    for f in c.fmus:
        print(f"  {f['fmu']}: {f['verdict']}")
        for m in f["log"]:
            print(f"    {m}")
    print(f"wrote {out}/check.md, {out}/check.json")
    return 0 if c.accepted else 1


def _repair(args) -> int:
    from scenarios.maps.repair import repair_map
    r = repair_map(args.file, args.out, args.build, I_max=args.I_max, drive=_drive(args))
    for c in r.changes:
        print(f"  {c}")
    for v in r.fmus:
        print(f"  {v.fmu}: {v.verdict}")
        for m in v.log:
            print(f"    {m}")
    for f in r.simulation:
        print(f"  short simulation (IpmsmDrive): {f}")
    print(f"wrote {r.out}" if r.out is not None
          else f"not written: {args.out} (the repaired map failed the checks above)")
    return 0 if r.accepted else 1
