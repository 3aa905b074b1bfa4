"""`python -m scenarios check FILE.toml [--junit FILE.xml] [--out DIR]`: a drive description's
CI gate. Runs the file's `checks.cycles` (whole cycles), compares each of its limits with the
run's summary, writes DIR/check.md (Markdown) and, with --junit, JUnit XML (one <testsuite> per
drive, one <testcase> per cycle x limit, classname = drive/cycle), and exits

    0  every limit holds on every cycle,
    1  a limit failed,
    2  bad input (a bad drive description, an unknown or malformed cycle, nothing to check, an
       output that cannot be written), or a cycle that could not run: its limits are <error>
       test cases, never passes.

A cycle is known by its full identity (a standard cycle's name, else its resolved path), so two
files of one name are two cycles. Names reach the XML with everything XML 1.0 forbids replaced,
and the file is parsed back before it is renamed into place; a reader (or CI) never sees half a
file. The output folders are checked writable before the first run; on bad input nothing is
written.
"""
from __future__ import annotations

import argparse
import math
import os
import re
import sys
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from scenarios.core import boundary
from scenarios.core.boundary import InputError, check_writable, printable
from scenarios.core.paths import BUILD_DIR
from scenarios.cosim import BACKEND_ALIASES, BACKENDS
from scenarios.drives.description import LIMITS, DriveDescription, DriveDescriptionError, load_drive
from scenarios.drives.fmu_acceptance import refuse_unless_fmus_accept

EXIT_PASS, EXIT_FAIL, EXIT_BAD_INPUT = 0, 1, 2

#: m/s per km/h
KMH = 1.0 / 3.6
#: Every check fails a cycle the car did not follow, whatever limits the drive names (a limit on
#: energy or torque error says nothing about a car that fell behind or never moved):
#: the speed error's RMS at most the WLTP drive-trace index RMSSE's 1.3 km/h (Regulation (EU)
#: 2017/1151 Annex XXI as amended by Regulation (EU) 2018/1832, the UN GTR 15 test's speed trace) ...
CYCLE_SPEED_RMSE_MAX = 1.3 * KMH
#: ... and the distance at least the cycle's less the trace's speed tolerance, 2 km/h (UN GTR 15;
#: EPA's 2 mph, 40 CFR 86.115-78, is 3.2 km/h), over the time the trace is moving
CYCLE_SPEED_TOLERANCE = 2.0 * KMH
#: the verdicts every check adds to the drive's limits: name -> (summary key, direction)
CYCLE_FOLLOWING = {"cycle_speed_rmse_mps_max": ("speed_rmse_mps", "max"),
                   "cycle_distance_km_min": ("distance_km", "min")}
#: ... and the keys they judge in a run whose fault came (a [fault] table, docs/faults.md): after
#: the trip the car has no traction by design, so the cycle is judged up to the trip
CYCLE_FOLLOWING_BEFORE_FAULT = {"cycle_speed_rmse_mps_max": ("speed_rmse_before_fault_mps", "max"),
                                "cycle_distance_km_min": ("distance_before_fault_km", "min")}


@dataclass(frozen=True)
class Verdict:
    """One limit on one cycle; `error` set: the cycle could not run (no figure, not a pass)."""

    cycle: str      # the cycle's label (unique within a check: see cycle_labels)
    limit: str      # the [checks] key, e.g. Wh_per_km_max
    key: str        # the summary key it bounds
    figure: float
    bound: float
    passed: bool
    wall_s: float   # the cycle's run time (each of its verdicts reports it)
    error: str | None = None
    note: str | None = None  # why a figure is undefined (a failure, never a pass)
    scope: str | None = None  # the part of the run judged, when not all of it ("until the trip at t = 1.5 s")

    @property
    def rel(self) -> str:
        """The limit's relation: a *_max limit is an upper bound, the others lower bounds."""
        return "<=" if self.limit.endswith("_max") else ">="

    @property
    def message(self) -> str:
        if self.error is not None:
            return f"{self.key}: the cycle could not run: {self.error}"
        state = "holds" if self.passed else "FAILED"
        return (f"{self.key} = {self.figure:.6g}" + ("" if self.scope is None else f" {self.scope}") +
                f", limit {self.rel} {self.bound:.6g}: {state}" + ("" if self.note is None else f" ({self.note})"))


def trip_time(summary: dict) -> float | None:
    """s, the communication point of the run's fault (None: no [fault] table, or it never came)."""
    t = summary.get("fault_time_s")
    return None if t is None else float(t)


def cycle_following(summary: dict) -> dict:
    """The cycle-following limits of a run (CYCLE_FOLLOWING name -> bound), over the cycle up to
    the trip in a run whose fault came: NaN bounds, which fail, when the summary lacks the
    cycle's figures."""
    before = "_before_fault" if trip_time(summary) is not None else ""
    try:
        km = (float(summary[f"cycle_distance{before}_km"]) -
              CYCLE_SPEED_TOLERANCE * float(summary[f"cycle_moving{before}_s"]) / 1000.0)
    except (KeyError, TypeError, ValueError):
        km = math.nan
    return {"cycle_speed_rmse_mps_max": CYCLE_SPEED_RMSE_MAX, "cycle_distance_km_min": max(km, 0.0)}


def judge(cycle: str, summary: dict, limits: dict, wall_s: float = 0.0) -> list[Verdict]:
    """The verdicts of one cycle's summary on every limit and on the cycle-following limits every
    check applies (a NaN or missing figure, e.g. Wh_per_km of a run that covered no distance,
    fails). A run whose fault came is judged on the cycle up to the trip (the verdict says so)."""
    t_trip = trip_time(summary)
    following = CYCLE_FOLLOWING if t_trip is None else CYCLE_FOLLOWING_BEFORE_FAULT
    scope = None if t_trip is None else f"until the trip at t = {t_trip:.6g} s"
    out = []
    for name, bound in {**limits, **cycle_following(summary)}.items():
        key, direction = LIMITS[name] if name in LIMITS else following[name]
        value = summary.get(key)
        try:
            x = math.nan if value is None else float(value)
        except (TypeError, ValueError):
            x = math.nan
        ok = math.isfinite(x) and (x <= bound if direction == "max" else x >= bound)
        out.append(Verdict(cycle, name, key, x, bound, ok, wall_s, note=None if math.isfinite(x) else
                           undefined_because(key, summary), scope=None if name in LIMITS else scope))
    return out


def undefined_because(key: str, summary: dict) -> str:
    """Why a summary's figure is undefined, in words (the verdict fails: nothing was measured)."""
    if key == "speed_rmse_before_fault_mps" and summary.get("distance_before_fault_km") is not None:
        return "the fault came at the cycle's start: no part of it before the trip to judge"
    if key.startswith("fault_"):
        if summary.get("fault_trigger") is None:
            return "the run had no fault: the drive has no [fault] table"
        if summary.get("fault_time_s") is None:
            return f"no fault in this cycle: {summary['fault_trigger']} was never reached"
        if key == "fault_time_to_zero_current_s":
            return "the current had not fallen to zero when the fault ended"
        if key == "fault_demag_margin_A":
            return "the drive has no demagnetisation limit: set fault.i_d_demag"
    return "the run did not define it"


def errored(cycle: str, limits: dict, error: str, wall_s: float = 0.0) -> list[Verdict]:
    """The verdicts of a cycle that could not run: every limit an error."""
    return [Verdict(cycle, name, (LIMITS[name] if name in LIMITS else CYCLE_FOLLOWING[name])[0], math.nan, bound,
                    False, wall_s, error)
            for name, bound in {**limits, **cycle_following({})}.items()]


def derated(summaries: dict) -> list[str]:
    """A line per cycle whose torque limit was derated (label -> summary dict): how long, how far."""
    return [f"{label}: torque limit derated for {s['time_derated_s']:.6g} s (lowest factor {s['derating_min']:.6g})"
            for label, s in summaries.items()
            if s is not None and isinstance(s.get("time_derated_s"), (int, float)) and s["time_derated_s"] > 0.0]


def cycle_labels(drive: DriveDescription) -> dict[str, str]:
    """Each check cycle's identity -> its label: a standard cycle's name, a CSV's path relative
    to the drive file's folder when inside it (else absolute). Distinct identities, distinct labels."""
    base = drive.source.parent if drive.source is not None else None
    labels = {}
    for c in dict.fromkeys(drive.checks.cycles):
        p = Path(c)
        label = c
        if p.is_absolute() and base is not None:
            try:
                label = p.relative_to(base).as_posix()
            except ValueError:
                label = c
        labels[c] = label
    # Labels a reader would take for one another (UDDS beside a file ./UDDS, NFC beside NFD, a
    # trailing space): each such CSV is labelled by its whole path, escaped (ascii: a decomposed
    # accent or a space shows), so no two rows of a report or JUnit read alike
    seen = {_look(label) for c, label in labels.items() if not Path(c).is_absolute()}
    for c, label in labels.items():
        if Path(c).is_absolute():
            if _look(label) in seen:
                labels[c] = ascii(c)
            seen.add(_look(labels[c]))
    return labels


def _look(label: str) -> str:
    """What a label looks like to a reader: compatibility-normalised, case-folded, stripped."""
    import unicodedata
    return unicodedata.normalize("NFKC", label).strip().casefold()


def load_cycles(drive: DriveDescription) -> dict:
    """identity -> Cycle, all read before any run (a bad cycle: exit 2, nothing run)."""
    from scenarios.vehicle.cycles import load_cycle
    cycles = {}
    for c in dict.fromkeys(drive.checks.cycles):
        try:
            cycles[c] = load_cycle(c)
        except (OSError, ValueError, KeyError) as e:
            raise DriveDescriptionError(drive.source, "checks.cycles", f"a loadable cycle ({e})") from None
    return cycles


def run_cycles(drive: DriveDescription, build: Path, backend: str = "drive", progress: bool = True,
               cycles: dict | None = None) -> dict:
    """cycle identity -> (summary dict, wall s) or (None, wall s, error text), each of the drive's
    check cycles run whole; a run that raises is recorded, the others still run."""
    import time

    from scenarios.runs.simulate import RunSpec, fmu_paths, simulate
    cycles = load_cycles(drive) if cycles is None else cycles
    results = {}
    for ident, cycle in cycles.items():
        t0 = time.perf_counter()
        try:
            s = simulate(cycle, RunSpec(drive=drive, backend=backend), fmus=fmu_paths(build), progress=progress)
            results[ident] = (s.to_dict(), s.wall_s, None)
        except Exception as e:  # an FMU error, an empty battery: this cycle has no verdict, an error
            results[ident] = (None, time.perf_counter() - t0, f"{type(e).__name__}: {e}")
    return results


def _md_cell(text: str) -> str:
    return printable(text).replace("|", "\\|").replace("`", "'")


def markdown(drive: DriveDescription, verdicts: list[Verdict], notes: list[str] = ()) -> str:
    ok = all(v.passed for v in verdicts)
    errors = any(v.error is not None for v in verdicts)
    state = "PASS" if ok else ("ERROR" if errors else "FAIL")
    lines = [f"# check: {_md_cell(drive.name)} — {state}", "",
             f"Drive description `{_md_cell(str(drive.source))}` (SHA-256 `{drive.sha256[:12]}`), "
             f"{len(verdicts)} limits on {len({v.cycle for v in verdicts})} cycles.", "",
             "| cycle | limit | figure | bound | result |", "|---|---|---|---|---|"]
    for v in verdicts:
        result = "pass" if v.passed else ("**ERROR**: " + _md_cell(v.error) if v.error is not None else
                                          "**FAIL**" + ("" if v.note is None else ": " + _md_cell(v.note)))
        result += "" if v.scope is None else f" ({_md_cell(v.scope)})"
        lines.append(f"| {_md_cell(v.cycle)} | `{v.limit}` | {v.figure:.6g} | {v.rel} {v.bound:.6g} | {result} |")
    lines += ["", "`cycle_*` limits: every check's (the car followed the cycle: scenarios.runs.check.CYCLE_FOLLOWING; "
              "in a run whose fault came, up to the trip)."]
    if notes:
        lines += ["", "## Derating", ""] + [f"- {_md_cell(n)}" for n in notes]
    return "\n".join(lines) + "\n"


#: what XML 1.0 forbids in a document (its Char production): C0 controls but tab, LF and CR;
#: surrogates (Python's stand-ins for undecodable bytes); U+FFFE and U+FFFF
_XML_FORBIDDEN = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ud800-\udfff\ufffe\uffff]")


def xml_text(text: str) -> str:
    """`text` with every character XML 1.0 cannot carry written as \\uXXXX (ElementTree escapes
    the rest: & < > and quotes)."""
    return _XML_FORBIDDEN.sub(lambda m: f"\\u{ord(m.group()):04x}", str(text))


def junit(drive: DriveDescription, verdicts: list[Verdict], notes: list[str] = ()) -> ET.ElementTree:
    """<testsuites><testsuite name=drive>, a <testcase> per verdict (classname drive/cycle,
    name the limit), a <failure> with the figure and the bound when it does not hold, an <error>
    when its cycle could not run."""
    suites = ET.Element("testsuites")
    failures = sum(not v.passed and v.error is None for v in verdicts)
    errors = sum(v.error is not None for v in verdicts)
    suite = ET.SubElement(suites, "testsuite", name=xml_text(drive.name), tests=str(len(verdicts)),
                          failures=str(failures), errors=str(errors), skipped="0",
                          time=f"{sum({v.cycle: v.wall_s for v in verdicts}.values()):.3f}")
    props = ET.SubElement(suite, "properties")
    ET.SubElement(props, "property", name="drive_file", value=xml_text(str(drive.source)))
    ET.SubElement(props, "property", name="drive_sha256", value=drive.sha256)
    for i, n in enumerate(notes):
        ET.SubElement(props, "property", name=f"derating_{i}", value=xml_text(n))
    for v in verdicts:
        case = ET.SubElement(suite, "testcase", classname=xml_text(f"{drive.name}/{v.cycle}"), name=v.limit,
                             time=f"{v.wall_s:.3f}")
        msg = xml_text(v.message)
        if v.error is not None:
            ET.SubElement(case, "error", message=msg, type="RunFailed").text = msg
        elif not v.passed:
            ET.SubElement(case, "failure", message=msg, type="LimitExceeded").text = msg
        else:
            ET.SubElement(case, "system-out").text = msg
    ET.indent(suites)
    return ET.ElementTree(suites)


def _parses_as_junit(expected_cases: int):
    def verify(path: Path) -> None:
        root = ET.parse(path).getroot()  # raises ParseError on anything a reader could not read
        n = sum(1 for _ in root.iter("testcase"))
        if n != expected_cases:
            raise RuntimeError(f"JUnit XML written with {n} test cases, {expected_cases} expected")
    return verify


def write_atomically(path: Path, write) -> None:
    """write(tmp_path) then rename over `path`: never half a file (scenarios.core.boundary)."""
    boundary.write_atomically(path, write)


def check(drive_file: Path | None, junit_path: Path | None, out: Path, build: Path = BUILD_DIR,
          backend: str = "drive", progress: bool = True) -> int:
    """The exit status (EXIT_PASS / EXIT_FAIL / EXIT_BAD_INPUT for a cycle that could not run); a
    bad input raises DriveDescriptionError or InputError before anything runs."""
    drive = load_drive(drive_file)
    refuse_unless_fmus_accept(drive, build)
    for a in drive.assumed:  # the motor's values neither the file nor its map gives
        print(f"assumed: {a}", file=sys.stderr)
    if not drive.checks.cycles:
        raise DriveDescriptionError(drive.source, "checks.cycles", "at least one cycle to check")
    if not drive.checks.limits:
        raise DriveDescriptionError(drive.source, "checks", "at least one limit (" + ", ".join(LIMITS) + ")")
    cycles = load_cycles(drive)
    check_writable(out, "--out")
    boundary.check_outputs(out, ("check.md",), "--out")
    if junit_path is not None:
        if junit_path.is_dir():
            raise InputError(junit_path, "--junit", "a file name, not a folder")
        # a regular file or nothing (a device, a FIFO, a dangling link or one leading out of its
        # folder: refused, untouched); missing folders are made on the path as given, never through a link
        boundary.output_target(junit_path, "--junit")
        if not junit_path.is_symlink():
            boundary.folders_made_here(junit_path.parent, "--junit")
        check_writable(Path(os.path.realpath(junit_path)).parent, "--junit")
    labels = cycle_labels(drive)
    verdicts, summaries = [], {}
    for ident, (summary, wall, error) in run_cycles(drive, build, backend, progress, cycles).items():
        verdicts += (judge(labels[ident], summary, drive.checks.limits, wall) if error is None else
                     errored(labels[ident], drive.checks.limits, error, wall))
        summaries[labels[ident]] = summary
    notes = derated(summaries)
    if junit_path is not None:
        tree = junit(drive, verdicts, notes)
        boundary.write_atomically(junit_path, lambda p: tree.write(p, encoding="utf-8", xml_declaration=True),
                                  verify=_parses_as_junit(len(verdicts)), what="--junit")
    write_atomically(out / "check.md", lambda p: p.write_text(markdown(drive, verdicts, notes), encoding="utf-8"))
    for v in verdicts:
        state = "ok  " if v.passed else ("ERROR" if v.error is not None else "FAIL")
        print(printable(f"{state} {drive.name}/{v.cycle} {v.message}", limit=2000))
    for n in notes:
        print(printable(f"note {drive.name}/{n}", limit=2000))
    if any(v.error is not None for v in verdicts):
        return EXIT_BAD_INPUT
    return EXIT_PASS if all(v.passed for v in verdicts) else EXIT_FAIL


def add_parser(sub) -> None:
    p = sub.add_parser("check", help="CI gate: run a drive description's checks.cycles against its limits "
                       "(exit 0 pass, 1 a limit failed, 2 bad input or a cycle that could not run)")
    p.add_argument("drive", type=Path, help="drive description (TOML) with a [checks] table")
    p.add_argument("--junit", type=Path, default=None, help="write JUnit XML here")
    p.add_argument("--out", type=Path, default=Path("out") / "check", help="folder of check.md")
    p.add_argument("--backend", default="drive", choices=BACKENDS + tuple(BACKEND_ALIASES),
                   help="drive: the IpmsmDrive FMU; reference (or fmpy): the reference loop")


def main(args: argparse.Namespace) -> int:
    try:
        status = check(args.drive, args.junit, args.out, build=args.build, backend=args.backend)
    except (DriveDescriptionError, InputError) as e:
        print(f"error: {printable(str(e), limit=2000)}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except OSError as e:  # an output that could not be written after all (a full disk)
        print(f"error: {printable(str(e.filename))}: could not write ({e.strerror or e})", file=sys.stderr)
        return EXIT_BAD_INPUT
    print(printable(f"wrote {args.out}/check.md" + (f", {args.junit}" if args.junit else ""), limit=2000))
    if status == EXIT_BAD_INPUT:
        print("error: a cycle could not run (its limits are errors in the report)", file=sys.stderr)
    return status
