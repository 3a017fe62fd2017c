"""docs/equations.md names one implementation per equation: every name it gives must import,
and the library itself must use it.

The page is the map from "eq. N" in the code to the function; a moved function must move
the map with it, or this test fails. A named function that only the tests reach while the
running code evaluates the equation elsewhere (a second copy) fails too: its name must be
used (called, instantiated, referenced) somewhere in the package source outside tests.
"""
from __future__ import annotations

import ast
import functools
import importlib
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGE = ROOT / "docs" / "equations.md"
NAME = re.compile(r"`((?:millflow|rtd)(?:\.[A-Za-z_][A-Za-z0-9_]*)+)`")


def _resolve(dotted: str):
    parts = dotted.split(".")
    for cut in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:cut]))
        except ModuleNotFoundError:
            continue
        for attr in parts[cut:]:
            obj = getattr(obj, attr)
        return obj
    raise ModuleNotFoundError(dotted)


def _names() -> list[str]:
    return sorted(set(NAME.findall(PAGE.read_text(encoding="utf-8"))))


@pytest.mark.parametrize("dotted", _names())
def test_every_named_implementation_imports(dotted):
    assert callable(_resolve(dotted)) or isinstance(_resolve(dotted), type)


def test_every_equation_has_an_implementation_line():
    text = PAGE.read_text(encoding="utf-8")
    sections = re.split(r"^## ", text, flags=re.M)
    for n in range(1, 11):
        section = next((s for s in sections if re.match(rf"Eqs?\. (\d+ and )?{n}\b|Eqs\. \d+ and {n}\b", s)), None)
        assert section is not None, f"eq. {n} has no section"
        assert "**Implemented in**" in section, f"eq. {n} names no implementation"


@functools.cache
def _names_used_in_library() -> frozenset[str]:
    """Every identifier the package source loads (names and attributes, not definitions,
    imports, strings or docstrings)."""
    used = set()
    for pkg in ("millflow", "rtd"):
        for path in (ROOT / pkg).rglob("*.py"):
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.Name) and isinstance(node.ctx, ast.Load):
                    used.add(node.id)
                elif isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Load):
                    used.add(node.attr)
    return frozenset(used)


@pytest.mark.parametrize("dotted", _names())
def test_every_named_implementation_is_used_by_the_library(dotted):
    # the running code must reach the named function, not a copy of its equation
    assert dotted.rsplit(".", 1)[1] in _names_used_in_library(), (
        f"{dotted} is named in docs/equations.md but nothing in millflow/ or rtd/ uses it")
