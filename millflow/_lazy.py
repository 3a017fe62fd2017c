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


#: Modules that ``import millflow`` must not load until a call needs them.
HEAVY = ("scipy.integrate", "scipy.stats", "pandas", "xarray", "matplotlib")


def import_path_env(**extra) -> dict:
    """Environment for a child Python that imports the same millflow as this process.

    The folder the ``millflow`` package is imported from goes first on PYTHONPATH (an
    installed package: site-packages; a source checkout: its root), plus ``extra`` variables.
    """
    import importlib.util
    import os
    from pathlib import Path

    env = dict(os.environ, **extra)
    package = importlib.util.find_spec(__name__.partition(".")[0]).submodule_search_locations[0]
    root = str(Path(package).resolve().parent)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    return env


def heavy_modules_loaded(statement: str = "import millflow") -> list[str]:
    """The modules of :data:`HEAVY` in ``sys.modules`` of a fresh process after ``statement``."""
    import json
    import subprocess
    import sys

    code = f"import sys, json\n{statement}\nprint(json.dumps([m for m in {list(HEAVY)!r} if m in sys.modules]))"
    out = subprocess.run([sys.executable, "-c", code], env=import_path_env(), capture_output=True, text=True,
                         check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])
