"""Issue 16: every ```python block of README.md and docs/*.md runs as written.

Blocks of one page run in order in one namespace, in a temporary working folder that
looks like the repository root (``flowsheets``, ``docs``, ``examples`` linked read-only
in spirit, ``../shared`` linked to the shared data), so relative paths in the docs work
and nothing the docs write lands in the checkout. Pages whose blocks need the SPRITE data
skip with a reason when it is absent.
"""
import contextlib
import io
import os
import re

import pytest

from tests import paths

PAGES = [paths.REPO / "README.md"] + sorted(paths.DOCS.glob("*.md"))
BLOCK = re.compile(r"^```python\n(.*?)^```", re.S | re.M)
SHARED = paths.REPO.parent / "shared"


def _pages():
    for page in PAGES:
        blocks = BLOCK.findall(page.read_text(encoding="utf-8"))
        if blocks:
            yield pytest.param(page, blocks, id=page.name)


@pytest.fixture
def workspace(tmp_path, monkeypatch):
    root = tmp_path / "repo"
    root.mkdir()
    for name in ("flowsheets", "docs", "examples"):
        (root / name).symlink_to(paths.REPO / name, target_is_directory=True)
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    monkeypatch.chdir(root)
    return root


@pytest.mark.parametrize("page, blocks", list(_pages()))
def test_python_blocks_run(page, blocks, workspace):
    text = "".join(blocks)
    if "shared/data" in text and not (SHARED / "data").is_dir():
        pytest.skip(f"{page.name} reads ../shared/data, which is absent here")
    before = {p for p in paths.REPO.rglob("*") if ".git" not in p.parts and "__pycache__" not in p.parts}
    namespace = {"__name__": f"docs_{page.stem}"}
    with contextlib.redirect_stdout(io.StringIO()):
        for k, block in enumerate(blocks):
            try:
                exec(compile(block, f"{page.name} python block {k + 1}", "exec"), namespace)
            except Exception as exc:  # name the block: the docs are what is under test
                raise AssertionError(f"{page.name}, python block {k + 1} fails: {type(exc).__name__}: {exc}") from exc
    after = {p for p in paths.REPO.rglob("*") if ".git" not in p.parts and "__pycache__" not in p.parts}
    assert sorted(map(str, after - before)) == [], "the docs wrote into the checkout"
    assert os.getcwd() == str(workspace)


def test_every_page_is_checked():
    """A page with python blocks is in the list above (none is skipped by accident)."""
    assert {p.values[0].name for p in _pages()} >= {"README.md", "mill.md", "flowsheets.md", "rtd.md"}
