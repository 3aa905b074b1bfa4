"""`compare` as a preset of study: the same per-run files as before (runs/<run>/summary.json and
trace.csv as simulate() writes them, byte for byte but for the timings), the report, and a second
call that runs nothing."""
import json

import scenarios.study.compare
from scenarios.runs.simulate import STUDY_CONDITIONS, RunSpec, simulate
from scenarios.study.compare import default_variants, run_study
from scenarios.vehicle.cycles import load_cycle

TIMINGS = ("wall_s", "real_time_factor")


def test_compare_preset_writes_what_simulate_writes(tmp_path, monkeypatch):
    # the controller's C++ benchmark (ns per call in the report) is not what is tested here: a minute saved
    monkeypatch.setattr(scenarios.study.compare, "controller_costs", lambda build: {})
    cycle = tmp_path / "ramp.csv"
    cycle.write_text("time_s,speed_mps\n0,2\n1,4\n2,5\n")
    conditions = STUDY_CONDITIONS[1:2]  # u_dc -15 %
    out = tmp_path / "compare"
    VARIANTS = default_variants()  # with least loss's where the FMUs have it: the last run is one of them
    results = run_study(out, cycles=(str(cycle),), conditions=conditions, variants=VARIANTS, workers=2)
    assert len(results) == len(conditions) * len(VARIANTS)
    written = sorted(p.name for p in out.iterdir())  # all of it in the message: a missing file once seen in CI
    assert {"report.md", "study.png", "runs.parquet"} <= set(written), written
    assert len((out / "summary.csv").read_text().splitlines()) == 1 + len(results)
    for r in (results[0], results[-1]):
        v = next(v for v in VARIANTS if v.label == r.variant)
        cond = next(c for c in conditions if c.name == r.condition)
        direct = tmp_path / "direct" / r.run_dir
        simulate(load_cycle(cycle), RunSpec(method=v.method, recursion=v.recursion, conditions=cond, command_check=0,
                                                 objective=v.objective),
                 out=direct, progress=False)
        assert (out / r.run_dir / "trace.csv").read_text() == (direct / "trace.csv").read_text()
        got, want = (json.loads((d / "summary.json").read_text()) for d in (out / r.run_dir, direct))
        for k in TIMINGS:
            got.pop(k), want.pop(k)
        assert got == want
        assert (out / r.run_dir / "run.png").exists()
    # resumable: nothing runs again, the report is the same
    report = (out / "report.md").read_text()
    again = run_study(out, cycles=(str(cycle),), conditions=conditions, variants=VARIANTS, workers=2)
    assert [a.summary for a in again] == [r.summary for r in results]
    assert (out / "report.md").read_text() == report
    # the controller's cost per call: a column only where bench_controller measured it (where it is
    # built), otherwise one line saying where the figures come from; every table row as wide as its header
    assert "ns/call" not in report and "-DIPMSM_BUILD_BENCH=ON" in report
    scenarios.study.compare.write_report(out, results, {results[0].variant: 123.0})
    measured = (out / "report.md").read_text()
    assert "controller ns/call" in measured and "-DIPMSM_BUILD_BENCH=ON" not in measured
    assert f"| {results[0].variant} |" in measured and "| 123 |" in measured
    for text in (report, measured):
        lines = text.splitlines()
        heads = [k for k, ln in enumerate(lines) if ln.startswith("| method | Wh/km")]
        assert heads
        for k in heads:
            table = lines[k:lines.index("", k)]
            assert len(table) > 2 and len({ln.count("|") for ln in table}) == 1, table
