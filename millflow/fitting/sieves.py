"""Reduce a solution on the fine numerical grid to the measured sieves (Principle IV).

The model is solved on a fine grid and compared with the data at the sizes that were
measured. The cumulative passing P at the grid's edges x_1 > ... > x_N is exact (sums of
class masses), so each measured size is read as follows:

- at or above the grid top x_1: P = 1 (all mass is finer than the top edge);
- on a grid edge (to 1e-9 in ln x): that edge's P, the exact class sum: the automatic
  grid of a fit (:func:`millflow.fitting.forward.auto_grid`) puts its top on the
  coarsest measured size and its ratio a whole fraction of a geometric sieve series
  (2^(1/4) against 2^(1/2) sieves), so that sieves fall on edges and this is the usual case;
- between two edges: Steffen's monotone cubic Hermite interpolant of P in ln x
  (M. Steffen, Astron. Astrophys. 239 (1990) 443-450): node slopes from the parabola
  through each node and its neighbours, limited so that the curve is monotone between
  the nodes (P never leaves the bracketing values); error O(h^3) in the class width h
  where P is smooth, below the O(h^2) of the class-averaged breakage;
- below the finest edge x_N (inside the sink, which has no resolution): linear in size
  from (0, 0) to (x_N, P_N).

The reading is fixed by the sizes and the grid: index and weight tables are built once,
and one evaluation for a whole population is a few gathers and array operations.
"""
from __future__ import annotations

import numpy as np

__all__ = ["SieveReduction", "ON_EDGE"]

#: Tolerance in ln x under which a measured size counts as a grid edge.
ON_EDGE = 1e-9


class SieveReduction:
    """Cumulative passing at measured sizes from cumulative passing at grid edges.

    The rows of :meth:`reduce`'s result are the measured sizes, group after group; it takes
    the passing at the grid edges of every group's solution for M members at once.

    Parameters
    ----------
    x : numpy.ndarray
        (N,) upper edges of the grid [m], coarse -> fine.
    sizes : list of numpy.ndarray
        The measured sizes [m] of each sample group.
    """

    def __init__(self, x, sizes):
        x = np.asarray(x, dtype=float)
        self.n = n = x.size
        lx = np.log(x)
        const, edge_rows, edge_idx, lin_rows, lin_idx, lin_w = [], [], [], [], [], []
        cub_rows, cub = [], []
        r = 0
        for g, s in enumerate(sizes):
            for sz in np.asarray(s, dtype=float):
                base = g * n
                if sz >= x[0] * (1 - ON_EDGE):
                    const.append((r, 1.0))
                elif sz <= 0:
                    const.append((r, 0.0))
                else:
                    ls = np.log(sz)
                    k = int(np.argmin(np.abs(lx - ls)))
                    if abs(lx[k] - ls) <= ON_EDGE:
                        edge_rows.append(r)
                        edge_idx.append(base + k)
                    elif sz < x[-1]:  # inside the sink: linear in size to (0, 0)
                        lin_rows.append(r)
                        lin_idx.append(base + n - 1)
                        lin_w.append(sz / x[-1])
                    else:
                        k = int(np.searchsorted(-x, -sz)) - 1  # x[k] > sz > x[k + 1]
                        cub_rows.append(r)
                        cub.append((base, k, (ls - lx[k + 1]) / (lx[k] - lx[k + 1])))
                r += 1
        self.rows = r
        self.const_rows = np.array([c[0] for c in const], dtype=int)
        self.const_vals = np.array([c[1] for c in const], dtype=float)
        self.edge_rows, self.edge_idx = np.array(edge_rows, dtype=int), np.array(edge_idx, dtype=int)
        self.lin_rows, self.lin_idx = np.array(lin_rows, dtype=int), np.array(lin_idx, dtype=int)
        self.lin_w = np.array(lin_w, dtype=float)
        self.cub_rows = np.array(cub_rows, dtype=int)
        self._cubic_tables(lx, cub)

    def _cubic_tables(self, lx, cub):
        """Gather indices, interval widths and Hermite basis values of the off-edge rows.

        Interval k of a row is (x_{k+1}, x_k); in ascending ln x its lower node is edge k+1,
        its upper node edge k; the neighbours below (k+2) and above (k-1) give the node
        slopes (absent at the grid's ends: Steffen's one-sided slopes there).
        """
        n = self.n
        if not cub:
            self._cub = None
            return
        base = np.array([c[0] for c in cub])
        k = np.array([c[1] for c in cub])
        t = np.array([c[2] for c in cub])
        lo, hi = k + 1, k
        below, above = np.minimum(k + 2, n - 1), np.maximum(k - 1, 0)
        h = lx[hi] - lx[lo]
        h_below = lx[lo] - lx[below]  # 0 where the lower node is the finest edge
        h_above = lx[above] - lx[hi]  # 0 where the upper node is the top edge
        self._cub = {"lo": base + lo, "hi": base + hi, "below": base + below, "above": base + above,
                     "h": h, "h_below": h_below, "h_above": h_above,
                     "has_below": k + 2 <= n - 1, "has_above": k >= 1,
                     "H00": 2 * t ** 3 - 3 * t ** 2 + 1, "H10": t ** 3 - 2 * t ** 2 + t,
                     "H01": -2 * t ** 3 + 3 * t ** 2, "H11": t ** 3 - t ** 2}

    def reduce(self, P) -> np.ndarray:
        """Passing at the measured sizes, (M, rows), from P (M, G, N) at the grid edges."""
        P = np.asarray(P, dtype=float)
        flat = P.reshape(P.shape[0], -1)
        out = np.empty((P.shape[0], self.rows))
        out[:, self.const_rows] = self.const_vals
        out[:, self.edge_rows] = flat[:, self.edge_idx]
        out[:, self.lin_rows] = flat[:, self.lin_idx] * self.lin_w
        c = self._cub
        if c is not None:
            out[:, self.cub_rows] = _steffen(flat, c)
        return out


def _steffen(flat, c) -> np.ndarray:
    """Steffen's (1990) monotone cubic between the lower and upper node of each row."""
    y0, y1 = flat[:, c["lo"]], flat[:, c["hi"]]
    yb, ya = flat[:, c["below"]], flat[:, c["above"]]
    h, hb, ha = c["h"], c["h_below"], c["h_above"]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (y1 - y0) / h
        sb = np.where(c["has_below"], (y0 - yb) / np.where(hb > 0, hb, 1.0), 0.0)
        sa = np.where(c["has_above"], (ya - y1) / np.where(ha > 0, ha, 1.0), 0.0)
        d0 = np.where(c["has_below"], _interior(sb, s, hb, h), _end(s, sa, h, ha, c["has_above"]))
        d1 = np.where(c["has_above"], _interior(s, sa, h, ha), _end(s, sb, h, hb, c["has_below"]))
    return c["H00"] * y0 + c["H10"] * h * d0 + c["H01"] * y1 + c["H11"] * h * d1


def _interior(s_left, s_right, h_left, h_right):
    """Steffen's slope at an interior node from the secants of its two intervals."""
    p = (s_left * h_right + s_right * h_left) / (h_left + h_right)
    lim = np.minimum(np.minimum(np.abs(s_left), np.abs(s_right)), 0.5 * np.abs(p))
    return (np.sign(s_left) + np.sign(s_right)) * lim


def _end(s, s_next, h, h_next, has_next):
    """Steffen's one-sided slope at an end node.

    The parabola through the end interval and its neighbour, limited to [0, 2 s] with the
    sign of s (the secant alone if the grid has only that interval).
    """
    w = h / np.where(has_next, h + h_next, 1.0)
    p = np.where(has_next, s * (1 + w) - s_next * w, s)
    p = np.where(p * s <= 0, 0.0, p)
    return np.where(np.abs(p) > 2 * np.abs(s), 2 * s, p)
