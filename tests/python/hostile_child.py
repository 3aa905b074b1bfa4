"""One FMU instance in a child process with an address-space limit (test_hostile_bounds.py): what a
hostile flux map costs must be a clear fmi2Error, not an exhausted machine, a crash or a hang.

python hostile_child.py FMU WORKDIR MAP GOOD_MAP HEADROOM_MB
Loads FMU, limits the address space to what the process has mapped plus HEADROOM_MB (not under
the sanitizers, whose shadow memory needs terabytes of address space), sets flux_map = MAP, calls
fmi2ExitInitializationMode, then flux_map = GOOD_MAP and again (the instance must stay usable).
Prints one JSON line: the two statuses and every log message as raw bytes decoded with
'backslashreplace', and whether each message was valid UTF-8.
"""
from __future__ import annotations

import ctypes as C
import json
import os
import resource
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import fmi2_raw as raw  # noqa: E402


class RawLogger(raw.Logger):
    """Keeps the messages' bytes: fmi2_raw.Logger's strict decoding would lose an invalid one."""

    def _log(self, env, instance, status, category, message):
        self.records.append((status, (category or b"").decode(), message or b""))


def mapped_bytes() -> int:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmSize:"):
            return int(line.split()[1]) * 1024
    raise RuntimeError("no VmSize in /proc/self/status")


def set_path(inst: raw.Instance, path: str) -> int:
    """flux_map = path as the file system's bytes (a Latin-1 name stays Latin-1)."""
    ref = raw.vrs([inst.fmu.vars["flux_map"].valueReference])
    return inst.fmu.fmi2SetString(inst.c, ref, 1, (C.c_char_p * 1)(os.fsencode(path)))


def main(fmu: str, workdir: str, map_path: str, good: str, headroom_mb: str) -> None:
    u = raw.Unzipped(fmu, workdir)
    log = RawLogger()
    inst = raw.Instance(u, "child", logger=log, logging_on=True)
    if os.environ.get("IPMSM_UNDER_SANITIZER") != "1":
        limit = mapped_bytes() + int(headroom_mb) * 2**20
        resource.setrlimit(resource.RLIMIT_AS, (limit, limit))
    assert inst.setup() == raw.OK and inst.enter() == raw.OK
    assert set_path(inst, map_path) == raw.OK
    first = inst.exit()
    assert set_path(inst, good) == raw.OK
    second = inst.exit()
    messages = []
    for status, category, m in log.records:
        try:
            m.decode("utf-8")
            valid = True
        except UnicodeDecodeError:
            valid = False
        messages.append({"status": status, "category": category, "valid_utf8": valid, "length": len(m),
                         "text": m.decode("utf-8", "backslashreplace")[:2000]})
    print(json.dumps({"first": first, "second": second, "messages": messages}))
    inst.free()


if __name__ == "__main__":
    main(*sys.argv[1:])
