"""High-precision references for the core benchmark (millflow.bench.core).

Usage::

    python benchmarks/reference_core.py [--sizes 25 50 100 200] [--cases baseline ...]
                                        [--dps 60] [--check-dps 100] [--no-expm-check]

For each case of :func:`millflow.bench.core.core_cases` this solves eq. 4,
dM/dt = K M, M(0) = feed, for the float64 inputs taken as exact binary numbers, in
mpmath arithmetic, and writes M at the case's times to
millflow/bench/data/core_<case>.json (rounded to float64, 17 significant digits).

Method: exponential polynomials, exact also for equal rates (the confluent form of
Reid's solution). Class i is the sum over distinct rates r of p_{i,r}(t) exp(-r t),
p a polynomial. Going down the classes,

    M_i(t) = f_i exp(-S_i t) + int_0^t exp(-S_i (t - s)) g_i(s) ds,
    g_i = sum_{j<i} b_ij S_j M_j,

and each term c s^k exp(-l s) of g_i integrates in closed form:
l == S_i (exactly equal rates): c t^(k+1)/(k+1) exp(-S_i t);
otherwise, with d = l - S_i:  c k!/d^(k+1) exp(-S_i t)
                              - exp(-l t) sum_{m<=k} c k!/(m! d^(k+1-m)) t^m.
No step divides by an exactly zero difference; nearly equal rates (1e-9 apart) cost
digits to cancellation, which the working precision absorbs. Verification: every
result is computed twice, at ``--dps`` and at ``--check-dps`` digits, and the largest
difference is stored (it must be far below 1e-17); unless ``--no-expm-check``, the
N = 25 results are also compared with mpmath.expm(K t) feed (Taylor with scaling and
squaring, an unrelated algorithm) at three times.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import mpmath

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent))  # run from a source checkout without installing

from millflow.bench.core import CASE_NAMES, SIZES_FULL, core_cases, rate_degeneracy  # noqa: E402

DATA = HERE.parent / "millflow" / "bench" / "data"  # package data: the installed suite reads it


def expo_poly_solution(S, b, feed, t, dps: int) -> list[list]:
    """M_i(t_k) of eq. 4 as mpf, (T, N), by exponential polynomials at dps digits."""
    with mpmath.workdps(dps):
        n = len(S)
        S_mp = [mpmath.mpf(float(s)) for s in S]
        terms = []  # terms[i]: {rate (float key): [c_0, c_1, ...]}
        fact = [mpmath.factorial(k) for k in range(n + 2)]
        for i in range(n):
            g: dict[float, list] = {}
            for j in range(i):
                w = float(b[i, j])
                if w == 0.0 or S[j] == 0.0:
                    continue
                scale = mpmath.mpf(w) * S_mp[j]
                for rate, coeffs in terms[j].items():
                    acc = g.setdefault(rate, [])
                    if len(acc) < len(coeffs):
                        acc.extend([mpmath.mpf(0)] * (len(coeffs) - len(acc)))
                    for k, c in enumerate(coeffs):
                        acc[k] += scale * c
            own = float(S[i])
            Mi: dict[float, list] = {own: [mpmath.mpf(float(feed[i]))]}

            def add(rate, k, value):
                lst = Mi.setdefault(rate, [])
                if len(lst) <= k:
                    lst.extend([mpmath.mpf(0)] * (k + 1 - len(lst)))
                lst[k] += value

            for rate, coeffs in g.items():
                for k, c in enumerate(coeffs):
                    if c == 0:
                        continue
                    if rate == own:
                        add(own, k + 1, c / (k + 1))
                    else:
                        d = mpmath.mpf(rate) - S_mp[i]  # exact: both are doubles
                        add(own, 0, c * fact[k] / d ** (k + 1))
                        for m in range(k + 1):
                            add(rate, m, -c * fact[k] / (fact[m] * d ** (k + 1 - m)))
            terms.append(Mi)
        out = []
        for tk in t:
            tm = mpmath.mpf(float(tk))
            ex = {}
            row = []
            for Mi in terms:
                total = mpmath.mpf(0)
                for rate, coeffs in Mi.items():
                    if rate not in ex:
                        ex[rate] = mpmath.exp(-mpmath.mpf(rate) * tm)
                    total += ex[rate] * _horner(coeffs, tm)
                row.append(total)
            out.append(row)
        return out


def expm_solution(S, b, feed, t, dps: int) -> list[list]:
    """exp(K t) feed by mpmath.expm (independent check, small N only)."""
    with mpmath.workdps(dps):
        n = len(S)
        K = mpmath.matrix(n, n)
        for i in range(n):
            K[i, i] = -mpmath.mpf(float(S[i]))
            for j in range(i):
                K[i, j] = mpmath.mpf(float(b[i, j])) * mpmath.mpf(float(S[j]))
        f = mpmath.matrix([mpmath.mpf(float(v)) for v in feed])
        return [list(mpmath.expm(K * mpmath.mpf(float(tk))) * f) for tk in t]


def max_diff(A, B) -> float:
    return float(max(abs(x - y) for ra, rb in zip(A, B) for x, y in zip(ra, rb)))


def make_entry(case, dps: int, check_dps: int, expm_check: bool) -> dict:
    start = time.perf_counter()
    M = expo_poly_solution(case.S, case.b, case.feed, case.t_s, dps)
    M_check = expo_poly_solution(case.S, case.b, case.feed, case.t_s, check_dps)
    entry = {
        "inputs": case.inputs(),  # matched to a case by value (millflow.bench.core.INPUT_RTOL)
        "dps": dps,
        "check_dps": check_dps,
        "max_diff_between_precisions": max_diff(M, M_check),
        "rate_degeneracy": rate_degeneracy(case.S),
        "M": [[float(v) for v in row] for row in M_check],
    }
    if expm_check:
        pick = [0, len(case.t_s) // 2, len(case.t_s) - 1]
        E = expm_solution(case.S, case.b, case.feed, case.t_s[pick], dps)
        entry["max_diff_vs_mpmath_expm"] = max_diff([M_check[k] for k in pick], E)
        entry["expm_check_times_s"] = [float(case.t_s[k]) for k in pick]
    entry["seconds"] = round(time.perf_counter() - start, 2)
    return entry


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--sizes", type=int, nargs="+", default=list(SIZES_FULL))
    p.add_argument("--cases", nargs="+", default=list(CASE_NAMES), choices=CASE_NAMES)
    p.add_argument("--dps", type=int, default=60)
    p.add_argument("--check-dps", type=int, default=100)
    p.add_argument("--no-expm-check", dest="expm_check", action="store_false",
                   help="skip the comparison of N = 25 with mpmath.expm (about 10 s per case)")
    p.add_argument("--out", type=Path, default=DATA)
    args = p.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)
    for name in args.cases:
        path = args.out / f"core_{name}.json"
        doc = json.loads(path.read_text()) if path.exists() else {}
        doc.update({"case": name, "generator": "benchmarks/reference_core.py",
                    "method": "exponential polynomials (confluent Reid) in mpmath"})
        entries = doc.setdefault("entries", {})
        for n in args.sizes:
            case = core_cases(n)[name]
            entry = make_entry(case, args.dps, args.check_dps, args.expm_check and n == 25)
            entries[str(n)] = entry
            print(f"{name} N={n}: {entry['seconds']} s, precision diff {entry['max_diff_between_precisions']:.2e}"
                  + (f", vs expm {entry['max_diff_vs_mpmath_expm']:.2e}" if "max_diff_vs_mpmath_expm" in entry else ""),
                  flush=True)
            doc["entries"] = dict(sorted(entries.items(), key=lambda kv: int(kv[0])))
            path.write_text(json.dumps(doc, separators=(",", ":")) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())


def _horner(coeffs, x):
    """sum_k coeffs[k] x^k (coefficients in ascending powers), in the working precision.
    Written out: mpmath.polyval's coefficient order is being changed (a DeprecationWarning
    in mpmath 1.4)."""
    total = mpmath.mpf(0)
    for c in reversed(coeffs):
        total = total * x + c
    return total
