"""The import cache: a map that needs converting (a .mat, a half-map CSV) is imported once and the
contract CSV kept, so the next run reads it directly. Trusted only as far as it is checked:

- keyed by content: the name holds the SHA-256 of the source's bytes and the importer's version;
  the cached CSV's own SHA-256 is kept beside it (NAME.sha256) and checked at every use, so a
  cached map edited afterwards is imported again, never used;
- owned: the cache folder and every file used from it belong to this user, are not links and are
  writable by nobody else (else the cache is not used: the map is imported again, into a private
  temporary folder);
- optional: a cache that cannot be made or written (an unwritable HOME, a read-only disk) is no
  error: the import goes to a private temporary folder that lives as long as the process.
"""
from __future__ import annotations

import atexit
import hashlib
import os
import shutil
import stat
import tempfile
from pathlib import Path

_private: Path | None = None  # this process's fallback folder (0700, removed at exit)


def cache_dir() -> Path:
    """Where imported maps are cached: $IPMSM_MAP_CACHE, else $XDG_CACHE_HOME/ipmsm-fmu/maps,
    else ~/.cache/ipmsm-fmu/maps."""
    if os.environ.get("IPMSM_MAP_CACHE"):
        return Path(os.environ["IPMSM_MAP_CACHE"])
    try:
        home = Path.home()
    except (RuntimeError, KeyError):  # no HOME, no passwd entry
        home = Path(tempfile.gettempdir())
    base = os.environ.get("XDG_CACHE_HOME") or home / ".cache"
    return Path(base) / "ipmsm-fmu" / "maps"


def _owned(path: Path, folder: bool) -> bool:
    """`path` is this user's (a real folder or regular file, no link), writable by nobody else."""
    try:
        st = os.lstat(path)
    except OSError:
        return False
    kind = stat.S_ISDIR(st.st_mode) if folder else stat.S_ISREG(st.st_mode)
    mine = not hasattr(os, "getuid") or st.st_uid == os.getuid()
    return kind and mine and not st.st_mode & (stat.S_IWGRP | stat.S_IWOTH)


def _private_dir() -> Path:
    global _private
    if _private is None:
        _private = Path(tempfile.mkdtemp(prefix="ipmsm-map-import-"))  # 0700, this user's
        atexit.register(shutil.rmtree, _private, True)
    return _private


def usable_dir() -> Path:
    """The cache folder if it can be used (made 0700 if missing, this user's, writable by nobody
    else, writable by us), else this process's private temporary folder."""
    d = cache_dir()
    try:
        d.mkdir(parents=True, exist_ok=True, mode=0o700)
        if _owned(d, folder=True) and os.access(d, os.W_OK | os.X_OK):
            return d
    except OSError:
        pass
    return _private_dir()


def _sha256(path: Path) -> str | None:
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "sha256").hexdigest()
    except OSError:
        return None


def trusted(path: Path) -> bool:
    """A cached file that may be used: this user's, nobody else's to write, in a folder of the
    same kind, with the content its sidecar's hash says."""
    side = path.with_name(path.name + ".sha256")
    if not (_owned(path.parent, folder=True) and _owned(path, folder=False) and _owned(side, folder=False)):
        return False
    try:
        want = side.read_text().strip()
    except OSError:
        return False
    return _sha256(path) == want


def seal(path: Path) -> None:
    """Record `path`'s content hash beside it (a failure: the entry is simply not trusted later)."""
    from scenarios.core.boundary import write_atomically
    digest = _sha256(path)
    if digest is not None:
        try:
            write_atomically(path.with_name(path.name + ".sha256"), digest + "\n")
        except (OSError, ValueError):
            pass


def contract_csv(path: str | Path) -> Path:
    """A contract CSV for `path`: a CSV that needs no conversion is checked and returned as is;
    anything else is imported once into the cache (the name keyed by the source's content and the
    importer's version, the output checked by its own hash at every use) and that CSV returned."""
    from scenarios.maps.importer import import_map, write_contract_csv
    path = Path(path)
    key = _key(path) if path.is_file() else None
    folder = usable_dir()
    cached = folder / key if key is not None else None
    if cached is not None and trusted(cached):
        return cached  # imported before, from these very bytes, and unchanged since
    as_is = cached.with_suffix(".as-is") if cached is not None else None
    if as_is is not None and trusted(as_is):
        return path  # checked before, these very bytes: a contract CSV that needs no conversion
    imported = import_map(path)
    if imported.source_format == "contract CSV" and not imported.notes:
        if as_is is not None:
            try:
                from scenarios.core.boundary import write_atomically
                write_atomically(as_is, f"{path}\n")
                seal(as_is)
            except (OSError, ValueError):
                pass  # no cache: checked again next time
        return path
    if cached is None:
        cached = _private_dir() / f"{path.stem}.csv"
    try:
        out = write_contract_csv(imported, cached)
    except OSError:  # the cache went away or filled up: the private folder
        out = write_contract_csv(imported, _private_dir() / cached.name)
    seal(out)
    return out


def _key(path: Path) -> str | None:
    """The cache's name for these bytes; None for a file the FMUs' size limit refuses (import_map
    then says why), so that no unknown file is read whole into memory."""
    from scenarios.core.boundary import InputError, read_bounded
    from scenarios.core.fmu_ranges import map_limits
    from scenarios.maps.importer import IMPORTER_VERSION
    try:
        h = hashlib.sha256(read_bounded(path, map_limits().max_bytes, "flux map"))
    except InputError:
        return None
    h.update(f"importer {IMPORTER_VERSION}".encode())
    return f"{path.stem}-{h.hexdigest()[:16]}.csv"
