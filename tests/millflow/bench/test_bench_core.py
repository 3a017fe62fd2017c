"""Core benchmark: the exact batch path against the cached mpmath references, and the
``millflow bench core`` command (docs/benchmarks.md, docs/CONTRACTS.md "Benchmarks").

Tolerances: 1e-12 absolute in every class is the issue-2 accuracy target of the exact
path (its rounding bound, eps times the cancellation of the basis, is ~1e-13 in the
degenerate case); -1e-15 on the minimum allows one rounding of a zero; 1e-13 on the
mass balance allows the sum of ~100 roundings of O(1) masses.
"""
import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from millflow.batch import batch_solve
from millflow.bench.core import CASE_NAMES, REFERENCE_DIR, CoreCase, core_cases, load_reference, rate_degeneracy
from millflow.cli import main
from tests import paths

ROOT = paths.REPO


@pytest.mark.parametrize("name", CASE_NAMES)
def test_exact_path_matches_reference_at_100_classes(name):
    case = core_cases(100)[name]
    ref, entry = load_reference(name, 100, case)
    assert ref is not None, entry
    res = batch_solve(case.S, case.b, case.feed, case.t_s, "exact")
    err = np.abs(res.M - ref)
    i, j = np.unravel_index(np.argmax(err), err.shape)
    assert err.max() <= 1e-12, f"{name}: max error {err.max():.3e} at t = {case.t_s[i]:g} s, class {j + 1}"
    assert res.M.min() >= -1e-15
    assert np.abs(res.M.sum(axis=1) - case.feed.sum()).max() <= 1e-13


def test_reference_is_matched_by_value_not_by_digest():
    # another CPU or libm computes the inputs a few ulps apart: still the same case
    case = core_cases(100)["degenerate"]
    nudged = CoreCase(case.name, case.S * (1 + 4e-16), case.b * (1 - 4e-16), case.feed, case.t_s * (1 + 2e-16),
                      case.description)
    assert load_reference("degenerate", 100, nudged)[0] is not None
    # a real change of the case (the 1e-9 scale the degenerate rates use) is refused, by name
    moved = CoreCase(case.name, case.S * (1 + 1e-9), case.b, case.feed, case.t_s, case.description)
    ref, why = load_reference("degenerate", 100, moved)
    assert ref is None and "S[" in why and "regenerate" in why


@pytest.mark.parametrize("name", CASE_NAMES)
def test_references_were_verified(name):
    # two precisions agree far below double rounding; N = 25 also against mpmath.expm
    doc = json.loads((REFERENCE_DIR / f"core_{name}.json").read_text())
    for n, entry in doc["entries"].items():
        assert entry["dps"] >= 50 and entry["check_dps"] > entry["dps"]
        assert entry["max_diff_between_precisions"] < 1e-40, (name, n)
    assert doc["entries"]["25"]["max_diff_vs_mpmath_expm"] < 1e-40


def test_cases_are_what_they_claim():
    cases = core_cases(100)
    deg = rate_degeneracy(cases["degenerate"].S)
    assert deg["equal_pairs"] >= 6 and deg["near_pairs_below_1e-6"] >= 3  # Reid divides by ~0
    S = cases["stiff"].S
    assert S[0] == 1e6 and S[-2] == pytest.approx(1e-6) and S[-1] == 0.0
    for case in cases.values():
        assert case.t_s.size == 10 and case.feed.sum() == pytest.approx(1.0)


def test_reference_algorithm_is_exact_for_equal_rates():
    mpmath = pytest.importorskip("mpmath")
    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        from reference_core import expo_poly_solution
    finally:
        sys.path.pop(0)
    s, t = 0.7, 3.0
    b = np.array([[0, 0, 0], [0.6, 0, 0], [0.4, 1.0, 0]])
    M = expo_poly_solution([s, s, 0.0], b, [1.0, 0.0, 0.0], [t], dps=40)[0]
    # class 2 of two equal rates: 0.6 s t exp(-s t) (Reid's formula is 0/0 here)
    with mpmath.workdps(40):
        assert abs(M[1] - 0.6 * mpmath.mpf(s) * t * mpmath.exp(-mpmath.mpf(s) * t)) < 1e-35
        assert abs(M[0] - mpmath.exp(-mpmath.mpf(s) * t)) < 1e-35
        assert abs(sum(M) - 1) < 1e-35


def _installed_copy(tmp_path):
    """The packages millflow and rtd copied alone into a folder (as an install puts them,
    with their package data), and an empty working folder: the repository is neither on
    the path nor the working folder."""
    import shutil

    import millflow
    import rtd

    site = tmp_path / "site"
    for pkg in (millflow, rtd):
        src = Path(pkg.__file__).parent
        shutil.copytree(src, site / src.name, ignore=shutil.ignore_patterns("__pycache__", "build", "*.egg-info"))
    work = tmp_path / "work"
    work.mkdir()
    return site, work


def test_bench_command_quick_json_rows(tmp_path):
    # run from a copy of the package, outside the repository: the suite reads its
    # references from package data, never from the checkout
    site, work = _installed_copy(tmp_path)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONPATH=str(site))
    env.pop("MILLFLOW_BENCH_DATA", None)
    out = subprocess.run([sys.executable, "-m", "millflow", "bench", "core", "--quick", "--json"],
                         capture_output=True, text=True, env=env, timeout=300, cwd=work)
    assert out.returncode == 0, out.stderr
    rows = json.loads(out.stdout)
    assert rows and all({"case", "method", "runtime_s"} <= r.keys() for r in rows)
    wp = [r for r in rows if r["table"] == "work_precision"]
    assert {r["n_classes"] for r in wp} == {25, 100}
    for r in wp:
        assert {"max_abs_error", "mass_balance_error", "ratio_vs_baseline", "min_value", "median_ms"} <= r.keys()
        assert r["max_abs_error"] is not None and r["blas_threads"] == "1"
    assert {r["case"] for r in rows if r["table"] == "targets"} == set(CASE_NAMES)
    # grid independence: first order in the log of the grid ratio (upper-edge sizes)
    orders = [r["observed_order"] for r in rows if r["table"] == "grid_independence" and r["observed_order"]]
    assert orders and all(0.8 < p < 1.2 for p in orders)


def test_unknown_suite_lists_the_valid_ones(capsys):
    assert main(["bench", "no-such-suite"]) == 2
    assert "core" in capsys.readouterr().err


def test_no_library_module_reads_beside_the_package():
    # an installed package has no repository around it: a module may find files inside
    # its own package (package data) but never climb out of it through __file__
    import ast
    import re

    import millflow

    pkg = Path(millflow.__file__).parent
    bad = []
    for path in pkg.rglob("*.py"):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in ast.walk(tree):
            if isinstance(node, ast.Name) and node.id == "__file__":
                line = path.read_text(encoding="utf-8").splitlines()[node.lineno - 1]
                climbs = len(re.findall(r"\.parent\b", line)) >= 2 or "parents[" in line or line.count("dirname") >= 2
                if climbs:
                    bad.append(f"{path.relative_to(pkg)}:{node.lineno}: {line.strip()}")
    assert not bad, bad
