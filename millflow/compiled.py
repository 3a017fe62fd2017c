"""The optional compiled kernels: C sources beside this file, built by setup.py.

:func:`load` returns a kernel module, or None when it was not built, when it is a
build of another version, or when ``MILLFLOW_KERNEL=numpy`` asks for the numpy loops.
Callers then run the same arithmetic in numpy, and report which kernel ran.
"""
from __future__ import annotations

import importlib
import os

__all__ = ["load", "status"]


def load(name: str, version: int):
    """The compiled module ``millflow.<name>`` if it is usable, else None."""
    if os.environ.get("MILLFLOW_KERNEL", "").lower() == "numpy":
        return None
    try:
        module = importlib.import_module(f"millflow.{name}")
    except ImportError:
        return None
    # a stale build of older source (an editable install does not rebuild by itself)
    return module if getattr(module, "KERNEL_VERSION", None) == version else None


def status() -> str:
    """Which kernel runs each compiled piece, e.g. "eigenbasis=compiled, cells=numpy"."""
    from millflow import linalg, mill_cells

    pieces = {"eigenbasis": linalg._compiled, "cells": mill_cells._compiled}
    return ", ".join(f"{name}={'numpy' if mod is None else 'compiled'}" for name, mod in pieces.items())
