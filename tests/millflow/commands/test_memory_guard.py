"""The run's memory guard against the memory it actually takes: a child process whose address
space is limited to what it holds plus the budget (resource.setrlimit(RLIMIT_AS)) is either
refused before it allocates (exit 2 naming the budget) or runs within the limit.

The guard used to count len(units) + 3 N x N matrices: measured peaks were 1.6-2.2 x that
(5001 classes: estimate 1.49 GiB, peak 2.88 GiB), so a run it let through could die of
MemoryError. The count is now calibrated on the measured peaks (run_matrices)."""
import os
import subprocess
import sys

import pytest

from tests import paths

resource = pytest.importorskip("resource")
if not os.path.exists("/proc/self/status"):  # the child reads its address space there
    pytest.skip("needs /proc (Linux)", allow_module_level=True)

BUDGET_GIB = 0.5

CHILD = r'''
import resource, sys
from millflow.cli import main

small, big, out = sys.argv[1], sys.argv[2], sys.argv[3]
args = sys.argv[4:]
# a small run first: every module `millflow run` imports is loaded before the limit is set
assert main(["run", small, "--out", out + "-warm", "--overwrite", "--no-plots", "--quiet"]) == 0
vm = next(int(l.split()[1]) * 1024 for l in open("/proc/self/status") if l.startswith("VmSize"))
budget = float(__import__("os").environ["MILLFLOW_MEMORY_BUDGET_GB"]) * 2**30
resource.setrlimit(resource.RLIMIT_AS, (int(vm + budget), resource.getrlimit(resource.RLIMIT_AS)[1]))
sys.exit(main(["run", big, "--out", out, "--overwrite", "--no-plots", "--quiet"] + args))
'''


def _flowsheet(tmp_path, n):
    base = (paths.FLOWSHEETS / "closed_circuit_ball_mill.toml").read_text()
    line = "ratio = 1.044273782427414"
    assert line in base
    path = tmp_path / f"n{n}.toml"
    path.write_text(base.replace(line, f"ratio = {(8000 / 10) ** (1 / (n - 1))!r}"))
    return path


def _run_limited(tmp_path, n, *args):
    env = {**os.environ, "MILLFLOW_MEMORY_BUDGET_GB": str(BUDGET_GIB), "OPENBLAS_NUM_THREADS": "1"}
    small = paths.FLOWSHEETS / "closed_circuit_ball_mill.toml"
    return subprocess.run([sys.executable, "-c", CHILD, str(small), str(_flowsheet(tmp_path, n)),
                           str(tmp_path / f"o{n}"), *args], capture_output=True, text=True, env=env,
                          timeout=600, cwd=str(paths.ROOT) if hasattr(paths, "ROOT") else None)


@pytest.mark.parametrize("n, args, expect", [
    (700, [], 0),                   # estimate 0.36 GiB with the grid check (1399 classes): runs within it
    (1200, [], 2),                  # 1.07 GiB: refused before allocating (it takes ~0.63 GiB above the budget's 0.5)
    (1500, ["--no-grid-check"], 0),  # 0.34 GiB without the grid check: runs within it
])
def test_refused_before_allocating_or_runs_within_the_limit(tmp_path, n, args, expect):
    r = _run_limited(tmp_path, n, *args)
    assert "MemoryError" not in r.stderr and "internal error" not in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.returncode == expect, r.stderr
    if expect == 2:
        assert "above the memory budget" in r.stderr and r.stderr.count("\n") == 1
        assert not (tmp_path / f"o{n}").exists()
    else:
        assert (tmp_path / f"o{n}" / "summary.json").exists()
