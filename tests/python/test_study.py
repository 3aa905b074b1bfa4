"""Studies on dask.distributed (issue 18): a small study on a LocalCluster of two workers equals
the same runs made directly; a worker killed mid-run; an interrupted study resumed; a run that
raises; the same study on a separately started scheduler and workers. Short windows (2 s of
WLTC 3b, ~0.3 s a run) keep it quick."""
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import replace

import numpy as np
import pyarrow.parquet as pq
import pytest

from scenarios.core.paths import ROOT
from scenarios.runs.simulate import simulate
from scenarios.study import parse, run_study
from scenarios.study.execute import KILL_ONCE_ENV
from scenarios.study.spec import run_spec
from scenarios.study.table import read_runs, summary_of, trace_path
from scenarios.vehicle.cycles import load_cycle, segment

from conftest import patient, same

WINDOW = [300.0, 302.0]  # s of WLTC 3b, the vehicle moving (a window at standstill has no Wh/km)
# each method's own commands (command_check 0): with the check on, a table's failing commands are
# recursion 2's and the tables' grid would not show
SPEC = {"study": {"cycles": ["WLTC3b"], "window_s": WINDOW, "methods": ["ferrari", "lut_speed"],
                  "u_dc_scale": [1.0, 0.85], "command_checks": [0]}}
#: a run's summary values that are not deterministic
TIMINGS = ("wall_s", "real_time_factor")


def study_runs(spec=SPEC):
    return parse(spec).runs


def rows_by_key(out):
    rows = read_runs(out).to_pylist()
    assert len({r["key"] for r in rows}) == len(rows)
    return {r["key"]: r for r in rows}


def assert_rows_equal_direct_runs(out, runs, keys, scratch):
    """Every run once, ok, and its row's summary and trace bit-identical to simulate() in-process."""
    rows = rows_by_key(out)
    assert set(rows) == set(keys) and len(rows) == len(runs)
    cycle = segment(load_cycle("WLTC3b"), *WINDOW)
    for key, run in zip(keys, runs):
        row = rows[key]
        assert row["status"] == "ok" and row["error"] is None
        direct = simulate(cycle, run_spec(run), progress=False, out=scratch / key)
        got, want = summary_of(row).to_dict(), direct.to_dict()
        assert set(got) == set(want)
        for name, value in want.items():
            if name not in TIMINGS:
                assert same(got[name], value) if isinstance(value, float) else got[name] == value, name
        trace = pq.read_table(trace_path(out, key)).to_pydict()
        expected = np.genfromtxt(scratch / key / "trace.csv", delimiter=",", names=True)
        for name in expected.dtype.names:
            assert same(trace[name], expected[name]), name
    return rows


def test_small_study_equals_direct_runs(tmp_path):
    coarse = replace(study_runs()[2], lut_n_torque=11, lut_n_speed=11)  # lut_speed on 11 x 11 tables
    runs = (*study_runs(), coarse)
    res = run_study(runs, tmp_path / "out", workers=2, progress=False)
    assert (res.executed, res.skipped, res.failed) == (5, 0, 0)
    rows = assert_rows_equal_direct_runs(tmp_path / "out", runs, res.keys, tmp_path / "direct")
    assert len({r["worker"] for r in rows.values()}) == 2, "both workers ran"
    # the grid reached the controller: coarser tables, another torque error
    assert study_runs()[2].method == "lut_speed"
    assert rows[res.keys[4]]["torque_rmse_Nm"] != rows[res.keys[2]]["torque_rmse_Nm"]
    # the same runs again execute nothing
    again = run_study(runs, tmp_path / "out", workers=2, progress=False)
    assert (again.executed, again.skipped) == (0, 5)
    # the report from runs.parquet alone
    import shutil

    from scenarios.__main__ import main
    shutil.rmtree(tmp_path / "out" / "traces")
    assert main(["study", "--report-only", str(tmp_path / "out")]) == 0
    report = (tmp_path / "out" / "report.md").read_text()
    assert all(f"`{k}`" in report for k in res.keys) and "11 x 11 points" in report
    assert (tmp_path / "out" / "study.png").exists()


@pytest.mark.parametrize("workers", [1, 2])  # 1: the nanny's restarted worker gets the run (and the FMUs again)
def test_worker_killed_mid_run_is_retried(tmp_path, monkeypatch, workers):
    marker = tmp_path / "killed"
    monkeypatch.setenv(KILL_ONCE_ENV, str(marker))  # the workers of the LocalCluster inherit it
    runs = study_runs()
    res = run_study(runs, tmp_path / "out", workers=workers, progress=False)
    assert marker.exists(), "no worker was killed: the test did not test anything"
    rows = rows_by_key(tmp_path / "out")
    assert set(rows) == set(res.keys) and len(rows) == 4
    assert all(r["status"] == "ok" for r in rows.values()), [r["error"] for r in rows.values()]
    assert res.failed == 0


def write_spec(path, methods=("ferrari", "lut_speed"), recursions=(1, 2), u_dc_scale=(1.0, 0.85), drives=None):
    lines = ["[study]", 'cycles = ["WLTC3b"]', f"window_s = {WINDOW}", f"methods = {list(methods)}",
             f"recursions = {list(recursions)}", f"u_dc_scale = {list(u_dc_scale)}"]
    if drives:
        lines.append(f"drives = {list(drives)}")
    path.write_text("\n".join(lines).replace("'", '"') + "\n")
    return path


def study_cli(spec_path, out, *extra):
    return [sys.executable, "-m", "scenarios", "study", str(spec_path), "--out", str(out), *extra]


def test_interrupted_study_resumes_only_missing_runs(tmp_path):
    spec = write_spec(tmp_path / "s.toml")  # 2 x 2 x 2 = 8 runs
    out = tmp_path / "out"
    # one worker, killed (client, scheduler and worker: the process group) after 3 runs
    p = subprocess.Popen(study_cli(spec, out, "--workers", "1"), cwd=ROOT, start_new_session=True,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + patient(120)
        while len(list((out / "parts").glob("*.parquet"))) < 3:
            assert p.poll() is None, "the study ended before it could be interrupted"
            assert time.monotonic() < deadline, f"no 3 runs in {patient(120):g} s"
            time.sleep(0.05)
    finally:
        os.killpg(p.pid, signal.SIGKILL)
        p.wait(30)
    k = len(rows_by_key(out))
    assert 3 <= k < 8
    resumed_at = time.time()
    r = subprocess.run(study_cli(spec, out, "--workers", "2"), cwd=ROOT, capture_output=True, text=True,
                       timeout=patient(300))
    assert r.returncode == 0, r.stderr
    assert f"{8 - k} runs executed (0 failed), {k} done before" in r.stdout
    rows = rows_by_key(out)
    assert len(rows) == 8 and all(x["status"] == "ok" for x in rows.values())
    started_now = [x for x in rows.values() if x["started_utc"] >= resumed_at]
    assert len(started_now) == 8 - k, "only the missing runs ran again"
    assert not list((out / "parts").glob("*.parquet")), "the parts are folded into runs.parquet"
    assert (out / "report.md").exists()


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def stop(proc):
    if proc.poll() is None:
        proc.terminate()
        try:
            proc.wait(15)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait(15)


def test_study_on_a_separately_started_scheduler_and_workers(tmp_path):
    from distributed import Client

    port = free_port()
    address = f"tcp://127.0.0.1:{port}"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}  # the workers import this checkout's scenarios
    log = open(tmp_path / "cluster.log", "w")
    scheduler = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                  "--port", str(port), "--no-dashboard"], cwd=tmp_path, env=env, stdout=log,
                                 stderr=subprocess.STDOUT)
    workers = None
    try:
        workers = subprocess.Popen([sys.executable, "-m", "distributed.cli.dask_worker", address, "--nworkers", "2",
                                    "--nthreads", "1", "--host", "127.0.0.1", "--no-dashboard"], cwd=tmp_path,
                                   env=env, stdout=log, stderr=subprocess.STDOUT)
        with Client(address, timeout="30s") as c:
            c.wait_for_workers(2, timeout=patient(60))
            external = set(c.scheduler_info()["workers"])
        spec = write_spec(tmp_path / "s.toml", recursions=(2,))
        r = subprocess.run(study_cli(spec, tmp_path / "out", "--scheduler", address), cwd=ROOT, capture_output=True,
                           text=True, timeout=patient(300))
        assert r.returncode == 0, r.stderr
        runs = parse({"study": {"cycles": ["WLTC3b"], "window_s": WINDOW, "methods": ["ferrari", "lut_speed"],
                                "recursions": [2], "u_dc_scale": [1.0, 0.85]}}).runs
        from scenarios.core.paths import BUILD_DIR
        from scenarios.study.keys import code_hash, fmu_hash
        from scenarios.study.plan import make_plan
        keys = make_plan(runs, tmp_path / "out", fmu_hash(BUILD_DIR / "fmu"), code_hash(), set()).keys
        rows = assert_rows_equal_direct_runs(tmp_path / "out", runs, keys, tmp_path / "direct")
        assert {x["worker"] for x in rows.values()} <= external
    finally:
        for proc in (workers, scheduler):
            if proc is not None:
                stop(proc)
        log.close()


def test_runs_with_a_bad_map_fail_with_their_message_and_the_others_complete(tmp_path, default_map_path):
    from scenarios.drives.description import DEFAULT_DRIVE

    # a map no reader accepts (fails as the drive loads, on the client) ...
    (tmp_path / "torn.csv").write_text("i_d,i_q,psi_d\n0,0,0\n")
    (tmp_path / "torn.toml").write_text('name = "torn"\n[motor]\nflux_map = "torn.csv"\n')
    # ... and one the Python reader takes but the FMUs refuse (psi_q falling with i_q: the plan asks
    # the build's FMUs, and records their refusal before any run)
    lines, header = [], False
    for line in default_map_path.read_text().splitlines():
        if not line.startswith("#") and header:
            c = line.split(",")
            line = ",".join([*c[:3], repr(-float(c[3]))])
        header = header or not line.startswith("#")
        lines.append(line)
    (tmp_path / "falling.csv").write_text("\n".join(lines) + "\n")
    (tmp_path / "falling.toml").write_text('name = "falling"\n[motor]\nflux_map = "falling.csv"\n')
    spec = write_spec(tmp_path / "s.toml", methods=("ferrari",), recursions=(2,), u_dc_scale=(1.0,),
                      drives=(str(DEFAULT_DRIVE), "torn.toml", "falling.toml"))
    r = subprocess.run(study_cli(spec, tmp_path / "out", "--workers", "2"), cwd=ROOT, capture_output=True, text=True,
                       timeout=patient(300))
    assert r.returncode == 1, r.stderr  # some runs failed
    assert "3 runs executed (2 failed)" in r.stdout
    rows = {os.path.basename(x["drive"]): x for x in read_runs(tmp_path / "out").to_pylist()}
    assert len(rows) == 3
    assert rows["default.toml"]["status"] == "ok" and rows["default.toml"]["drive_name"] == "default"
    torn, falling = rows["torn.toml"], rows["falling.toml"]
    assert torn["status"] == "failed" and "motor.flux_map" in torn["error"] and "torn.csv" in torn["error"]
    assert falling["status"] == "failed" and "motor.flux_map" in falling["error"], falling["error"]
    assert "FMU accepts with this motor; it refuses it" in falling["error"], falling["error"]  # the FMU's words
    assert not falling["worker"], "refused at planning, by the FMUs, before any run"
    assert falling["Wh_per_km"] is None and torn["Wh_per_km"] is None
    report = (tmp_path / "out" / "report.md").read_text()
    assert "## Failed runs" in report and "torn.csv" in report
