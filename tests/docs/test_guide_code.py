"""Every ```python block of the guide (docs/guide/*.md) runs.

Each page's blocks are executed in order in one namespace, in an empty temporary
working directory, so that a page reads as one script. Blocks that must not run are
fenced otherwise (```bash, ```toml, ```text). Running the pages is marked slow (about
two minutes in all); finding and compiling the blocks is not.
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

GUIDE = Path(__file__).resolve().parents[2] / "docs" / "guide"
PAGES = sorted(GUIDE.glob("*.md"))
# a fence at the start of a line: ```python (optionally with more words), the code, ```
FENCE = re.compile(r"^```python[^\n]*\n(.*?)^```[ \t]*$", re.M | re.S)


def python_blocks(text: str) -> list[tuple[int, str]]:
    """``(line number of the first code line, code)`` of each ```python block."""
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in FENCE.finditer(text)]


def run_page(path: Path, namespace: dict | None = None) -> dict:
    """Execute the page's python blocks in order in one namespace (in the current
    working directory); a block that raises fails with the page, line and error."""
    ns = {"__name__": "__guide__"} if namespace is None else namespace
    for line, code in python_blocks(path.read_text()):
        where = f"{path.name}, block at line {line}"
        try:
            exec(compile(code, f"{path}:{line}", "exec"), ns)
        except Exception as e:  # noqa: BLE001 - any failure of a block fails its page
            raise AssertionError(f"{where} raised {type(e).__name__}: {e}") from e
    return ns


def test_the_guide_has_pages_with_code():
    assert PAGES, f"no guide pages in {GUIDE}"
    empty = [p.name for p in PAGES if not python_blocks(p.read_text())]
    assert not empty, f"guide pages without a python block: {empty}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_blocks_compile(page):
    for line, code in python_blocks(page.read_text()):
        compile(code, f"{page}:{line}", "exec")


def test_a_raising_block_fails_its_page(tmp_path):
    page = tmp_path / "broken.md"
    page.write_text("text\n\n```python\nx = 1\n```\n\n```python\nraise ValueError('boom')\n```\n")
    ns = {}
    with pytest.raises(AssertionError, match=r"broken.md, block at line 8 raised ValueError: boom"):
        run_page(page, ns)
    assert ns["x"] == 1          # the blocks before it ran, in the same namespace


@pytest.mark.slow
@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.stem)
def test_guide_page_runs(page, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MPLBACKEND", "Agg")
    run_page(page)
