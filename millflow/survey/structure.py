"""The reconciliation problem of a survey: variables, exact balances and measurement functions.

Variables (SI, kg/s): the solids flow of every stream in every sieve class of the
common sieve series (component flows m_sk), the water of every stream W_s and the
water added at units a_u (the last two only when water is measured). In these
variables every node balance is linear:

- a classifier, mixer, tank or splitter conserves each size class:
  sum_in m_sk - sum_out m_sk = 0 for every class k;
- a mill breaks particles, so it conserves total solids only: sum_k (in - out) = 0;
- water: sum_in W_s + a_u - sum_out W_s = 0.

The measurements are functions of the variables: solids flow M_s = sum_k m_sk and water
W_s are linear; a class fraction f_sj = sum_{k in j} m_sk / M_s (j a class of the
stream's own sieves; the common series is the union of every analysis's sieves, so
each analysis's class is a range of common classes)
and the solids content M_s / (M_s + W_s) are not. The pan of each analysis is one
minus the others, so it is not an independent measurement and is not counted.
Flows given with SD 0 are exact: they join the balances as A z = b.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError

__all__ = ["Structure", "build_structure"]

@dataclass
class Structure:
    """Indices, constraints (A z = b) and measurement rows of a survey's reconciliation."""

    streams: list
    sieves: np.ndarray          # common sieve series [m], descending
    live: np.ndarray            # indices of the classes that can hold mass (of n_sieves + 1)
    wet: bool
    additions: list             # units with a water addition variable
    A: np.ndarray
    b: np.ndarray
    constraint_names: list
    exact: list                 # (key, variable kind, index, value) of the exact measurements
    rows: list                  # one dict per measurement: kind, stream, key, class, label
    y: np.ndarray
    sd: np.ndarray
    L: np.ndarray               # linear measurement rows (n_meas x n_z; zero rows for nonlinear ones)
    frac_rows: np.ndarray       # measurement row index of each fraction row
    frac_stream: np.ndarray
    frac_mask: np.ndarray       # (n_frac, K) 1 where a live class belongs to the measured class
    content_rows: np.ndarray
    content_stream: np.ndarray

    def model_sd(self, h: np.ndarray) -> np.ndarray:
        """SDs of the error model evaluated at values ``h`` (given SDs kept as they are)."""
        out = self.sd.copy()
        for i, row in enumerate(self.rows):
            rule = row.get("rule")
            if rule is None:
                continue
            if rule[0] == "rel":
                out[i] = rule[1] * abs(h[i])
            else:
                q = min(max(h[i], 0.0), 1.0)
                out[i] = rule[1] * 2.0 * np.sqrt(q * (1.0 - q)) + rule[2]
        return np.where(out > 0, out, self.sd)

    @property
    def S(self) -> int:
        return len(self.streams)

    @property
    def K(self) -> int:
        return int(self.live.size)

    @property
    def n_z(self) -> int:
        return self.S * self.K + (self.S + len(self.additions) if self.wet else 0)

    def m_index(self, s: int) -> slice:
        return slice(s * self.K, (s + 1) * self.K)

    def w_index(self, s: int) -> int:
        return self.S * self.K + s

    def a_index(self, k: int) -> int:
        return self.S * self.K + self.S + k

    def solids_gradient(self, s: int) -> np.ndarray:
        g = np.zeros(self.n_z)
        g[self.m_index(s)] = 1.0
        return g

    def measure(self, z, sparse: bool = False):
        """Measurement functions h(z) and their Jacobian dh/dz (a CSR matrix with ``sparse``:
        each row touches one stream's classes, so J N costs a tenth of the dense product)."""
        from scipy.sparse import coo_matrix

        if not hasattr(self, "_L_coo"):
            c = coo_matrix(self.L)
            self._L_coo = (c.row, c.col, c.data)
        h = self.L @ z
        rows, cols, vals = [self._L_coo[0]], [self._L_coo[1]], [self._L_coo[2]]
        S, K = self.S, self.K
        m = z[:S * K].reshape(S, K)
        M = m.sum(axis=1)
        if self.frac_rows.size:
            si = self.frac_stream
            Ms = M[si]
            with np.errstate(divide="ignore", invalid="ignore"):
                f = (self.frac_mask * m[si]).sum(axis=1) / Ms
                h[self.frac_rows] = f
                block = (self.frac_mask - f[:, None]) / Ms[:, None]
            rows.append(np.repeat(self.frac_rows, K))
            cols.append((si[:, None] * K + np.arange(K)[None, :]).ravel())
            vals.append(block.ravel())
        if self.content_rows.size:
            si = self.content_stream
            W = z[S * K + si]
            T = M[si] + W
            with np.errstate(divide="ignore", invalid="ignore"):
                h[self.content_rows] = M[si] / T
                dm, dw = W / T ** 2, -M[si] / T ** 2
            rows += [np.repeat(self.content_rows, K), self.content_rows]
            cols += [(si[:, None] * K + np.arange(K)[None, :]).ravel(), S * K + si]
            vals += [np.repeat(dm, K), dw]
        J = coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                       shape=(len(self.rows), self.n_z)).tocsr()
        return h, (J if sparse else J.toarray())


#: Two sieves closer than this ratio are not two sieves of one series but one sieve written two
#: ways (4100 and 4000 um, 74 and 75 um): the finest series in use, ISO 565's R40/3 and the
#: fourth root of 2, step by 1.19, and R40 itself by 1.06.
NEAR_DUPLICATE_RATIO = 1.05


def _common_sieves(survey) -> tuple[np.ndarray, dict]:
    """The common sieve series (the union of every analysis's sieves, descending) and each
    stream's sieve indices in it.

    Analyses may use different ranges of one series (a stream without the top sieve, another
    with one more fine sieve): each analysis's classes are ranges of the common classes. Two
    sieves within :data:`NEAR_DUPLICATE_RATIO` of each other but not equal (to 1e-6) are
    refused: they do not nest. The error names the stream(s) that bring the sieve fewer
    analyses use.
    """
    psds = {n: m.psd for n, m in survey.streams.items() if m.psd is not None}
    if not psds:
        return np.zeros(0), {}
    union = []
    for p in psds.values():
        for x in p.sizes:
            if not any(abs(x - u) <= 1e-6 * x for u in union):
                union.append(float(x))
    common = np.array(sorted(union, reverse=True))
    users = {k: [n for n, p in psds.items() if np.any(np.abs(p.sizes - x) <= 1e-6 * x)] for k, x in enumerate(common)}
    for k in range(common.size - 1):
        if common[k] / common[k + 1] < NEAR_DUPLICATE_RATIO:
            a, b = (k, k + 1) if len(users[k]) <= len(users[k + 1]) else (k + 1, k)
            odd, usual = common[a], common[b]
            who = ", ".join(f"streams.{n}.psd" for n in users[a])
            raise InputError(f"{survey.source}: {who}: sieves do not nest: {odd * 1e6:.6g} um is within "
                             f"{100 * (NEAR_DUPLICATE_RATIO - 1):.0f} % of the {usual * 1e6:.6g} um sieve of "
                             f"{', '.join(f'streams.{n}.psd' for n in users[b])}; one sieve written two ways, or "
                             "two series: give every analysis sieves of one series")
    where = {n: np.array([int(np.argmin(np.abs(common - x))) for x in p.sizes]) for n, p in psds.items()}
    return common, where


def build_structure(survey) -> Structure:
    """The reconciliation problem of ``survey`` (see the module docstring)."""
    fs = survey.flowsheet
    streams = fs.stream_names
    sidx = {n: k for k, n in enumerate(streams)}
    sieves, where = _common_sieves(survey)
    if sieves.size == 0:
        raise InputError(f"{survey.source}: no stream has a sieve analysis (psd); the size-by-size balance needs "
                         "at least one")
    n_cls = sieves.size + 1
    # the class above the coarsest sieve is dead when every analysis on that sieve passes 100 %
    on_top = [m.psd for n, m in survey.streams.items() if m.psd is not None and where[n][0] == 0]
    top_empty = all(p.passing[0] >= 1.0 - 1e-12 for p in on_top)
    live = np.arange(1 if top_empty else 0, n_cls)
    pos = {int(c): k for k, c in enumerate(live)}
    K = live.size
    wet = survey.wet
    additions = list(survey.water_additions) if wet else []
    S = len(streams)
    n_z = S * K + (S + len(additions) if wet else 0)

    rows, A_rows, names, b = [], [], [], []
    for u, unit in fs.units.items():
        if unit.type in ("feed", "product"):
            continue
        ins = [sidx[s] for s in fs.inlets(u)]
        outs = [sidx[s] for s in fs.outlets(u)]
        per_class = unit.type != "mill"
        for k in (range(K) if per_class else [None]):
            a = np.zeros(n_z)
            for s, sign in [(s, 1.0) for s in ins] + [(s, -1.0) for s in outs]:
                if k is None:
                    a[s * K:(s + 1) * K] += sign
                else:
                    a[s * K + k] += sign
            A_rows.append(a)
            b.append(0.0)
            names.append(f"units.{u} solids" + ("" if k is None else f" class {k + 1}"))
        if wet:
            a = np.zeros(n_z)
            for s in ins:
                a[S * K + s] += 1.0
            for s in outs:
                a[S * K + s] -= 1.0
            if u in additions:
                a[S * K + S + additions.index(u)] = 1.0
            A_rows.append(a)
            b.append(0.0)
            names.append(f"units.{u} water")

    exact, L, y, sd = [], [], [], []
    frac_rows, frac_stream, frac_mask, content_rows, content_stream = [], [], [], [], []

    def add(row, lin, value, sdev):
        rows.append(row)
        L.append(np.zeros(n_z) if lin is None else lin)
        y.append(value)
        sd.append(sdev)
        return len(rows) - 1

    for n, m in survey.streams.items():
        s = sidx[n]
        if m.solids is not None:
            g = np.zeros(n_z)
            g[s * K:(s + 1) * K] = 1.0
            if m.solids_sd == 0:
                A_rows.append(g), b.append(m.solids), names.append(f"streams.{n}.solids_tph (exact)")
                exact.append((f"streams.{n}.solids_tph", m.solids))
            else:
                add({"kind": "solids", "stream": n, "key": f"streams.{n}.solids_tph",
                     "rule": None if m.solids_rel is None else ("rel", m.solids_rel)}, g, m.solids, m.solids_sd)
        if wet and m.water is not None:
            g = np.zeros(n_z)
            g[S * K + s] = 1.0
            if m.water_sd == 0:
                A_rows.append(g), b.append(m.water), names.append(f"streams.{n}.water_tph (exact)")
                exact.append((f"streams.{n}.water_tph", m.water))
            else:
                add({"kind": "water", "stream": n, "key": f"streams.{n}.water_tph",
                     "rule": None if m.water_rel is None else ("rel", m.water_rel)}, g, m.water, m.water_sd)
        if wet and m.solids_content is not None:
            r = add({"kind": "solids_content", "stream": n, "key": f"streams.{n}.solids_content_pct"}, None,
                    m.solids_content, m.solids_content_sd)
            content_rows.append(r), content_stream.append(s)
        if m.psd is not None:
            u = where[n]
            frac = m.psd.fractions
            bounds = [(0, u[0])] + [(u[j - 1] + 1, u[j]) for j in range(1, u.size)]
            for j, (c0, c1) in enumerate(bounds):  # the stream's own classes but its pan
                mask = np.zeros(K)
                for c in range(c0, c1 + 1):
                    if c in pos:
                        mask[pos[c]] = 1.0
                if not mask.any():
                    continue  # above the coarsest sieve, where no stream holds anything
                upper = None if j == 0 else float(sieves[u[j - 1]])
                r = add({"kind": "fraction", "stream": n, "key": f"streams.{n}.psd", "class": j,
                         "upper_m": upper, "lower_m": float(sieves[u[j]]),
                         "rule": None if m.psd.sd_rule is None else ("psd",) + tuple(m.psd.sd_rule),
                         "label": (f"+{sieves[u[0]] * 1e6:.6g} um" if j == 0 else
                                   f"-{upper * 1e6:.6g} +{sieves[u[j]] * 1e6:.6g} um")},
                        None, float(frac[j]), float(m.psd.sd[j]))
                frac_rows.append(r), frac_stream.append(s), frac_mask.append(mask)
    for k, u in enumerate(additions):
        v, sdev = survey.water_additions[u]
        if v is None:
            continue
        g = np.zeros(n_z)
        g[S * K + S + k] = 1.0
        if sdev == 0:
            A_rows.append(g), b.append(v), names.append(f"water_additions.{u}.water_tph (exact)")
            exact.append((f"water_additions.{u}.water_tph", v))
        else:
            add({"kind": "addition", "stream": None, "unit": u, "key": f"water_additions.{u}.water_tph"}, g, v,
                sdev)
    sd_arr = np.array(sd, float)
    return Structure(streams, sieves, live, wet, additions, np.array(A_rows).reshape(-1, n_z), np.array(b, float),
                     names, exact, rows, np.array(y, float), sd_arr, np.array(L).reshape(-1, n_z),
                     np.array(frac_rows, int), np.array(frac_stream, int), np.array(frac_mask).reshape(-1, K),
                     np.array(content_rows, int), np.array(content_stream, int))
