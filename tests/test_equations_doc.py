"""docs/equations.md names one implementation per equation: every name it gives must import.

The page is the map from "eq. N" in the code to the function; a moved function must move
the map with it, or this test fails.
"""
from __future__ import annotations

import importlib
import re
from pathlib import Path

import pytest

PAGE = Path(__file__).resolve().parents[1] / "docs" / "equations.md"
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
