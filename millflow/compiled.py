"""The optional compiled kernels: C sources beside this file, built by setup.py.

:func:`load` returns a kernel module, or None when it was not built, when it is a
build of another version, or when ``MILLFLOW_KERNEL=numpy`` asks for the numpy loops.
Callers then run the same arithmetic in numpy, and report which kernel ran.
"""
from __future__ import annotations

import importlib
import os

__all__ = ["KERNELS", "load", "status"]

#: The compiled pieces: name -> (module, the KERNEL_VERSION its callers are written for).
KERNELS = {"eigenbasis": ("_eigenbasis", 1), "cells": ("_cells", 1)}


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
    return ", ".join(f"{name}={'numpy' if load(*spec) is None else 'compiled'}" for name, spec in KERNELS.items())
