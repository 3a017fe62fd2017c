"""Start-up: ``import millflow`` loads no heavy library until a call needs it, and the
package roots still serve every public name (lazily, PEP 562)."""
import importlib
import json
import subprocess
import sys

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
