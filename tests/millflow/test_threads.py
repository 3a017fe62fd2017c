"""BLAS threads: millflow's small dense solves run on one BLAS thread whatever the
process's setting (millflow.threads), so the non-linear batch solve does not slow down
when BLAS is allowed more threads."""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

threadpoolctl = pytest.importorskip("threadpoolctl")

from millflow.threads import blas_threads, single_threaded_blas  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def _scene(n):
    from millflow.breakage import b_from_B, normalized_B, power_law_rates
    from millflow.grid import SizeGrid
    from millflow.nonlinear import Aggregation, constant_kernel, kinetics

    grid = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    S = power_law_rates(grid.x, 1.0, 1.0, grid.x[0])
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return kinetics(S, b, aggregation=Aggregation(constant_kernel(1.0), grid.x[-1]), grid=grid), feed


def test_context_limits_and_restores():
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        before = blas_threads()
        with single_threaded_blas():
            assert blas_threads() == 1
            with single_threaded_blas():  # nested: still one, and the outer exit restores
                assert blas_threads() == 1
            assert blas_threads() == 1
        assert blas_threads() == before


def test_batch_nonlinear_factorises_on_one_thread(monkeypatch):
    import millflow.nonlinear.batch as nb

    seen = []
    real = nb.integrate

    def spy(*args, **kwargs):
        seen.append(blas_threads())
        return real(*args, **kwargs)

    monkeypatch.setattr(nb, "integrate", spy)
    kin, feed = _scene(30)
    with threadpoolctl.threadpool_limits(2, user_api="blas"):
        nb.batch_nonlinear(kin, feed, [10.0], error_estimate=False)
    assert seen and set(seen) == {1}


_CHILD = """
import json, time, numpy as np, sys
sys.path.insert(0, {root!r})
from tests.millflow.test_threads import _scene
from millflow.nonlinear import batch_nonlinear
kin, feed = _scene(100)
# BDF: every step solves with an LU factorisation of the (N + 1)^2 iteration matrix
# (LSODA stays non-stiff on this scene and factorises nothing)
batch_nonlinear(kin, feed, [100.0], error_estimate=False, method="BDF")
ts = []
for _ in range(3):
    t0 = time.perf_counter()
    r = batch_nonlinear(kin, feed, [100.0], error_estimate=False, method="BDF")
    ts.append(time.perf_counter() - t0)
print(json.dumps({{"t": sorted(ts)[1], "nlu": r.info["nlu"]}}))
"""


def test_batch_time_does_not_grow_with_blas_threads():
    """Same work (LU count, > 0: the BDF path factorises) and about the same time with 1
    and 2 BLAS threads. Without the limit, 2 threads on a loaded 2-core machine cost
    10-20x; the margin (2.5x) only has to tell that apart from scheduling noise, it is not
    a timing target."""
    out = {}
    for threads in (1, 2):
        env = dict(os.environ, OPENBLAS_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads),
                   MKL_NUM_THREADS=str(threads))
        proc = subprocess.run([sys.executable, "-c", _CHILD.format(root=str(ROOT))], env=env, capture_output=True,
                              text=True, timeout=600, check=True)
        out[threads] = json.loads(proc.stdout.strip().splitlines()[-1])
    assert out[1]["nlu"] == out[2]["nlu"] > 0
    assert out[2]["t"] / out[1]["t"] < 2.5
