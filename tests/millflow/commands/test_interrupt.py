"""Ctrl-C at any moment of ``millflow run`` (while the package imports, while it solves,
while it writes): never a traceback, and no half-written results folder."""
import os
import signal
import subprocess
import sys
import time

import pytest

from tests import paths

ROOT = paths.FLOWSHEETS.parent


@pytest.mark.skipif(os.name != "posix", reason="POSIX signals")
@pytest.mark.parametrize("delay", [0.05, 0.4, 1.5, 4.0])
def test_sigint_never_prints_a_traceback(tmp_path, delay):
    out = tmp_path / "out"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    proc = subprocess.Popen([sys.executable, "-m", "millflow", "run",
                             str(paths.FLOWSHEETS / "closed_circuit_aggregating_mill.toml"), "--out", str(out),
                             "--quiet"], stderr=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=tmp_path,
                            env=env)
    time.sleep(delay)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=300)
    if "init_import_site" in err:  # the signal came during Python's own start-up, before any millflow code
        return
    if "Traceback" in err and "millflow" not in err.split("Traceback", 1)[1].split("KeyboardInterrupt", 1)[0]:
        return  # raised in runpy's own frames, before the first line of millflow ran (no millflow frame)
    assert "Traceback" not in err, err
    # killed quietly while importing (-SIGINT), interrupted (130) or already done (0)
    assert proc.returncode in (0, 130, -signal.SIGINT), (proc.returncode, err)
    # nothing half written: no staging folder left behind, and a results folder only if the
    # command got as far as renaming its whole staged folder into place (the signal may land
    # after that rename, while the interpreter shuts down)
    assert not list(tmp_path.glob(".out.millflow-*")), list(tmp_path.iterdir())
    if proc.returncode != 0 and out.exists() and any(out.iterdir()):
        assert (out / "results.nc").is_file() and (out / "summary.json").is_file(), sorted(os.listdir(out))
