"""`python -m scenarios check FILE.toml [--junit FILE.xml] [--out DIR]`: a drive description's
CI gate. Runs the file's `checks.cycles` (whole cycles), compares each of its limits with the
run's summary, writes DIR/check.md (Markdown) and, with --junit, JUnit XML (one <testsuite> per
drive, one <testcase> per cycle x limit, classname = drive/cycle), and exits

    0  every limit holds,
    1  a limit failed,
    2  bad input: a bad drive description, an unknown cycle, nothing to check, a run that failed.

Files are written to a temporary name beside the target and renamed, so a reader (or CI) never
sees half a file; on bad input nothing is written.
"""
from __future__ import annotations

import argparse
import math
import os
import sys
import tempfile
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from scenarios.core.paths import BUILD_DIR
from scenarios.cosim import BACKENDS
from scenarios.drives.description import LIMITS, DriveDescription, DriveDescriptionError, load_drive

EXIT_PASS, EXIT_FAIL, EXIT_BAD_INPUT = 0, 1, 2


@dataclass(frozen=True)
class Verdict:
    """One limit on one cycle."""

    cycle: str
    limit: str      # the [checks] key, e.g. Wh_per_km_max
    key: str        # the summary key it bounds
    figure: float
    bound: float
    passed: bool
    wall_s: float   # the cycle's run time (each of its verdicts reports it)

    @property
    def rel(self) -> str:
        """The limit's relation: a *_max limit is an upper bound, the others lower bounds."""
        return "<=" if self.limit.endswith("_max") else ">="

    @property
    def message(self) -> str:
        state = "holds" if self.passed else "FAILED"
        return f"{self.key} = {self.figure:.6g}, limit {self.rel} {self.bound:.6g}: {state}"


def judge(cycle: str, summary: dict, limits: dict, wall_s: float = 0.0) -> list[Verdict]:
    """The verdicts of one cycle's summary on every limit (a NaN or missing figure, e.g. Wh_per_km
    of a run that covered no distance, fails)."""
    out = []
    for name, bound in limits.items():
        key, direction = LIMITS[name]
        x = math.nan if summary[key] is None else float(summary[key])
        ok = math.isfinite(x) and (x <= bound if direction == "max" else x >= bound)
        out.append(Verdict(cycle, name, key, x, bound, ok, wall_s))
    return out


def run_cycles(drive: DriveDescription, build: Path, backend: str = "drive", progress: bool = True) -> dict:
    """cycle -> (summary dict, wall s), each of the drive's check cycles run whole."""
    from scenarios.runs.simulate import RunSpec, fmu_paths, simulate
    from scenarios.vehicle.cycles import load_cycle
    cycles = {}
    for c in drive.checks.cycles:
        try:
            cycles[c] = load_cycle(c)
        except (OSError, ValueError, KeyError) as e:
            raise DriveDescriptionError(drive.source, "checks.cycles", f"a loadable cycle ({e})") from None
    results = {}
    for cycle in cycles.values():
        s = simulate(cycle, RunSpec(drive=drive, backend=backend), fmus=fmu_paths(build), progress=progress)
        results[cycle.name] = (s.to_dict(), s.wall_s)
    return results


def markdown(drive: DriveDescription, verdicts: list[Verdict]) -> str:
    ok = all(v.passed for v in verdicts)
    lines = [f"# check: {drive.name} — {'PASS' if ok else 'FAIL'}", "",
             f"Drive description `{drive.source}` (SHA-256 `{drive.sha256[:12]}`), "
             f"{len(verdicts)} limits on {len({v.cycle for v in verdicts})} cycles.", "",
             "| cycle | limit | figure | bound | result |", "|---|---|---|---|---|"]
    for v in verdicts:
        lines.append(f"| {v.cycle} | `{v.limit}` | {v.figure:.6g} | {v.rel} {v.bound:.6g} | "
                     f"{'pass' if v.passed else '**FAIL**'} |")
    return "\n".join(lines) + "\n"


def junit(drive: DriveDescription, verdicts: list[Verdict]) -> ET.ElementTree:
    """<testsuites><testsuite name=drive>, a <testcase> per verdict (classname drive/cycle,
    name the limit), a <failure> with the figure and the bound when it does not hold."""
    suites = ET.Element("testsuites")
    failures = sum(not v.passed for v in verdicts)
    suite = ET.SubElement(suites, "testsuite", name=drive.name, tests=str(len(verdicts)), failures=str(failures),
                          errors="0", skipped="0", time=f"{sum({v.cycle: v.wall_s for v in verdicts}.values()):.3f}")
    props = ET.SubElement(suite, "properties")
    ET.SubElement(props, "property", name="drive_file", value=str(drive.source))
    ET.SubElement(props, "property", name="drive_sha256", value=drive.sha256)
    for v in verdicts:
        case = ET.SubElement(suite, "testcase", classname=f"{drive.name}/{v.cycle}", name=v.limit, time="0")
        if not v.passed:
            ET.SubElement(case, "failure", message=v.message, type="LimitExceeded").text = v.message
        else:
            ET.SubElement(case, "system-out").text = v.message
    ET.indent(suites)
    return ET.ElementTree(suites)


def write_atomically(path: Path, write) -> None:
    """write(tmp_path) then rename over `path`: never half a file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def check(drive_file: Path | None, junit_path: Path | None, out: Path, build: Path = BUILD_DIR,
          backend: str = "drive", progress: bool = True) -> int:
    """The exit status (EXIT_PASS / EXIT_FAIL); a bad input raises DriveDescriptionError."""
    drive = load_drive(drive_file)
    for a in drive.assumed:  # the motor's values neither the file nor its map gives
        print(f"assumed: {a}", file=sys.stderr)
    if not drive.checks.cycles:
        raise DriveDescriptionError(drive.source, "checks.cycles", "at least one cycle to check")
    if not drive.checks.limits:
        raise DriveDescriptionError(drive.source, "checks", "at least one limit (" + ", ".join(LIMITS) + ")")
    verdicts = []
    for cycle, (summary, wall) in run_cycles(drive, build, backend, progress).items():
        verdicts += judge(cycle, summary, drive.checks.limits, wall)
    write_atomically(out / "check.md", lambda p: p.write_text(markdown(drive, verdicts)))
    if junit_path is not None:
        write_atomically(junit_path, lambda p: junit(drive, verdicts).write(p, encoding="utf-8", xml_declaration=True))
    for v in verdicts:
        print(f"{'ok  ' if v.passed else 'FAIL'} {drive.name}/{v.cycle} {v.message}")
    return EXIT_PASS if all(v.passed for v in verdicts) else EXIT_FAIL


def add_parser(sub) -> None:
    p = sub.add_parser("check", help="CI gate: run a drive description's checks.cycles against its limits "
                       "(exit 0 pass, 1 a limit failed, 2 bad input)")
    p.add_argument("drive", type=Path, help="drive description (TOML) with a [checks] table")
    p.add_argument("--junit", type=Path, default=None, help="write JUnit XML here")
    p.add_argument("--out", type=Path, default=Path("out") / "check", help="folder of check.md")
    p.add_argument("--backend", default="drive", choices=BACKENDS,
                   help="drive: the IpmsmDrive FMU; fmpy: the reference loop")


def main(args: argparse.Namespace) -> int:
    try:
        status = check(args.drive, args.junit, args.out, build=args.build, backend=args.backend)
    except DriveDescriptionError as e:
        print(f"error: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as e:  # a run that could not finish (an FMU error, an empty battery): not a verdict
        print(f"error: {type(e).__name__}: {e}", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(f"wrote {args.out}/check.md" + (f", {args.junit}" if args.junit else ""))
    return status
