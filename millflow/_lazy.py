"""Public names of a package served from their modules on first use (PEP 562).

A package ``__init__`` that imports every submodule makes ``import millflow`` (and every
command's start-up) pay for scipy.integrate, scipy.stats, pandas, xarray and matplotlib
whether or not the call needs them. With :func:`attach` the package keeps its public
names (``from millflow import steady_mill`` works as before, ``dir()`` lists them) and
imports a module only when one of its names is first looked up.
"""
from __future__ import annotations

import importlib


def attach(package: str, modules: dict[str, tuple[str, ...]]):
    """``(__getattr__, __dir__)`` for ``package`` serving ``modules``: {module: names}.

    The first look-up of a name imports its module and stores the value in the package's
    namespace, so later look-ups are plain attribute reads.
    """
    where = {name: module for module, names in modules.items() for name in names}

    def __getattr__(name):
        module = where.get(name)
        if module is None:
            raise AttributeError(f"module {package!r} has no attribute {name!r}")
        value = getattr(importlib.import_module(module), name)
        setattr(importlib.import_module(package), name, value)
        return value

    def __dir__():
        return sorted(set(vars(importlib.import_module(package))) | set(where))

    return __getattr__, __dir__
