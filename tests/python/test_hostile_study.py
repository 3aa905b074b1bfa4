"""Studies under hostile files and peers (issue 24): a corrupt runs.parquet, a 0-byte part and a
part of a foreign schema are quarantined and their runs run again, to exactly one row per run
(a real LocalCluster on 127.0.0.1); a window in which the car stands reports; consolidate beside
running writers loses nothing and raises nothing; the FMU cache trusts content, not a marker;
a scheduler address that accepts and never speaks, or speaks another protocol, is refused
within its timeout."""
from __future__ import annotations

import socket
import threading
import time

import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from scenarios.study import parse, run_study
from scenarios.study import table as study_table
from scenarios.study.report import write_report
from scenarios.study.runner import StudyError, probe_scheduler
from scenarios.study.table import QUARANTINE_DIR, consolidate, read_runs, write_part

from conftest import patient

#: UDDS's first 5 s: the car stands (Wh_per_km undefined); two recursions, two runs
SPEC = {"study": {"cycles": ["UDDS"], "window_s": [0.0, 5.0], "recursions": [1, 2]}}


def one_row_per_run(out, keys) -> list[dict]:
    rows = read_runs(out).to_pylist()
    assert sorted(r["key"] for r in rows) == sorted(keys), "exactly one row per run"
    return rows


def test_corrupt_empty_and_foreign_files_are_quarantined_and_run_again(tmp_path):
    runs = parse(SPEC).runs
    out = tmp_path / "out"
    res = run_study(runs, out, workers=1, progress=False)
    assert (res.executed, res.failed) == (2, 0)
    rows = one_row_per_run(out, res.keys)
    assert all(r["Wh_per_km"] is None or r["Wh_per_km"] != r["Wh_per_km"] for r in rows)  # the car stood
    report = write_report(out, res.table)
    assert "| – |" in report.read_text()
    # now break everything a resume reads
    (out / "runs.parquet").write_bytes(b"PAR1 this is not a parquet file")
    parts = out / "parts"
    parts.mkdir(exist_ok=True)
    (parts / "empty.parquet").write_bytes(b"")
    pq.write_table(pa.table({"key": ["x"], "colour": ["red"]}), parts / "foreign.parquet")
    again = run_study(runs, out, workers=1, progress=False)
    assert (again.executed, again.failed) == (2, 0), "the quarantined runs ran again"
    one_row_per_run(out, res.keys)
    assert len(list((out / QUARANTINE_DIR).iterdir())) == 3
    write_report(out)
    third = run_study(runs, out, workers=1, progress=False)
    assert (third.executed, third.skipped) == (0, 2)


def _row(key: str) -> dict:
    runs = parse({"study": {"cycles": ["UDDS"]}}).runs
    return study_table.row_of(runs[0], dict(key=key, status="ok", fmu_hash="f", code_hash="c"), None)


def test_consolidate_beside_running_writers_loses_nothing(tmp_path):
    out = tmp_path / "out"
    keys = [f"k{i:04d}" for i in range(300)]
    errors = []

    def writer():
        try:
            for k in keys:
                write_part(out, _row(k))
        except Exception as e:  # noqa: BLE001 - the test reports any
            errors.append(e)

    t = threading.Thread(target=writer)
    t.start()
    while t.is_alive():
        consolidate(out)   # must neither raise nor drop a part written meanwhile
    t.join()
    final = consolidate(out)
    assert not errors
    assert sorted(final.column("key").to_pylist()) == keys


def test_the_fmu_cache_trusts_content_not_a_marker(tmp_path, monkeypatch):
    from scenarios.study import ship
    monkeypatch.setattr(ship.tempfile, "gettempdir", lambda: str(tmp_path))
    files = (("fmu/A.fmu", b"the real bytes"),)
    folder = ship._cache() / "build-x"
    (folder / "fmu").mkdir(parents=True)
    (folder / "fmu" / "A.fmu").write_bytes(b"planted")
    (folder / ".complete").touch()
    ship._write_once(folder, files)
    assert (folder / "fmu" / "A.fmu").read_bytes() == b"the real bytes"
    assert oct(ship._cache().stat().st_mode & 0o777) == "0o700"


def _server(speak: bytes | None):
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(8)
    held = []

    def serve():
        while True:
            try:
                c, _ = s.accept()
            except OSError:
                return
            held.append(c)
            if speak is not None:
                c.sendall(speak)

    threading.Thread(target=serve, daemon=True).start()
    return s, f"tcp://127.0.0.1:{s.getsockname()[1]}"


@pytest.mark.parametrize("speak,words", [(None, "did not answer within 1 s"),
                                         (b"HTTP/1.1 200 OK\r\n\r\n", "does not speak dask's protocol"),
                                         (b"", "did not answer")])
def test_a_scheduler_that_never_speaks_or_speaks_another_protocol_is_refused_in_time(speak, words):
    s, address = _server(speak)
    try:
        t0 = time.perf_counter()
        with pytest.raises(StudyError, match=words):
            probe_scheduler(address, timeout=1.0)
        assert time.perf_counter() - t0 < patient(5.0)
    finally:
        s.close()


def test_no_server_at_all_is_named():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    with pytest.raises(StudyError, match="no dask scheduler"):
        probe_scheduler(f"tcp://127.0.0.1:{port}", timeout=1.0)
