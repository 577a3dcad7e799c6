"""The docs stay a newcomer's size and describe the product as it is: the README at most 15 KB, docs/
Markdown at most 120 KB in all, and no docstring or comment under drivewm/ dated (history lives in git)."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: A calendar date (2026-12-01) in running text; file names such as inception-2015-12-05.pt are not dates of history.
DATE = re.compile(r"(?<![\w-])20\d\d-[01]\d-[0-3]\d(?![\w.-])")


def test_readme_and_docs_fit_their_budgets():
    assert (REPO / "README.md").stat().st_size <= 15_000
    assert sum(p.stat().st_size for p in (REPO / "docs").rglob("*.md")) <= 120_000


def test_no_module_under_drivewm_carries_a_date():
    dated = [
        f"{path.relative_to(REPO)}:{n}"
        for path in sorted((REPO / "drivewm").rglob("*.py"))
        for n, line in enumerate(path.read_text().splitlines(), 1)
        if DATE.search(line)
    ]
    assert not dated, dated
