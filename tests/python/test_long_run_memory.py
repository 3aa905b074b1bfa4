"""Bounded memory for a long run (issue 24, docs/inputs.md): `python -m scenarios run` end to end
on UDDS repeated for 1 h and for 4 h of simulated time (tools/long_run_memory.py: the cycle, a
drive whose pack lasts, /usr/bin/time -v). Four times the steps must not take more memory: the
cycle is sampled a block at a time, trace.csv streamed to disk, run.png drawn from a thinned
trace (scenarios.runs.plots.load_trace). A week-long run takes hours; its figure is in
docs/inputs.md, measured with the same tool."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys

import pytest

from scenarios.core.paths import ROOT
from scenarios.runs.plots import load_trace

#: MiB the 4 h run's peak may exceed the 1 h run's: a leak of 20 bytes a vehicle step would show as
#: 20 MiB (3 h are 1.08 million steps of 10 ms), the trace held in memory (108 000 more rows of 19
#: numbers: 16 MiB as a float array, several times that as Python objects) as about as much or more
GROWTH_MAX_MIB = 20.0


@pytest.mark.slow
@pytest.mark.skipif(not shutil.which("time") and not os.path.exists("/usr/bin/time"), reason="/usr/bin/time missing")
def test_four_times_the_cycle_needs_no_more_memory(tmp_path):
    r = subprocess.run([sys.executable, str(ROOT / "tools" / "long_run_memory.py"), "1", "4", "--json",
                        "--work", str(tmp_path)], capture_output=True, text=True, timeout=7200)
    assert r.returncode == 0, r.stderr[-3000:] + r.stdout[-3000:]
    runs = [json.loads(line) for line in r.stdout.splitlines() if line.startswith("{")]
    print("\n" + "\n".join(line for line in r.stdout.splitlines() if not line.startswith("{")))
    one, four = runs
    assert four["trace_rows"] == 4 * one["trace_rows"] == 4 * 36_000   # the whole trace is on disk
    assert four["peak_rss_MiB"] - one["peak_rss_MiB"] < GROWTH_MAX_MIB, runs


def test_the_plotted_trace_is_thinned_to_a_bound(tmp_path):
    """load_trace holds at most max_rows rows whatever the file's length, evenly spaced, the
    first row kept (the bound that keeps run.png of a week-long run in bounded memory)."""
    p = tmp_path / "trace.csv"
    with open(p, "w") as f:
        f.write("time_s,region\n")
        f.writelines(f"{0.1 * k:.1f},{k % 5}\n" for k in range(1, 250_002))
    t = load_trace(p, max_rows=100_000)
    assert 50_000 < len(t["time_s"]) <= 100_000
    step = t["time_s"][1] - t["time_s"][0]
    assert t["time_s"][0] == pytest.approx(0.1) and step == pytest.approx(0.4)
    assert (abs(t["time_s"][1:] - t["time_s"][:-1] - step) < 1e-6).all()
    whole = load_trace(p, max_rows=10**6)
    assert len(whole["time_s"]) == 250_001 and whole["region"][:6].tolist() == [1, 2, 3, 4, 0, 1]
