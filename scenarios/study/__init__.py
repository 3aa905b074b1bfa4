"""Parameter studies on dask.distributed, resumable and fault-tolerant (issue 18; the contract:
docs/spec/INTERFACE.md, "Study specification (TOML)"): `python -m scenarios study SPEC.toml`.

spec (TOML -> runs), keys (a run's key), plan (runs -> tasks), execute (a run on a worker),
runner (the client's loop), table (runs.parquet, traces), report (report.md from runs.parquet),
progress (stderr). docs/studies.md: running on a cluster.
"""
from scenarios.study.runner import StudyError, StudyResult, run_study
from scenarios.study.spec import Run, SpecError, StudySpec, load_spec, parse

__all__ = ["Run", "SpecError", "StudyError", "StudyResult", "StudySpec", "load_spec", "parse", "run_study"]
