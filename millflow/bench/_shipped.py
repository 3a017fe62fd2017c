"""The example flowsheets shipped with the bench suites (package data, never the repository).

``millflow/bench/data/flowsheets/*.toml`` are copies of the repository's ``flowsheets/``
(kept equal by a test): an installed package has no repository around it, so the suites
read their circuits from here, whatever the working folder.
"""
from __future__ import annotations

import tomllib
from importlib import resources

__all__ = ["shipped_names", "shipped_text", "shipped_document"]


def _folder():
    return resources.files("millflow.bench").joinpath("data", "flowsheets")


def shipped_names() -> list[str]:
    """Names (file stems) of the shipped flowsheets, sorted."""
    return sorted(p.name[:-5] for p in _folder().iterdir() if p.name.endswith(".toml"))


def shipped_text(name: str) -> str:
    """The TOML text of shipped flowsheet ``name``; an unknown name is named with the valid ones."""
    try:
        return _folder().joinpath(f"{name}.toml").read_text("utf-8")
    except FileNotFoundError:
        from millflow.errors import InputError

        raise InputError(f"bench: circuit {name!r} is not shipped with millflow.bench; expected one of "
                         f"{', '.join(shipped_names())}") from None


def shipped_document(name: str) -> dict:
    """Shipped flowsheet ``name``, parsed (the dict :func:`millflow.flowsheet.from_dict` reads)."""
    return tomllib.loads(shipped_text(name))
