"""The one error a flux-map import raises: it names the file, the field and what was expected."""
from __future__ import annotations

from pathlib import Path


class MapImportError(ValueError):
    """A flux-map file that cannot be imported. `file` (the path), `key` (the field, variable or
    column concerned) and `expected` (what a good file has there) say why; `found` what was there."""

    def __init__(self, file: str | Path | None, key: str, expected: str, found: str | None = None):
        self.file = None if file is None else Path(file)
        self.key = key
        self.expected = expected
        self.found = found
        super().__init__()

    def __str__(self) -> str:
        found = f", found {self.found}" if self.found else ""
        return f"{self.file if self.file is not None else '<map>'}: {self.key}: expected {self.expected}{found}"
