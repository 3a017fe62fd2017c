"""Start-up: ``import millflow`` loads no heavy library until a call needs it, and the
package roots still serve every public name (lazily, PEP 562)."""
import importlib
import json
import subprocess
import sys

import numpy as np
import pytest

from millflow._lazy import HEAVY, heavy_modules_loaded


def _loaded(statement: str) -> list[str]:
    return heavy_modules_loaded(statement)


def test_import_millflow_loads_no_heavy_module():
    assert _loaded("import millflow") == []


def test_version_and_steady_solve_need_no_integrator_or_plots():
    # the package's version and the steady mill: no scipy.integrate/stats, no matplotlib
    assert _loaded("import millflow; millflow.__version__") == []
    left = _loaded("from millflow import steady_mill, Mill, SizeGrid, InputError")
    assert not {"scipy.integrate", "scipy.stats", "matplotlib"} & set(left)
    assert "matplotlib" not in _loaded("import rtd; rtd.TanksInSeries(1.0, 3).pdf(1.0)")
    assert not {"scipy.stats", "scipy.integrate"} & set(_loaded("import rtd; rtd.TanksInSeries(1.0, 3).pdf(1.0)"))


def test_cli_version_imports_nothing_heavy():
    code = ("import sys, json\nfrom millflow.cli import main\ntry:\n    main(['--version'])\nexcept SystemExit:\n"
            f"    pass\nprint(json.dumps([m for m in {list(HEAVY) + ['numpy']!r} if m in sys.modules]))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.startswith("millflow ")
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []


@pytest.mark.parametrize("package", ["millflow", "millflow.mill", "millflow.scaleup", "rtd"])
def test_every_public_name_resolves(package):
    mod = importlib.import_module(package)
    for name in mod.__all__:
        assert getattr(mod, name) is not None, name
        assert name in dir(mod)
    with pytest.raises(AttributeError, match="no_such_name"):
        mod.no_such_name  # noqa: B018


def test_lazy_names_are_the_modules_objects():
    import millflow
    from millflow.mill.steady import steady_mill

    assert millflow.steady_mill is steady_mill
    from millflow import Flowsheet
    from millflow.flowsheet import Flowsheet as F2

    assert Flowsheet is F2


def test_command_table_matches_the_modules():
    # millflow.commands.COMMANDS lists every command module (name and help line as its
    # add_parser registers them): the command line imports only the module it runs
    import argparse
    import pkgutil

    import millflow.commands as commands

    found = {}
    for info in pkgutil.iter_modules(commands.__path__):
        module = importlib.import_module(f"millflow.commands.{info.name}")
        if hasattr(module, "add_parser"):
            sub = argparse.ArgumentParser().add_subparsers()
            module.add_parser(sub)
            for action in sub._choices_actions:
                found[action.dest] = (info.name, action.help)
    assert found == commands.COMMANDS
    assert commands.USES_DASK <= set(commands.COMMANDS)


def test_a_command_line_imports_only_its_command():
    code = ("import sys, json\nfrom millflow.cli import build_parser\nbuild_parser(['run', 'x.toml'])\n"
            "print(json.dumps(sorted(m for m in sys.modules if m.startswith('millflow.commands.'))))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert set(json.loads(out.stdout.strip().splitlines()[-1])) <= {"millflow.commands.run",
                                                                     "millflow.commands.output"}
    # the full parser (documentation, tests) still has every command with its options
    from millflow.cli import build_parser

    sub = next(a for a in build_parser()._actions if a.dest == "command")
    assert "--tear-method" in {o for a in sub.choices["run"]._actions for o in a.option_strings}
    assert "--vary" in {o for a in sub.choices["sweep"]._actions for o in a.option_strings}


def test_run_without_plots_loads_neither_dask_nor_matplotlib(tmp_path):
    # the whole `millflow run --no-plots` process: results.nc is written by xarray, which
    # would import dask.array to tell a numpy array from a dask one; the command line tells
    # it dask is absent (the run holds no dask array) and the file is the same
    from millflow._lazy import import_path_env
    from tests import paths

    sheet = paths.FLOWSHEETS / "open_circuit_ball_mill.toml"  # a small open circuit
    code = ("import sys, json, runpy\nsys.argv = ['millflow', 'run', sys.argv[1], '--no-plots', '--quiet', "
            "'--out', sys.argv[2]]\ntry:\n    runpy.run_module('millflow', run_name='__main__')\nexcept SystemExit:\n"
            "    pass\nprint(json.dumps([m for m in ('dask', 'dask.array', 'matplotlib', 'distributed') "
            "if sys.modules.get(m) is not None]))")
    out = subprocess.run([sys.executable, "-c", code, str(sheet), str(tmp_path / "out")], env=import_path_env(),
                         capture_output=True, text=True, check=True)
    assert json.loads(out.stdout.strip().splitlines()[-1]) == []
    import xarray as xr

    from millflow.flowsheet import load, solve
    from millflow.flowsheet.results import to_dataset

    with xr.open_dataset(tmp_path / "out" / "results.nc") as ds:
        ref = to_dataset(solve(load(sheet)))  # the file holds the Dataset (run times aside)
        assert ds["mass_flow"].attrs["units"] == "kg/s"
        np.testing.assert_allclose(ds["mass_flow"].values, ref["mass_flow"].values, rtol=1e-12, atol=0)
        assert list(ds["source"].values) == list(ref["source"].values)
        assert list(ds["stream"].values) == list(ref["stream"].values)


def test_dataset_in_process_keeps_dask_usable():
    # millflow.cli.main called from Python (not the command line) leaves dask importable
    from millflow.cli import main

    with pytest.raises(SystemExit):
        main(["--version"])
    assert sys.modules.get("dask", True) is not None
