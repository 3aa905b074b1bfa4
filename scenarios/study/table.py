"""A study's results on disk: `DIR/runs.parquet` (one row per run: the spec's columns, the run's
summary, where and how it ran) and `DIR/traces/<key>.parquet` (each run's trace).

Durability: the client writes each finished run's row at once as a small part,
`DIR/parts/<key>.parquet` (written to a temporary name, then renamed: a part is whole or
absent); `consolidate` folds the parts into runs.parquet (same rename) at the start and end of
a study. An interrupted study loses only the runs that were in flight. One row per key: a later
row replaces an earlier one (a failed run that is run again and succeeds).
"""
from __future__ import annotations

import csv
import math
import os
import uuid
from dataclasses import asdict, fields, replace
from pathlib import Path

import pyarrow as pa
import pyarrow.csv as pa_csv
import pyarrow.parquet as pq

from scenarios.core.boundary import write_atomically
from scenarios.core.version import VERSION
from scenarios.runs.results import RunSummary
from scenarios.runs.simulate import Conditions
from scenarios.study.spec import Run

RUNS_FILE = "runs.parquet"
PARTS_DIR = "parts"
TRACES_DIR = "traces"

#: parts read into one table at a time when folding them in (memory: one table per batch)
FOLD_BATCH = 256

_ARROW = {str: pa.string(), int: pa.int64(), float: pa.float64(), bool: pa.bool_(), "float | None": pa.float64(),
          "int | None": pa.int64(), "bool | None": pa.bool_(), "str | None": pa.string()}


def _arrow_type(t) -> pa.DataType:
    return _ARROW.get(t) or _ARROW[{"str": str, "int": int, "float": float, "bool": bool}.get(t, t)]


#: the summary's fields that are columns of their own; `method`, `recursion`, `objective` and
#: `conditions` are the spec's columns already, `cycle` (the name with the window) and `drive` (the drive's
#: name) are cycle_name and drive_name (the spec's `cycle` and `drive` are what the spec says)
RENAMED = {"cycle": "cycle_name", "drive": "drive_name"}
SUMMARY_COLUMNS = tuple(f.name for f in fields(RunSummary)
                        if f.name not in ("method", "recursion", "objective", "conditions", *RENAMED))

#: where and how the run ran
META = (("key", pa.string()), ("status", pa.string()), ("error", pa.string()), ("fmu_hash", pa.string()),
        ("code_hash", pa.string()), ("worker", pa.string()), ("started_utc", pa.float64()),
        ("run_wall_s", pa.float64()), ("condition", pa.string()), ("cycle_name", pa.string()),
        ("drive_name", pa.string()), ("lut_u_dc", pa.float64()), ("lut_T_magnet", pa.float64()))

SCHEMA = pa.schema(
    [(f.name, _arrow_type(f.type)) for f in fields(Run)]
    + list(META)
    + [(f.name, _arrow_type(f.type)) for f in fields(RunSummary) if f.name in SUMMARY_COLUMNS])


def row_of(run: Run, meta: dict, summary: RunSummary | None) -> dict:
    """A row of runs.parquet: the run's columns, `meta` (META's keys) and the summary (None:
    a failed run, its summary columns null)."""
    row = {**run.to_dict(), **{k: None for k, _ in META}, **meta}
    d = summary.to_dict() if summary is not None else {}
    for name in SUMMARY_COLUMNS:
        row[name] = d.get(name)
    for name, column in RENAMED.items():
        row[column] = d.get(name)
    if summary is not None:  # the tables' conditions and the objective, as the run resolved them from its drive
        row["lut_u_dc"], row["lut_T_magnet"] = summary.conditions["lut_u_dc"], summary.conditions["lut_T_magnet"]
        row["objective"] = summary.objective
    else:  # a failed run too says which release it failed in
        row["version"] = VERSION
    return row


def row_conditions(row: dict) -> Conditions:
    """The conditions of a row's run, as its summary had them."""
    return replace(Run.of_row(row).conditions(), name=row["condition"], lut_u_dc=row["lut_u_dc"],
                   lut_T_magnet=row["lut_T_magnet"])


def summary_of(row: dict) -> RunSummary:
    """The RunSummary of an "ok" row (inverse of row_of)."""
    run = Run.of_row(row)
    return RunSummary(method=run.method, recursion=run.recursion, objective=run.objective or "current",
                      conditions=asdict(row_conditions(row)),
                      **{name: row[column] for name, column in RENAMED.items()},
                      **{k: row[k] for k in SUMMARY_COLUMNS})


def write_trace_csv(trace_parquet: Path, dest: Path) -> None:
    """A trace as trace.csv (the format of scenarios.runs.results.Trace.write_csv: floats as repr)."""
    t = pq.read_table(trace_parquet)
    def write(tmp: Path) -> None:
        with open(tmp, "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(t.column_names)
            w.writerows(zip(*(t.column(n).to_pylist() for n in t.column_names)))
    write_atomically(dest, write)


def _atomic_write_table(table: pa.Table, path: Path) -> None:
    write_atomically(path, lambda tmp: pq.write_table(table, tmp))


def write_part(out: Path, row: dict) -> Path:
    """The row of a finished run, durably, as DIR/parts/<key>.parquet."""
    parts = Path(out) / PARTS_DIR
    parts.mkdir(parents=True, exist_ok=True)
    path = parts / f"{row['key']}.parquet"
    _atomic_write_table(pa.Table.from_pylist([row], schema=SCHEMA), path)
    return path


#: the columns without which a file is not a study's: the run's identity and its outcome
REQUIRED = ("key", "status", *(f.name for f in fields(Run)))
QUARANTINE_DIR = "quarantine"


class Foreign(ValueError):
    """A file in a study's folder that is not one of its tables (corrupt, empty, another schema)."""


def _read(path: Path) -> pa.Table:
    try:
        t = pq.read_table(path)
    except Exception as e:  # ArrowInvalid, OSError: a torn or foreign file
        raise Foreign(f"not a Parquet table ({type(e).__name__}: {e})") from None
    missing = [n for n in REQUIRED if n not in t.column_names]
    if missing:
        raise Foreign(f"not a study's table: no column {missing[0]!r}")
    unknown = [n for n in t.column_names if n not in SCHEMA.names]
    if unknown:
        raise Foreign(f"not this study's schema: unknown column {unknown[0]!r}")
    # columns added since the file was written are null
    try:
        cols = [t.column(n).cast(f.type) if n in t.column_names else pa.nulls(t.num_rows, f.type)
                for n, f in zip(SCHEMA.names, SCHEMA)]
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError) as e:
        raise Foreign(f"not this study's schema ({e})") from None
    table = pa.Table.from_arrays(cols, schema=SCHEMA)
    if table.column("key").null_count:
        raise Foreign("rows without a key")
    return table


def quarantine(out: Path, path: Path, why: str) -> Path | None:
    """Move a file that cannot be read as a study's table to DIR/quarantine/ (kept for a look, out
    of the way of every resume: the runs it held are run again) and say so on stderr."""
    import sys
    import time
    dest_dir = Path(out) / QUARANTINE_DIR
    dest_dir.mkdir(parents=True, exist_ok=True)
    dest = dest_dir / f"{path.name}.{time.strftime('%Y%m%dT%H%M%S')}.{uuid.uuid4().hex[:8]}"
    try:
        os.replace(path, dest)
    except FileNotFoundError:  # gone meanwhile (a writer's rename): nothing to keep
        return None
    print(f"study: {path}: {why}; moved to {dest}, its runs will run again", file=sys.stderr)
    return dest


def _read_or_quarantine(out: Path, path: Path) -> pa.Table | None:
    try:
        return _read(path)
    except Foreign as e:
        quarantine(out, path, str(e))
        return None
    except FileNotFoundError:
        return None


def _parts(out: Path) -> list[tuple[Path, tuple[int, int]]]:
    """The parts, oldest first, each with its (inode, mtime) when listed; a part that vanishes
    meanwhile (a writer's rename, a parallel consolidate) is left out."""
    d = Path(out) / PARTS_DIR
    found = []
    for p in (d.glob("*.parquet") if d.is_dir() else ()):
        try:
            st = p.stat()
        except FileNotFoundError:
            continue
        found.append((p, (st.st_ino, st.st_mtime_ns)))
    return sorted(found, key=lambda x: x[1][1])


def _latest(tables: list[pa.Table]) -> pa.Table:
    """One row per key: in write order, a later row of a key replaces the earlier."""
    if not tables:
        return SCHEMA.empty_table()
    t = pa.concat_tables(tables).combine_chunks()
    last = {k: i for i, k in enumerate(t.column("key").to_pylist())}
    return t.take(pa.array(sorted(last.values()), type=pa.int64()))


def read_runs(out: Path, parts: list | None = None) -> pa.Table:
    """runs.parquet with the parts not yet folded in; corrupt or foreign files are quarantined."""
    runs = Path(out) / RUNS_FILE
    parts = _parts(out) if parts is None else parts
    tables = []
    if runs.exists():
        t = _read_or_quarantine(out, runs)
        if t is not None:
            tables.append(t)
    for i in range(0, len(parts), FOLD_BATCH):  # a few large tables, not one small table per part
        batch = [t for t in (_read_or_quarantine(out, p) for p, _ in parts[i:i + FOLD_BATCH]) if t is not None]
        if batch:
            tables.append(pa.concat_tables(batch).combine_chunks())
    return _latest(tables)


def consolidate(out: Path) -> pa.Table:
    """Fold DIR/parts/* into DIR/runs.parquet; returns the table. Safe beside running writers: a
    part that appears meanwhile stays for the next fold, and a part is removed only if it is still
    the very file that was read (same inode and mtime)."""
    parts = _parts(out)
    table = read_runs(out, parts)
    if parts:
        _atomic_write_table(table, Path(out) / RUNS_FILE)
        for p, seen in parts:
            try:
                st = p.stat()
            except FileNotFoundError:
                continue
            if (st.st_ino, st.st_mtime_ns) == seen:
                p.unlink(missing_ok=True)
    return table


def done_keys(table: pa.Table) -> set[str]:
    """Keys of the runs that finished "ok" (a failed run is run again: see execute.py)."""
    return {r["key"] for r in table.select(["key", "status"]).to_pylist() if r["status"] == "ok"}


def trace_path(out: Path, key: str) -> Path:
    return Path(out) / TRACES_DIR / f"{key}.parquet"


def write_trace_parquet(trace_csv: Path, dest: Path) -> None:
    """A run's trace.csv (scenarios.runs.results; floats written as repr, so exact) as Parquet.
    A `nan` stays a float NaN (pyarrow's default reads it as null, and a column of them as nulls)."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    table = pa_csv.read_csv(trace_csv, convert_options=pa_csv.ConvertOptions(null_values=[]))
    _atomic_write_table(table, dest)


def is_nan(x) -> bool:
    return x is None or (isinstance(x, float) and math.isnan(x))
