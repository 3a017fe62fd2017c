"""Lab fit -> plant prediction: rates at scale, circuit product, throughput at a target P80.

:class:`ScaleUp` binds a :class:`~millflow.scaleup.fitted.FittedBreakage` (the lab fit,
evaluated at the lab's process conditions, eq. 10), the lab mill it was measured in, the
plant circuit and its feed, and a scaling rule:

- ``"herbst_fuerstenau"``: S_plant = S_lab (P_plant / H_plant) / (P_lab / H_lab)
  (S^E = S_lab H_lab / P_lab carried unchanged, :func:`.scaling.herbst_fuerstenau_rates`);
- ``"austin"``: A and mu of eq. 7 multiplied by :func:`.scaling.austin_factors`.

B (normalised, eq. 6) is carried unchanged. Every method takes a full parameter vector,
so that :mod:`.uncertainty` can propagate the fit's covariance through it.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millflow.errors import GridError, InputError, SolverError
from millflow.grid import SizeGrid
from millflow.psd import percentile_size
from millflow.scaleup.fitted import FittedBreakage
from millflow.scaleup.plant import Circuit, MillDesign
from millflow.scaleup.scaling import austin_factors
from millflow.scaleup.study import PlantStudy, bracketed_roots, check_range

__all__ = ["ScaleUp", "SCALINGS", "p80_fast"]

SCALINGS = ("herbst_fuerstenau", "austin")


def p80_fast(x, frac, percent=80.0):
    """Deprecated alias of :func:`millflow.psd.percentile_size` (the one P80, which now
    solves on the bracketing interval only, as this function did)."""
    return percentile_size(x, frac, percent)


@dataclass(frozen=True)
class ScaleUp:
    """Everything a plant prediction needs; see the module docstring.

    feed : (N,) fresh-feed mass fractions on ``x`` (the fit's grid unless given).
    feed_tph : fresh feed rate [t/h] of the predicted operating point.
    throughput_range_tph : search interval of the throughput root (target P80).
    """

    fit: FittedBreakage
    lab: MillDesign
    lab_process: dict
    circuit: Circuit
    feed: np.ndarray
    feed_tph: float
    scaling: str = "herbst_fuerstenau"
    austin_overrides: dict = field(default_factory=dict)
    x: np.ndarray | None = None
    throughput_range_tph: tuple = (None, None)

    def __post_init__(self):
        if self.scaling not in SCALINGS:
            raise InputError(f"scaling = {self.scaling!r}: expected one of {list(SCALINGS)}")
        if isinstance(self.x, SizeGrid):
            object.__setattr__(self, "_grid", self.x)
            x = self.x.x
        else:
            x = self.fit.x if self.x is None else np.asarray(self.x, float)
        object.__setattr__(self, "x", x)
        f = np.asarray(self.feed, float)
        if f.shape != x.shape or np.any(f < 0) or abs(f.sum() - 1) > 1e-9:
            raise GridError(f"feed: {f.shape} fractions summing to {float(f.sum())!r}; expected {x.shape} "
                            "non-negative fractions summing to 1 on the prediction grid")
        object.__setattr__(self, "feed", f)
        if not (math.isfinite(self.feed_tph) and self.feed_tph > 0):
            raise InputError(f"plant.feed_tph = {float(self.feed_tph)!r}: expected a number > 0")
        object.__setattr__(self, "lab_process", self.fit.check_process(self.lab_process, "lab.process"))
        lo, hi = self.throughput_range_tph
        lo = self.feed_tph / 20 if lo is None else float(lo)
        hi = self.feed_tph * 20 if hi is None else float(hi)
        if not (0 < lo < hi):
            raise InputError(f"throughput_range_tph = [{lo!r}, {hi!r}]: expected 0 < low < high")
        object.__setattr__(self, "throughput_range_tph", (lo, hi))
        if self.scaling == "austin":
            self._austin()

    # ------------------------------------------------------------------ scaling
    def _austin(self):
        return austin_factors(self.lab.as_dict(), self.circuit.mill.as_dict(), **self.austin_overrides)

    def factors(self) -> dict:
        """Scale-up factors on A and mu (plant / lab) and the powers and hold-ups used."""
        pl, pp = self.lab.power(), self.circuit.mill.power()
        Hl, Hp = self.lab.holdup(), self.circuit.mill.holdup()
        out = {"lab_power_kW": pl["net_kW"], "plant_power_kW": pp["net_kW"], "lab_holdup_kg": Hl,
               "plant_holdup_kg": Hp, "plant_gross_kW": pp["gross_kW"], "power_model": pp["model"],
               "plant_kw_per_t_balls": pp["kw_per_t_balls"], "plant_ball_mass_t": pp["ball_mass_t"]}
        if self.scaling == "herbst_fuerstenau":
            out.update(A=(pp["net_kW"] / Hp) / (pl["net_kW"] / Hl), mu=1.0)
        else:
            a = self._austin()
            out.update(A=a["A"], mu=a["mu"], terms=a["terms"])
        return out

    def plant_rates(self, theta):
        """S [1/s] and b of the plant mill on the prediction grid (class averages) for full
        parameter vector(s) theta."""
        f = self._cached_factors()
        return self.fit.on_grid(theta, self.grid, self.lab_process, f["A"], f["mu"])

    def _cached_factors(self):
        c = self.__dict__.get("_factors")
        if c is None:
            c = self.factors()
            object.__setattr__(self, "_factors", c)
        return c

    # ------------------------------------------------------ the plant flowsheet
    @property
    def grid(self):
        """The prediction grid (:class:`~millflow.grid.SizeGrid` of ``x``)."""
        g = self.__dict__.get("_grid")
        if g is None:
            g = self.x if isinstance(self.x, SizeGrid) else SizeGrid(self.x)
            object.__setattr__(self, "_grid", g)
        return g

    @property
    def study(self) -> PlantStudy:
        """The plant circuit as a flowsheet study (:class:`~millflow.scaleup.study.PlantStudy`)."""
        st = self.__dict__.get("_study")
        if st is None:
            f = self._cached_factors()
            st = PlantStudy(self.grid, self.feed, self.circuit, f["plant_holdup_kg"], f["plant_power_kW"] * 1e3)
            object.__setattr__(self, "_study", st)
        return st

    def flowsheet(self, theta):
        """The plant flowsheet with the material of parameter vector theta (the last few kept:
        a root's steps reuse the flowsheet and its units, whose S and b on the grid are kept)."""
        theta = np.asarray(theta, float)
        key = theta.tobytes()
        cache = self.__dict__.setdefault("_flowsheets", {})
        fs = cache.get(key)
        if fs is None:
            f = self._cached_factors()
            rate = self.fit.rate_model(theta, self.lab_process, f["A"], f["mu"])
            fs = self.study.flowsheet(rate, self.fit.distribution_model(theta))
            if len(cache) > 4:
                cache.clear()
            cache[key] = fs
        return fs

    # -------------------------------------------------------------- predictions
    @property
    def power_kW(self) -> float:
        return self._cached_factors()["plant_power_kW"]

    def _p80(self, p):
        return self.study.p80(p)  # the circuit's own product, in a root loop

    def operate(self, theta, feed_tph=None) -> dict:
        """Circuit at the fresh feed rate (default ``feed_tph``): product fractions,
        p80_m, tau_s, circulating_load, specific_energy_kWh_t, mass_balance."""
        F = (self.feed_tph if feed_tph is None else float(feed_tph)) / 3.6
        fs = self.flowsheet(theta)
        guesses = self.__dict__.setdefault("_guess_u", {})
        r = self.study.at_throughput(fs, F, guess_u=guesses.get(("F", round(F, 12))))
        if np.array_equal(theta, self.fit.theta):
            guesses[("F", round(F, 12))] = math.log(r["mill_flow_kg_s"])
        r["p80_m"] = self._p80(r["product"])
        r["specific_energy_kWh_t"] = self.power_kW / (F * 3.6)
        r["feed_tph"] = F * 3.6
        return r

    def throughput_for_p80(self, theta, target_p80_m) -> dict:
        """Fresh feed rate [t/h] whose circuit product has P80 = target: Brent's method on
        ln F_m (mill flow), bracketed within ``throughput_range_tph``. Returns feed_tph,
        p80_m, residual_rel (|P80 - target| / target), specific_energy_kWh_t, and the
        circuit state. A target outside the reachable P80 range raises InputError."""
        from scipy.optimize import brentq

        t = float(target_p80_m)
        if not (math.isfinite(t) and t > 0):
            raise InputError(f"target_p80 = {t!r}: expected a size > 0")
        fs = self.flowsheet(theta)
        study = self.study

        def h(u):
            return math.log(self._p80(study.at_mill_flow(fs, math.exp(u))["product"]) / t)
        # near the point estimate's root (Monte Carlo draws, finite differences): a narrow
        # bracket around it, widened until the sign changes; otherwise the full range
        guesses = self.__dict__.setdefault("_guess_u", {})
        u0 = guesses.get(("t", t))
        bracket = self._narrow_bracket(h, u0) if u0 is not None else None
        if bracket is None:
            bracket = self._full_bracket(fs, h, t)
        u = brentq(h, *bracket, xtol=1e-13, rtol=4 * np.finfo(float).eps)
        if np.array_equal(theta, self.fit.theta):
            guesses[("t", t)] = u
        r = study.at_mill_flow(fs, math.exp(u))
        r["p80_m"] = self._p80(r["product"])
        r["residual_rel"] = abs(r["p80_m"] - t) / t
        if r["residual_rel"] > 1e-8:
            raise SolverError(f"throughput root: P80 residual {r['residual_rel']:.3g} (relative) above 1e-8")
        r["feed_tph"] = r["fresh_kg_s"] * 3.6
        check_range(r["feed_tph"], self.throughput_range_tph, t)
        r["specific_energy_kWh_t"] = self.power_kW / r["feed_tph"]
        r["bracket_tph"] = self.throughput_range_tph
        return r

    # ----------------------------------------------------------- populations
    def _member_loop(self, thetas, fun):
        """fun(theta) -> dict of numbers per member, NaN for a member whose solve fails."""
        from millflow.errors import MillflowError

        rows = []
        for th in thetas:
            try:
                rows.append(fun(th))
            except MillflowError:
                rows.append(None)
        keys = next((r.keys() for r in rows if r is not None), ())
        return {k: np.array([np.nan if r is None else r[k] for r in rows], float) for k in keys
                if k != "product"} | {"product": np.array([np.full(self.grid.n, np.nan) if r is None else r["product"]
                                                           for r in rows])}

    def operate_population(self, thetas, feed_tph=None) -> dict:
        """:meth:`operate` for parameter vectors thetas (M, P) at once: arrays product (M, N),
        p80_m, circulating_load, mill_flow_kg_s (NaN for a member whose solve fails). The
        flowsheet is solved for all members per root step where it can be
        (:meth:`PlantStudy.population_at_mill_flow`), else member by member."""
        thetas = np.atleast_2d(np.asarray(thetas, float))
        F = (self.feed_tph if feed_tph is None else float(feed_tph)) / 3.6
        point = self.operate(self.fit.theta, feed_tph)
        fs = self.flowsheet(self.fit.theta)
        S, b = self.plant_rates(thetas)
        study = self.study
        if not study.closed:
            r = study.population_at_mill_flow(fs, S, b, np.full(len(thetas), F))
            if r is None:
                return self._member_loop(thetas, lambda th: self.operate(th, feed_tph))
            r["mill_flow_kg_s"] = np.full(len(thetas), F)
        else:
            if study.population_at_mill_flow(fs, S[:1], b[:1], np.array([F])) is None:
                return self._member_loop(thetas, lambda th: self.operate(th, feed_tph))

            def g(u, idx):
                return np.log(study.population_at_mill_flow(fs, S[idx], b[idx], np.exp(u))["fresh_kg_s"] / F)

            u = bracketed_roots(g, np.full(len(thetas), math.log(point["mill_flow_kg_s"])), width=0.02)
            ok = np.isfinite(u)
            M = len(thetas)
            r = {"product": np.full((M, self.grid.n), np.nan), "circulating_load": np.full(M, np.nan),
                 "fresh_kg_s": np.full(M, np.nan)}
            if ok.any():
                rr = study.population_at_mill_flow(fs, S[ok], b[ok], np.exp(u[ok]))
                for k in r:
                    r[k][ok] = rr[k]
            r["mill_flow_kg_s"] = np.exp(u)
        r["p80_m"] = study.p80s(r["product"])
        return r

    def throughput_population(self, thetas, target_p80_m) -> dict:
        """:meth:`throughput_for_p80` for parameter vectors thetas (M, P) at once: arrays
        feed_tph, specific_energy_kWh_t, p80_m, product (NaN for a member whose root fails
        or leaves ``throughput_range_tph``)."""
        thetas = np.atleast_2d(np.asarray(thetas, float))
        t = float(target_p80_m)
        point = self.throughput_for_p80(self.fit.theta, t)
        fs = self.flowsheet(self.fit.theta)
        S, b = self.plant_rates(thetas)
        study = self.study
        M = len(thetas)
        if study.population_at_mill_flow(fs, S[:1], b[:1], np.array([point["mill_flow_kg_s"]])) is None:
            def one(th):
                r = self.throughput_for_p80(th, t)
                return {k: r[k] for k in ("feed_tph", "specific_energy_kWh_t", "p80_m", "product", "mill_flow_kg_s")}
            return self._member_loop(thetas, one)

        def h(u, idx):
            r = study.population_at_mill_flow(fs, S[idx], b[idx], np.exp(u))
            with np.errstate(invalid="ignore", divide="ignore"):
                return np.log(study.p80s(r["product"]) / t)

        u = bracketed_roots(h, np.full(M, math.log(point["mill_flow_kg_s"])))
        out = {"feed_tph": np.full(M, np.nan), "p80_m": np.full(M, np.nan),
               "product": np.full((M, self.grid.n), np.nan)}
        ok = np.isfinite(u)
        if ok.any():
            rr = study.population_at_mill_flow(fs, S[ok], b[ok], np.exp(u[ok]))
            out["feed_tph"][ok] = rr["fresh_kg_s"] * 3.6
            out["product"][ok] = rr["product"]
            out["p80_m"][ok] = study.p80s(rr["product"])
        lo, hi = self.throughput_range_tph
        outside = ~((out["feed_tph"] >= lo * (1 - 1e-9)) & (out["feed_tph"] <= hi * (1 + 1e-9)))
        for k in out:
            out[k][outside] = np.nan
        out["mill_flow_kg_s"] = np.where(outside, np.nan, np.exp(u))
        out["specific_energy_kWh_t"] = self.power_kW / out["feed_tph"]
        return out

    @staticmethod
    def _narrow_bracket(h, u0, width=0.05, limit=8):
        a, b = u0 - width, u0 + width
        ha, hb = h(a), h(b)
        for _ in range(limit):
            if ha <= 0 <= hb:
                return a, b
            if ha > 0:
                b, hb = a, ha
                width *= 2
                a = a - width
                ha = h(a)
            else:
                a, ha = b, hb
                width *= 2
                b = b + width
                hb = h(b)
        return None

    def _full_bracket(self, fs, h, t):
        lo_tph, hi_tph = self.throughput_range_tph
        study = self.study
        # bracket in ln(mill flow): the low end carries lo_tph of fresh feed; the high end
        # carries hi_tph, or (closed circuit) as much as the circuit can pass below that
        r_lo = study.at_throughput(fs, lo_tph / 3.6)
        u_lo = math.log(r_lo["mill_flow_kg_s"])
        u_hi = math.log(hi_tph / 3.6)
        if study.closed:
            for _ in range(30):
                if study.at_mill_flow(fs, math.exp(u_hi))["fresh_kg_s"] * 3.6 >= hi_tph:
                    break
                u_hi += math.log(2.0)
            else:
                hi_tph = study.at_mill_flow(fs, math.exp(u_hi))["fresh_kg_s"] * 3.6

        h_lo, h_hi = h(u_lo), h(u_hi)
        if h_lo > 0:
            raise InputError(f"target P80 {t * 1e6:.6g} um is not reachable: the finest product in the "
                             f"throughput range, at {lo_tph:.6g} t/h, has P80 {t * math.exp(h_lo) * 1e6:.6g} um")
        if h_hi < 0:
            raise InputError(f"target P80 {t * 1e6:.6g} um is not reachable: even at {hi_tph:.6g} t/h (top of "
                             f"throughput_range_tph) the product has P80 {t * math.exp(h_hi) * 1e6:.6g} um")
        return u_lo, u_hi
