"""The optional compiled kernels: C sources beside this file, built by setup.py.

:func:`load` returns a kernel module, or None when it was not built, when it is a
build of another version, or when ``MILLFLOW_KERNEL=numpy`` asks for the numpy loops.
Callers then run the same arithmetic in numpy, and report which kernel ran.
"""
from __future__ import annotations

import importlib
import os

__all__ = ["KERNELS", "CHOICES", "kernel", "load", "status"]

#: What a ``kernel=`` argument may say: None (the environment decides: MILLFLOW_KERNEL=numpy
#: forces numpy, otherwise compiled where it was built), "compiled" (required) or "numpy".
CHOICES = (None, "compiled", "numpy")

#: The compiled pieces: name -> (module, the KERNEL_VERSION its callers are written for).
KERNELS = {"eigenbasis": ("_eigenbasis", 1), "cells": ("_cells", 2)}


def load(name: str, version: int):
    """The compiled module ``millflow.<name>`` if it is usable, else None."""
    if os.environ.get("MILLFLOW_KERNEL", "").lower() == "numpy":
        return None
    return _load_built(name, version)


def kernel(piece: str, choice: str | None = None):
    """The compiled module for ``piece`` ("eigenbasis" or "cells"), or None to run numpy.

    ``choice`` None follows the environment (the default everywhere), "numpy" forces the
    numpy loops, "compiled" requires the built kernel and raises if it is missing.
    """
    from millflow.errors import InputError

    if choice not in CHOICES:
        raise InputError(f"kernel = {choice!r}; expected 'compiled', 'numpy' or None (the environment's choice)")
    if choice == "numpy" or (choice is None and os.environ.get("MILLFLOW_KERNEL", "").lower() == "numpy"):
        return None
    module = _load_built(*KERNELS[piece])
    if module is None and choice == "compiled":
        raise InputError(f"kernel = 'compiled': the {piece} kernel (millflow.{KERNELS[piece][0]}) was not built "
                         "or is of another version; reinstall with a C compiler, or use kernel='numpy'")
    return module


def _load_built(name: str, version: int):
    """The built module, or None if absent or a stale build of older source (an
    editable install does not rebuild by itself)."""
    try:
        module = importlib.import_module(f"millflow.{name}")
    except ImportError:
        return None
    return module if getattr(module, "KERNEL_VERSION", None) == version else None


def status() -> str:
    """Which kernel runs each compiled piece, e.g. "eigenbasis=compiled, cells=numpy"."""
    return ", ".join(f"{name}={'numpy' if kernel(name) is None else 'compiled'}" for name in KERNELS)
