"""python -m scenarios map {import, show}: flux maps from FEM tools, and the machine at a glance."""
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
    show.add_argument("file", type=Path)
    show.add_argument("--u-dc", type=float, default=None,
                      help=f"DC-link voltage, V (default: the map's u_dc_V metadata, else {U_DC_NOMINAL_V:g})")
    show.add_argument("--I-max", type=float, default=None,
                      help="peak current limit, A (default: the map's I_max_A metadata, else what the grid covers)")
    show.add_argument("--out", type=Path, default=None, help="folder (default out/map_<name>)")


def main(args: argparse.Namespace) -> int:
    try:
        if args.map_cmd == "import":
            from scenarios.maps.importer import import_map, write_contract_csv
            imported = import_map(args.file)
            write_contract_csv(imported, args.out)
            print(f"{args.file} ({imported.source_format}): {len(imported.i_d)} x {len(imported.i_q)} points")
            for n in imported.notes:
                print(f"  {n}")
            for w in imported.warnings:
                print(f"  warning: {w}")
            print(f"wrote {args.out}")
        else:
            from scenarios.core.paths import OUT_DIR
            from scenarios.maps.show import show_map
            out = args.out or OUT_DIR / f"map_{args.file.stem}"
            show_map(args.file, out, u_dc=args.u_dc, I_max=args.I_max, build=args.build)
            print(f"wrote {out}/map.png, {out}/map.md")
    except MapImportError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    return 0
