"""The input boundary and the output discipline of every command (docs/inputs.md).

Inputs: `InputError` (file, key or line, what was expected) is the one refusal; the CLI turns it
into exit 2 and one line. `read_bounded` reads a regular file of bounded size without ever
holding more than the bound; `load_toml` parses a TOML file after bounding its bytes, its lines
and its nesting (tomllib recurses per level and a long dotted key costs memory quadratically).

Outputs: `strict_json` (never NaN or Infinity: null, the status beside it says why),
`write_atomically` (a temporary file beside the target, checked, made 0644, renamed: a reader
sees the old file or the whole new one), `check_writable` (before any run starts).
"""
from __future__ import annotations

import json
import math
import os
import stat
import tempfile
from collections.abc import Callable
from pathlib import Path

import tomllib


class InputError(ValueError):
    """An input that cannot be used: which file, which key or line, what was expected."""

    def __init__(self, file: str | Path | None, key: str, expected: str):
        self.file, self.key, self.expected = file, key, expected
        super().__init__(f"{printable(str(file))}: {printable(key)}: {printable(expected, limit=1000)}")

    def __reduce__(self):  # picklable (Dask sends errors back from its workers)
        return type(self), (self.file, self.key, self.expected)


def printable(text: str, limit: int = 300) -> str:
    """`text` for one line of a terminal: control characters, surrogates (undecodable file
    names) and other non-printables escaped, at most `limit` characters."""
    out = text if text.isprintable() else "".join(c if c.isprintable() else ascii(c)[1:-1] for c in text)
    return out if len(out) <= limit else out[:limit] + "..."


# -- reading --------------------------------------------------------------------------------------
#: a drive description or a study specification is a page of keys; 1 MiB is thousands of pages
TOML_MAX_BYTES = 1 << 20
#: longer lines than this are no hand-written key (the FMUs' map reader has the same line bound)
TOML_MAX_LINE = 4096
#: tables and arrays nested deeper than this are no drive or study (they use at most 3)
TOML_MAX_DEPTH = 16


def read_bounded(path: str | Path, max_bytes: int, what: str) -> bytes:
    """The bytes of a regular file of at most `max_bytes` (a device, a pipe, a folder, a larger
    file: InputError, without reading it)."""
    path = Path(path)
    try:
        fd = os.open(path, os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0))
    except (OSError, ValueError) as e:  # ValueError: a NUL in the path
        raise InputError(path, "(file)", f"a readable {what} ({getattr(e, 'strerror', None) or e})") from None
    try:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise InputError(path, "(file)", f"a regular file ({what}), not a folder, device or pipe")
        if st.st_size > max_bytes:
            raise InputError(path, "(file)", f"a {what} of at most {max_bytes} bytes, it has {st.st_size}")
        chunks, n = [], 0
        while True:
            b = os.read(fd, 1 << 20)
            if not b:
                break
            n += len(b)
            if n > max_bytes:  # grew while read
                raise InputError(path, "(file)", f"a {what} of at most {max_bytes} bytes")
            chunks.append(b)
        return b"".join(chunks)
    except OSError as e:
        raise InputError(path, "(file)", f"a readable {what} ({e.strerror or e})") from None
    finally:
        os.close(fd)


def decode_utf8(path: Path, raw: bytes, what: str) -> str:
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as e:
        line = raw[:e.start].count(b"\n") + 1
        raise InputError(path, f"line {line}", f"UTF-8 text ({what}), byte {raw[e.start]:#04x} is not") from None


def _nesting(text: str) -> tuple[int, int]:
    """The deepest nesting of [ and { outside strings and comments, and the line it is on.
    Conservative: it only has to bound what tomllib's recursion meets."""
    depth = deepest = 0
    where = 1
    line = 1
    quote = ""
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            if quote in ('"', "'"):
                quote = ""
        elif quote:
            if text.startswith(quote, i):
                i += len(quote)
                quote = ""
                continue
            if c == "\\" and quote.startswith('"'):
                i += 2
                continue
        elif c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        elif c in "\"'":
            quote = c * 3 if text.startswith(c * 3, i) else c
            i += len(quote)
            continue
        elif c in "[{":
            depth += 1
            if depth > deepest:
                deepest, where = depth, line
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return deepest, where


def load_toml(path: str | Path, what: str) -> tuple[dict, bytes]:
    """A TOML file, parsed after its size, line lengths and nesting are bounded: (document, bytes)."""
    path = Path(path)
    raw = read_bounded(path, TOML_MAX_BYTES, what)
    text = decode_utf8(path, raw, what)
    for i, line in enumerate(text.split("\n"), 1):
        if len(line) > TOML_MAX_LINE:
            raise InputError(path, f"line {i}", f"at most {TOML_MAX_LINE} characters a line, it has {len(line)}")
        if line.count(".") > TOML_MAX_DEPTH * 4 and "=" in line and line.split("=", 1)[0].count(".") > TOML_MAX_DEPTH:
            raise InputError(path, f"line {i}", f"a key of at most {TOML_MAX_DEPTH} dotted parts")
    deepest, where = _nesting(text)
    if deepest > TOML_MAX_DEPTH:
        raise InputError(path, f"line {where}", f"arrays and tables nested at most {TOML_MAX_DEPTH} deep")
    try:
        return tomllib.loads(text), raw
    except tomllib.TOMLDecodeError as e:
        raise InputError(path, "(syntax)", f"valid TOML ({e})") from None
    except RecursionError:
        raise InputError(path, "(syntax)", f"arrays and tables nested at most {TOML_MAX_DEPTH} deep") from None


def finite(value: float, where: str | Path, key: str, lo: float | None = None, hi: float | None = None,
           lo_open: bool = False) -> float:
    """A command-line or file number: finite and in [lo, hi] (lo open with lo_open), else InputError."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    try:
        x = float(value) if ok else math.nan
    except OverflowError:
        x = math.inf
    if not math.isfinite(x) or (lo is not None and (x < lo or (lo_open and x == lo))) or (hi is not None and x > hi):
        rng = ("" if lo is None and hi is None else
               f" in {'(' if lo_open else '['}{'-inf' if lo is None else f'{lo:g}'}, "
               f"{'inf' if hi is None else f'{hi:g}'}]")
        raise InputError(where, key, f"a finite number{rng}, got {value!r}")
    return x


# -- writing --------------------------------------------------------------------------------------
OUTPUT_MODE = 0o644


def strict(obj):
    """`obj` with every non-finite float replaced by None (JSON null), recursively."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: strict(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [strict(v) for v in obj]
    if hasattr(obj, "item") and callable(obj.item) and getattr(obj, "shape", None) == ():  # numpy scalars
        return strict(obj.item())
    return obj


def strict_json(obj, indent: int | None = 2) -> str:
    """JSON any strict reader accepts: NaN and Infinity become null (allow_nan=False checks it)."""
    return json.dumps(strict(obj), indent=indent, allow_nan=False)


def _kind(mode: int) -> str:
    return ("folder" if stat.S_ISDIR(mode) else "FIFO" if stat.S_ISFIFO(mode) else "socket" if stat.S_ISSOCK(mode)
            else "device" if stat.S_ISCHR(mode) or stat.S_ISBLK(mode) else "special file")


def output_target(path: str | Path, what: str = "output", root: str | Path | None = None) -> Path:
    """Where writing `path` lands, refused (InputError naming `what`) unless an output may go
    there: nothing yet, or a regular file; through a symlink only to an existing regular file
    inside `root` (None: the link's own folder), so a link stays a link. A device, a FIFO, a
    folder, a dangling link or one leading out of `root` is refused and left as it is: an output
    replaces only a file it could have written."""
    path = Path(path)
    try:
        st = os.lstat(path)
    except FileNotFoundError:
        return path
    except (OSError, ValueError) as e:
        raise InputError(path, what, f"a path an output can be written to ({getattr(e, 'strerror', None) or e})") \
            from None
    if stat.S_ISLNK(st.st_mode):
        real = Path(os.path.realpath(path))
        base = Path(os.path.realpath(root if root is not None else path.parent))
        try:
            rst = os.stat(real)
        except OSError:  # a link to a file not written yet: only into an existing folder inside root
            if real.parent.is_dir() and (real.parent == base or base in real.parents):
                return real
            raise InputError(path, what, f"a regular file or a link to one in an existing folder inside {base}; "
                             f"this link leads nowhere ({real}), and no folder is made through a link") from None
        if not stat.S_ISREG(rst.st_mode):
            raise InputError(path, what, f"a regular file or a link to one; this link leads to a {_kind(rst.st_mode)} "
                             f"({real}), left as it is")
        if base not in real.parents:
            raise InputError(path, what, f"a link that stays inside {base}; it leads to {real}")
        return real
    if not stat.S_ISREG(st.st_mode):
        raise InputError(path, what, f"a regular file (or nothing) to write; it is a {_kind(st.st_mode)}, left as "
                         "it is")
    return path


def folders_made_here(path: str | Path, what: str) -> None:
    """The missing folders of `path` would be made where the path says, not through a link: the
    nearest existing ancestor is no link and has none above it (InputError, nothing made)."""
    p = Path(os.path.abspath(path))
    while not os.path.lexists(p) and p != p.parent:
        p = p.parent
    if p != Path(path).absolute() and os.path.realpath(p) != str(p):
        raise InputError(path, what, f"a path whose missing folders are not made through a link ({p} leads to "
                         f"{os.path.realpath(p)}): make the folder, or name the real one")


def check_outputs(folder: str | Path, names, what: str = "--out") -> None:
    """Every named output in `folder` is one write_atomically may replace (before a run starts)."""
    for name in names:
        output_target(Path(folder) / name, what, folder)


def write_atomically(path: str | Path, data: bytes | str | Callable[[Path], None],
                     verify: Callable[[Path], None] | None = None, what: str = "output",
                     root: str | Path | None = None) -> Path:
    """`data` (bytes, text, or a function writing the temporary path) to `path`: written beside
    it, flushed, checked by `verify` (raises on a bad file), made 0644 (whatever the umask: an
    output is for others to read), renamed over the target. The target is output_target's (a
    device, a FIFO, a link out of `root`: InputError, nothing touched); missing folders are made
    on the path as given, never through a link."""
    path = output_target(Path(path), what, root)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        if callable(data):
            os.close(fd)
            fd = -1
            data(Path(tmp))
        else:
            with os.fdopen(fd, "wb") as f:
                fd = -1
                f.write(data.encode("utf-8") if isinstance(data, str) else data)
                f.flush()
                os.fsync(f.fileno())
        if verify is not None:
            verify(Path(tmp))
        os.chmod(tmp, OUTPUT_MODE)
        os.replace(tmp, path)
    except BaseException:
        if fd >= 0:
            os.close(fd)
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def check_writable(folder: str | Path, what: str = "--out") -> Path:
    """`folder` exists (made if need be) and takes a file; else InputError naming it. Called
    before any run starts, so a run's hours are never lost to a folder that cannot be written."""
    folder = Path(folder)
    try:
        os.fsencode(str(folder))
        folder.mkdir(parents=True, exist_ok=True)
        fd, probe = tempfile.mkstemp(prefix=".write-probe.", dir=folder)
        os.close(fd)
        os.unlink(probe)
    except (OSError, ValueError, UnicodeError) as e:
        raise InputError(folder, what, f"a folder this user can write ({getattr(e, 'strerror', None) or e})") \
            from None
    return folder


def inside(base: Path, name: str, what: str) -> Path:
    """base / name, refused (InputError) if it would leave `base` (.., absolute, a NUL)."""
    base = Path(base).resolve()
    if "\0" in name or not name or name in (".", ".."):
        raise InputError(base, what, f"a plain file name, got {name!r}")
    p = (base / name).resolve()
    if p != base and base not in p.parents:
        raise InputError(base, what, f"a name that stays inside {base}, got {name!r}")
    return p
