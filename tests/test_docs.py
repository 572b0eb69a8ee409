"""The README and the guides in ``docs/``: every relative link reaches a file, the README stays short.

Guides move and get renamed; a link left pointing at the old place is caught here.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCUMENTS = [ROOT / "README.md"] + sorted((ROOT / "docs").glob("*.md"))
_LINK = re.compile(r"\]\(([^)\s]+)\)")
#: The README is the front door (issue 10 item 7: "at most ~200 lines"); the rest lives in docs/.
README_MAX_LINES = 200


@pytest.mark.parametrize("path", DOCUMENTS, ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(path):
    dead = []
    for target in _LINK.findall(path.read_text(encoding="utf-8")):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue   # a web address or an anchor in the same page
        if not (path.parent / target.split("#", 1)[0]).exists():
            dead.append(target)
    assert not dead, f"{path.relative_to(ROOT)}: links to missing files: {dead}"


def test_readme_is_a_front_door():
    lines = (ROOT / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(lines) <= README_MAX_LINES, f"README.md has {len(lines)} lines: move detail to docs/"
