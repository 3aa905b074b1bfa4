"""The README is for people: at most 150 lines, measurements in docs/; every file it
links or names as a path exists (a renamed file breaks it here, not in a reader's browser)."""
from __future__ import annotations

import re

from conftest import ROOT

README = ROOT / "README.md"
MAX_LINES = 150


def test_the_readme_is_short():
    n = len(README.read_text().splitlines())
    assert n <= MAX_LINES, f"README.md has {n} lines; measurements and their history go to docs/"


def test_every_link_of_the_readme_resolves():
    text = README.read_text()
    links = re.findall(r"\]\(([^)#]+)\)", text)
    missing = [link for link in links if not link.startswith("http") and not (ROOT / link).exists()]
    assert links and not missing, missing


def test_the_docs_pages_the_readme_sends_readers_to_exist():
    for page in ("docs/accuracy.md", "docs/validation.md", "docs/performance.md"):
        assert page in README.read_text() and (ROOT / page).is_file(), page
