"""What a study ships to its workers, so that they need nothing of the client's files: the
build's FMUs once per worker, each drive description with
the files it names (flux map, OCV curve) once per drive. A worker writes what it receives under
its machine's temp directory, in folders named after the content's hash, once (temporary name,
then rename: concurrent workers on one machine do not race)."""
from __future__ import annotations

import hashlib
import os
import stat
import tempfile
import uuid
from dataclasses import dataclass, replace
from pathlib import Path

from scenarios.drives.description import DriveDescription
from scenarios.study import keys


def _sha(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def _same_content(path: Path, data: bytes) -> bool:
    """`path` is a regular file of this user (not a link) whose bytes hash as `data`'s."""
    try:
        st = os.lstat(path)
        if not stat.S_ISREG(st.st_mode) or st.st_uid != os.getuid() or st.st_size != len(data):
            return False
        return _sha(path.read_bytes()) == _sha(data)
    except OSError:
        return False


def _write_once(folder: Path, files) -> Path:
    """`files` ((relative path, bytes), ...) in `folder`: each file verified by its content hash
    (a marker file proves nothing: anything found that differs is written again)."""
    for rel, data in files:
        dest = folder / rel
        if _same_content(dest, data):
            continue
        dest.parent.mkdir(parents=True, exist_ok=True)
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.{uuid.uuid4().hex[:8]}.tmp")
        tmp.write_bytes(data)
        os.chmod(tmp, 0o755)
        os.replace(tmp, dest)
    return folder


def _cache() -> Path:
    """This user's cache under the temp directory, 0700: another local user can neither plant
    files in it nor read them; a path that is not this user's own folder is not used."""
    d = Path(tempfile.gettempdir()) / f"ipmsm-study-{os.getuid()}"
    try:
        d.mkdir(mode=0o700, exist_ok=True)
        st = os.lstat(d)
        if stat.S_ISDIR(st.st_mode) and st.st_uid == os.getuid():
            if stat.S_IMODE(st.st_mode) != 0o700:
                os.chmod(d, 0o700)
            return d
    except OSError:
        pass
    return Path(tempfile.mkdtemp(prefix="ipmsm-study-"))


@dataclass(frozen=True)
class FmuBundle:
    """The build's FMUs as bytes, by path relative to the build."""

    hash: str                 # the FMUs' content hash (keys.fmu_hash), in every row
    files: tuple[tuple[str, bytes], ...]

    @classmethod
    def of(cls, build: Path) -> FmuBundle:
        build = Path(build)
        missing = [n for n in keys.FMU_NAMES if not (build / "fmu" / n).is_file()]
        if missing:
            raise FileNotFoundError(f"{build / 'fmu'}: {', '.join(missing)} missing: build first")
        rel = [f"fmu/{n}" for n in keys.FMU_NAMES]
        return cls(keys.fmu_hash(build / "fmu"), tuple((r, (build / r).read_bytes()) for r in rel))

    def materialise(self) -> Path:
        """The bundle as a build folder (fmu/, lib/) on this machine."""
        h = hashlib.sha256(b"".join(r.encode() + b"\0" + _sha(d).encode() for r, d in self.files)).hexdigest()
        return _write_once(_cache() / f"build-{h[:16]}", self.files)


@dataclass(frozen=True)
class ShippedDrive:
    """A loaded drive description and the content of the files it names."""

    drive: DriveDescription
    flux_map: bytes
    ocv_csv: bytes

    @classmethod
    def of(cls, drive: DriveDescription) -> ShippedDrive:
        return cls(drive, Path(drive.motor.flux_map).read_bytes(), Path(drive.battery.ocv_csv).read_bytes())

    def content_hash(self) -> str:
        """What the drive is: its file, its map's and its OCV curve's content."""
        return _sha(f"{self.drive.sha256}:{_sha(self.flux_map)}:{_sha(self.ocv_csv)}".encode())

    def localise(self) -> DriveDescription:
        """The drive with its files written on this machine and named there."""
        files = {"flux_map": (Path(self.drive.motor.flux_map).name, self.flux_map),
                 "ocv_csv": (Path(self.drive.battery.ocv_csv).name, self.ocv_csv)}
        local = {}
        for role, (name, data) in files.items():
            local[role] = _write_once(_cache() / f"file-{_sha(data)[:24]}", [(name, data)]) / name
        d = self.drive
        return replace(d, motor=replace(d.motor, flux_map=local["flux_map"]),
                       battery=replace(d.battery, ocv_csv=local["ocv_csv"]))
