"""A plant study: the plant circuit as a flowsheet with the fitted material and the mill by dimensions.

Scale-up keeps only its design rules (power, hold-up, the scaling of the rates); the plant
itself is a :class:`millflow.flowsheet.graph.Flowsheet` solved by :mod:`millflow.flowsheet`:

- fresh feed -> (mixer ->) mill -> (classifier -> coarse back to the mixer) -> product, the
  mill a :class:`~millflow.flowsheet.units.MillUnit` with the fitted rate at plant scale
  (:meth:`millflow.scaleup.fitted.FittedBreakage.rate_model`), the fitted distribution, its
  transport, its solids hold-up H (tau = H / F_m, F_m the mill's solids throughput) and its
  power; the classifier a :class:`~millflow.flowsheet.units.Classifier` with the plant
  file's curve. Continuous forms are class-averaged on the grid (second order).
- At a given mill throughput F_m the flowsheet is linear (:func:`millflow.flowsheet.solve.
  solve_at`): its solution for any fresh feed scales to the fresh feed F = F_m / m_hat that
  carries that mill flow (m_hat the mill feed per unit fresh feed). A root in
  u = ln F_m (Brent's method) then gives the circuit at a fresh feed rate, or the fresh feed
  whose product has a target P80; every step reuses the flowsheet and its units (their S and
  b on the grid are computed once).
- For many parameter sets at once (Monte Carlo draws, finite differences) the same flowsheet
  is solved for the whole population per step (:func:`millflow.flowsheet.population.
  solve_population`), with the roots vectorised over the members (:func:`bracketed_roots`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from millflow.errors import GridError, InputError, SolverError
from millflow.psd import percentile_size

__all__ = ["PlantStudy", "bracketed_roots", "MILL"]

#: Unit and stream names of the plant flowsheet.
MILL, FEED, MIX, CLASSIFIER, PRODUCT = "mill", "fresh_feed", "mill_feed_box", "classifier", "product"


@dataclass(frozen=True, eq=False)
class PlantStudy:
    """The plant circuit on a size grid: what every solve of the study shares.

    Attributes
    ----------
    grid : SizeGrid of the prediction.
    feed_psd : (N,) fresh-feed mass fractions on ``grid``.
    circuit : :class:`millflow.scaleup.plant.Circuit` (mill design, transport, classifier).
    holdup_kg : the mill's solids hold-up H [kg]; power_W : its net power [W].
    """

    grid: object
    feed_psd: np.ndarray
    circuit: object
    holdup_kg: float
    power_W: float

    @property
    def closed(self) -> bool:
        """True for a closed circuit (a classifier after the mill)."""
        return self.circuit.classifier is not None

    def flowsheet(self, rate, breakage, fresh_kg_s: float = 1.0):
        """The plant flowsheet with this mill material (rate and distribution models)."""
        from millflow.flowsheet.graph import Flowsheet, Stream
        from millflow.flowsheet.units import Classifier, Feed, MillUnit, Mixer, Product

        c = self.circuit
        mill = MillUnit(MILL, rate, breakage, c.transport, dict(c.transport_params), holdup=float(self.holdup_kg),
                        power=float(self.power_W), transport_note=getattr(c, "transport_note", None))
        units = {FEED: Feed(FEED, float(fresh_kg_s), np.asarray(self.feed_psd, float)), MILL: mill,
                 PRODUCT: Product(PRODUCT)}
        if self.closed:
            params = {k: v for k, v in c.classifier.items() if k != "curve"}
            units[MIX] = Mixer(MIX)
            units[CLASSIFIER] = Classifier(CLASSIFIER, "hydrocyclone", c.classifier["curve"], params)
            streams = {"fresh": Stream("fresh", FEED, "out", MIX), "mill_feed": Stream("mill_feed", MIX, "out", MILL),
                       "mill_discharge": Stream("mill_discharge", MILL, "out", CLASSIFIER),
                       "recycle": Stream("recycle", CLASSIFIER, "underflow", MIX),
                       "product": Stream("product", CLASSIFIER, "overflow", PRODUCT)}
        else:
            streams = {"fresh": Stream("fresh", FEED, "out", MILL), "product": Stream("product", MILL, "out", PRODUCT)}
        return Flowsheet(self.grid, units, streams, title="plant circuit (scale-up)")

    # ----------------------------------------------------------- one member
    def at_mill_flow(self, fs, F_m: float) -> dict:
        """The circuit at mill solids throughput F_m [kg/s].

        Product (mass fractions), fresh_kg_s, tau_s, circulating_load (recycle / fresh),
        mass_balance, relative_residual.
        """
        from millflow.flowsheet.solve import solve_at

        flows, info = solve_at(fs, {MILL: {"throughput": float(F_m)}})
        names = fs.stream_names
        feed_in = math.fsum(flows[names.index("mill_feed" if self.closed else "fresh")])
        fresh = math.fsum(flows[names.index("fresh")])
        if not (feed_in > 0 and np.all(np.isfinite(flows))):
            raise SolverError(f"plant circuit has no steady state at a mill flow of {F_m * 3.6:.4g} t/h")
        scale = F_m / feed_in
        prod = flows[names.index("product")]
        total = math.fsum(prod)
        out = {"product": prod / total, "fresh_kg_s": fresh * scale, "tau_s": self.holdup_kg / F_m,
               "circulating_load": (math.fsum(flows[names.index("recycle")]) / fresh) if self.closed else 0.0,
               "mass_balance": abs(1.0 - total / fresh), "relative_residual": info.get("relative_residual", 0.0),
               "mill_flow_kg_s": float(F_m)}
        return out

    def at_throughput(self, fs, F: float, guess_u: float | None = None) -> dict:
        """The circuit at fresh feed F [kg/s]: F_m / m_hat(F_m) = F by Brent's method on ln F_m."""
        if not self.closed:
            return self.at_mill_flow(fs, F)
        from scipy.optimize import brentq

        def g(u):
            return math.log(self.at_mill_flow(fs, math.exp(u))["fresh_kg_s"] / F)

        lo = math.log(F)  # F_m >= F: g(lo) <= 0
        hi = None
        if guess_u is not None:
            a, b = guess_u - 0.02, guess_u + 0.02
            if a > lo and g(a) < 0 < g(b):
                lo, hi = a, b
        if hi is None:
            hi = lo + math.log(4.0)
            k = 0
            while g(hi) < 0:
                lo, hi = hi, hi + math.log(4.0)
                k += 1
                if k > 20:
                    raise SolverError(f"circuit cannot pass a fresh feed of {F * 3.6:.6g} t/h: the recycle grows "
                                      "without bound (mill capacity exceeded)")
        u = brentq(g, lo, hi, xtol=1e-13, rtol=4 * np.finfo(float).eps)
        return self.at_mill_flow(fs, math.exp(u))

    def p80(self, product) -> float:
        """P80 [m] of a product (:func:`millflow.psd.percentile_size`, the one P80)."""
        return percentile_size(self.grid, product, 80.0, validate=False)

    # ------------------------------------------------------- a population
    def population_at_mill_flow(self, fs, S, b, F_m) -> dict:
        """The circuit for P parameter sets at once.

        The circuit for P members at once (S (P, N), b (P, N, N) of the mill on the grid,
        F_m (P,) mill flows [kg/s]): arrays product (P, N), fresh_kg_s, circulating_load; None
        when the flowsheet is not of the kind :func:`~millflow.flowsheet.population.
        solve_population` solves (then member by member).
        """
        from millflow.flowsheet.population import solve_population

        F_m = np.asarray(F_m, float)
        flows = solve_population(fs, {MILL: (S, b)}, {MILL: F_m})
        if flows is None:
            return None
        names = fs.stream_names
        with np.errstate(all="ignore"):
            feed_in = flows[:, names.index("mill_feed" if self.closed else "fresh")].sum(axis=1)
            fresh = flows[:, names.index("fresh")].sum(axis=1)
            scale = F_m / feed_in
            prod = flows[:, names.index("product")]
            prod = prod / prod.sum(axis=1, keepdims=True)
            load = flows[:, names.index("recycle")].sum(axis=1) / fresh if self.closed else np.zeros_like(F_m)
        bad = ~(np.isfinite(scale) & (feed_in > 0) & np.all(np.isfinite(prod), axis=1))
        return {"product": np.where(bad[:, None], np.nan, prod), "fresh_kg_s": np.where(bad, np.nan, fresh * scale),
                "circulating_load": np.where(bad, np.nan, load)}

    def p80s(self, products) -> np.ndarray:
        """P80 [m] per member (NaN where undefined: inside the sink, or a failed member)."""
        out = np.full(len(products), np.nan)
        for k, p in enumerate(products):
            if np.all(np.isfinite(p)):
                try:
                    out[k] = percentile_size(self.grid, p, 80.0, validate=False)
                except GridError:
                    pass
        return out


def bracketed_roots(h, u0, width: float = 0.05, expand: int = 12, xtol: float = 1e-12, ftol: float = 1e-14,
                    maxiter: int = 100):
    """Roots of increasing functions, one per member, vectorised over the members.

    ``h(u, idx)`` returns h at u (len(idx),) for the members ``idx`` (an index array): only
    members still searching are evaluated. From brackets [u0 - width, u0 + width] moved and
    widened (doubling) until h changes sign (at most ``expand`` times), regula falsi with
    a modification that keeps it superlinear (it never leaves its bracket) to |bracket| <= xtol (absolute
    in u), or until |h| <= ``ftol`` at an end (h here is the log of a ratio of two computed
    values: 1e-14 is rounding, beyond which the secants carry no information), with the
    Anderson-Bjorck weights (J. Anderson and A. Bjorck, BIT 13
    (1973) 253-264). Members whose h is not finite or whose bracket is not found get NaN.
    Returns u (P,).
    """
    u0 = np.asarray(u0, float)
    P = u0.size
    every = np.arange(P)
    a, b = u0 - width, u0 + width
    ha, hb = h(a, every), h(b, every)
    w = np.full(P, float(width))
    for _ in range(expand):
        low = ha > 0  # the root is below a: [a - 2w, a]
        high = ~low & (hb < 0)  # the root is above b: [b, b + 2w]
        if not (low | high).any():
            break
        w = np.where(low | high, 2 * w, w)
        b, hb = np.where(low, a, b), np.where(low, ha, hb)
        a, ha = np.where(high, b, a), np.where(high, hb, ha)
        a = np.where(low, a - w, a)
        b = np.where(high, b + w, b)
        if low.any():
            ha[low] = h(a[low], every[low])
        if high.any():
            hb[high] = h(b[high], every[high])
    ok = np.isfinite(ha) & np.isfinite(hb) & (ha <= 0) & (hb >= 0)
    side = np.zeros(P)
    for _ in range(maxiter):
        active = ok & (np.abs(b - a) > xtol) & (np.abs(ha) > ftol) & (np.abs(hb) > ftol)
        if not active.any():
            break
        idx = every[active]
        with np.errstate(all="ignore"):
            c = b[idx] - hb[idx] * (b[idx] - a[idx]) / (hb[idx] - ha[idx])
        inside = (c > a[idx]) & (c < b[idx])
        c = np.where(inside, c, 0.5 * (a[idx] + b[idx]))
        hc = h(c, idx)
        fin = np.isfinite(hc)
        ok[idx[~fin]] = False
        left, right, exact = fin & (hc < 0), fin & (hc > 0), fin & (hc == 0)
        # Anderson-Bjorck: scale the value at the end kept a second time in a row by
        # m = 1 - h_c / h_new-end (0.5 where that is not positive): order ~1.7
        keep_b, keep_a = left & (side[idx] == -1), right & (side[idx] == 1)
        with np.errstate(all="ignore"):
            mb = 1.0 - hc / ha[idx]  # left: the old a is replaced by c
            ma = 1.0 - hc / hb[idx]
        hb[idx[keep_b]] *= np.where(mb[keep_b] > 0, mb[keep_b], 0.5)
        ha[idx[keep_a]] *= np.where(ma[keep_a] > 0, ma[keep_a], 0.5)
        a[idx[left]], ha[idx[left]] = c[left], hc[left]
        b[idx[right]], hb[idx[right]] = c[right], hc[right]
        a[idx[exact]], b[idx[exact]], ha[idx[exact]], hb[idx[exact]] = c[exact], c[exact], 0.0, 0.0
        side[idx[left]], side[idx[right]] = -1, 1
    u = np.where(np.abs(ha) <= np.abs(hb), a, b)
    return np.where(ok, u, np.nan)


def check_range(feed_tph: float, rng: tuple, target_m: float) -> None:
    """Refuse a throughput root outside ``rng`` = (low, high) [t/h]."""
    lo, hi = rng
    if not (lo * (1 - 1e-9) <= feed_tph <= hi * (1 + 1e-9)):
        raise InputError(f"target P80 {target_m * 1e6:.6g} um is not reachable within throughput_range_tph "
                         f"[{lo:.6g}, {hi:.6g}] (root at {feed_tph:.6g} t/h)")


def with_feed(fs, fresh_kg_s: float):
    """The flowsheet with its fresh feed rate set to ``fresh_kg_s`` (units reused)."""
    from millflow.flowsheet.graph import Flowsheet

    units = dict(fs.units)
    units[FEED] = replace(units[FEED], solids=float(fresh_kg_s))
    return Flowsheet(fs.grid, units, fs.streams, title=fs.title)
