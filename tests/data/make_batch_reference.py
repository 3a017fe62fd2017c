"""Make tests/data/batch_reference.json: high-precision batch-grinding references.

Independent of millflow's solver: exp(K t) f in mpmath at 50 digits by Taylor series
on the vector with time sub-steps (every term of the series is non-negative apart from
the diagonal shift, so no digits are lost), checked against a 70-digit run.
Run:  python tests/data/make_batch_reference.py   (about a minute)
"""
import json
from pathlib import Path

import mpmath as mp
import numpy as np

HERE = Path(__file__).parent


def cases(n=40):
    x = 2.0 ** (-np.arange(n) / 4.0)
    B = np.zeros((n, n))
    for j in range(n - 1):
        r = x[j:n - 1] / x[j]  # x_{i-1}/x_j for i = j+1..n-1
        B[j + 1:, j] = 0.4 * r ** 0.8 + 0.6 * r ** 3.0
    b = np.zeros((n, n))
    b[:-1] = B[:-1] - B[1:]
    b[-1] = B[-1]
    b = np.tril(b, -1)
    feed = np.zeros(n)
    feed[:4] = [0.1, 0.4, 0.3, 0.2]
    base = np.r_[0.5 * (x[:-1] / x[0]), 0.0]
    stiff = np.r_[np.logspace(6, -6, n - 1), 0.0]
    degenerate = base.copy()
    degenerate[:10] = 0.5                                 # a run of equal rates
    degenerate[10:20] = 0.3 * (1 + 1e-9 * np.arange(10))   # nearly equal
    degenerate[20:38:2] = degenerate[21:39:2]             # equal pairs
    return {
        "baseline": (base, b, feed, np.linspace(0.5, 20.0, 6)),
        "stiff": (stiff, b, feed, np.geomspace(1e-4, 1e2, 6)),
        "degenerate": (degenerate, b, feed, np.linspace(0.5, 20.0, 6)),
    }


def reference(S, b, feed, times, dps):
    mp.mp.dps = dps
    n = len(S)
    K = [[mp.mpf(0)] * n for _ in range(n)]
    for i in range(n):
        K[i][i] = -mp.mpf(S[i])
        for j in range(i):
            K[i][j] = mp.mpf(b[i, j]) * mp.mpf(S[j])
    mu = max(mp.mpf(s) for s in S)  # shift: K + mu I has a non-negative diagonal
    out, y, t_prev = [], [mp.mpf(v) for v in feed], mp.mpf(0)
    for t in times:
        dt = mp.mpf(t) - t_prev
        steps = int(mp.ceil(dt * mu / 4)) + 1
        h = dt / steps
        for _ in range(steps):
            term, total = y[:], y[:]
            for k in range(1, 400):
                term = [(mp.fsum(K[i][j] * term[j] for j in range(i + 1)) + mu * term[i]) * h / k for i in range(n)]
                total = [a + c for a, c in zip(total, term)]
                if max(abs(v) for v in term) < mp.mpf(10) ** (-dps):
                    break
            y = [v * mp.exp(-mu * h) for v in total]
        out.append([float(v) for v in y])
        t_prev = mp.mpf(t)
    return np.array(out)


def main():
    data = {}
    for name, (S, b, feed, times) in cases().items():
        if name == "stiff":
            # sub-stepping at rate 1e6 over 100 s is too long: exact Reid at high precision
            # is valid here because all rates are distinct by decades.
            ref = reid(S, b, feed, times, 50)
            check = reid(S, b, feed, times, 70)
        else:
            ref = reference(S, b, feed, times, 40)
            check = reference(S, b, feed, times, 50)
        assert np.abs(ref - check).max() < 1e-20, name
        data[name] = {"S": S.tolist(), "b": b.tolist(), "feed": feed.tolist(), "t": times.tolist(), "M": ref.tolist()}
        print(name, "done")
    (HERE / "batch_reference.json").write_text(json.dumps(data))


def reid(S, b, feed, times, dps):
    """Reid's closed form in high precision (distinct rates only)."""
    mp.mp.dps = dps
    n = len(S)
    s = [mp.mpf(v) for v in S]
    X = [[mp.mpf(int(i == j)) for j in range(n)] for i in range(n)]
    for i in range(1, n):
        for j in range(i):
            r = mp.fsum(mp.mpf(b[i, k]) * s[k] * X[k][j] for k in range(j, i))
            X[i][j] = r / (s[i] - s[j])
    w = []
    for i in range(n):
        w.append(mp.mpf(feed[i]) - mp.fsum(X[i][k] * w[k] for k in range(i)))
    def mass(i, t):
        return float(mp.fsum(X[i][j] * w[j] * mp.exp(-s[j] * mp.mpf(t)) for j in range(i + 1)))
    return np.array([[mass(i, t) for i in range(n)] for t in times])


if __name__ == "__main__":
    main()
