"""python -m scenarios {sweep, run, compare, check, study, map, fmu-path} ... (see --help of each). A bad drive
description or input exits 2 with the file, the key and what was expected."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from scenarios.core.paths import BUILD_DIR, FMU_FOLDERS, fmu_folder
from scenarios.core.version import VERSION
from scenarios.maps import cli as map_cli
from scenarios.runs import cli as runs_cli
from scenarios.runs.cli import slug as _slug  # noqa: F401 - the name tests and tools know

#: exit status: bad input (file, key, what was expected); a run that could not finish
EXIT_BAD_INPUT, EXIT_FAILED = 2, 1
#: what `fmu-path` finds: the FMUs (build/fmu/NAME.fmu; --fmi 3: build/fmu3/NAME.fmu) and the SSP
#: package (build/ssp/NAME.ssp)
FMU_NAMES = ("IpmsmController", "IpmsmPlant", "IpmsmDrive")
SSP_NAME = "IpmsmControllerPlant"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m scenarios", description=__doc__)
    ap.add_argument("--version", action="version", version=f"ipmsm-fmu {VERSION}")
    ap.add_argument("--build", type=Path, default=BUILD_DIR, help="build folder with fmu/ (and ssp/); default: "
                    "the repository's build/, or the installed wheel's copies")
    sub = ap.add_subparsers(dest="cmd", required=True)
    runs_cli.add_parsers(sub)
    from scenarios.study import compare_cli
    compare_cli.add_parser(sub)
    fp = sub.add_parser("fmu-path", help="where the FMUs (and the SSP package) are: print the file's path")
    fp.add_argument("name", choices=FMU_NAMES + (SSP_NAME,), help="an FMU's model identifier, or the SSP package")
    fp.add_argument("--fmi", type=int, default=2, choices=tuple(FMU_FOLDERS),
                    help="the FMU's FMI version: 2 (build/fmu, the default) or 3 (build/fmu3)")
    from scenarios.runs import check
    check.add_parser(sub)
    map_cli.add_parser(sub)
    from scenarios.study import cli as study_cli
    study_cli.add_parser(sub)
    args = ap.parse_args(argv)
    from scenarios.core.boundary import InputError, printable
    from scenarios.maps.error import MapImportError
    try:
        return _dispatch(args)
    except (InputError, MapImportError) as e:  # the one boundary: file, key or line, what was expected
        print(f"error: {printable(str(e), limit=2000)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except OSError as e:  # an output that could not be written, a file that vanished
        print(f"error: {printable(str(e.filename or ''))}: {e.strerror or e}", file=sys.stderr)
        return EXIT_FAILED
    except Exception as e:  # a run that failed (an FMU refused, the battery ran flat): one line, no traceback
        print(f"error: {type(e).__name__}: {printable(str(e), limit=2000)}", file=sys.stderr)
        return EXIT_FAILED


def _dispatch(args) -> int:
    if args.cmd == "fmu-path":
        if args.name == SSP_NAME and args.fmi != 2:
            print(f"error: --fmi {args.fmi}: the SSP package holds the FMI 2.0 FMUs only", file=sys.stderr)
            return EXIT_BAD_INPUT
        path = (args.build / "ssp" / f"{SSP_NAME}.ssp" if args.name == SSP_NAME
                else fmu_folder(args.build, args.fmi) / f"{args.name}.fmu")
        if not path.is_file():
            print(f"error: {path} is missing: build it (cmake --build build)", file=sys.stderr)
            return 2
        print(path)
        return 0
    if args.cmd in ("run", "sweep"):
        return runs_cli.main(args)
    if args.cmd == "compare":
        from scenarios.study import compare_cli
        return compare_cli.main(args)
    if args.cmd == "check":
        from scenarios.runs import check
        return check.main(args)
    if args.cmd == "map":
        from scenarios.drives.description import check_metadata_rules
        from scenarios.drives.fmu_acceptance import load_accepted
        args.check_metadata = check_metadata_rules  # what an import may write (drives sit above maps)
        if args.map_cmd == "show" and args.drive is None:
            # the map's machine and the options as a drive's would be: the schema's rules (check and
            # repair read maps with holes and defects, which is their job: their options only)
            from scenarios.drives.description import check_map_machine
            check_map_machine(args.file, args.u_dc, args.I_max)
        elif args.map_cmd in ("show", "check", "repair"):
            runs_cli.number_as_key(getattr(args, "u_dc", None), "--u-dc", "controller.lut_u_dc")
            runs_cli.number_as_key(args.I_max, "--I-max", "motor.I_max")
        args.drive_description = load_accepted(args.drive, args.build) if getattr(args, "drive", None) is not None \
            else None
        return map_cli.main(args)
    if args.cmd == "study":
        from scenarios.study import cli as study_cli
        return study_cli.main(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
