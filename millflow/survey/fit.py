"""Fitting a circuit to a reconciled survey: named flowsheet parameters against every stream at once.

The parameters are keys of the flowsheet document by their dotted path, in the units
their keys state (``materials.ore.rate.A_per_min``, ``units.cyclones.d50c_um``,
``units.cyclones.bypass``, ``units.ball_mill.tau_min``, a predicted cyclone's ``F1``):
any number the flowsheet reader accepts, so mill breakage forms (eqs. 5-8, 10),
transport, classifier curves and predicted-cyclone calibration are all fitted the same
way. The feeds are set to the reconciled feed streams (solids, sieve analysis, water)
and measured water additions to their reconciled values: the survey's inputs are
inputs, not data.

Data and weights: the reconciled measurements of every other stream, whose covariance
C = sd J cov(t) J^T sd is singular (the balances hold exactly). The residuals are
whitened by C^{+1/2} (eigen-decomposition, the zero eigenvalues dropped), so that the
SSR is sum (model - reconciled)^T C^+ (model - reconciled): to first order the same as
fitting the raw measurements with their own SDs, because a flowsheet's predictions
satisfy the balances. The fit is :func:`millflow.fitting.estimate.fit` (global search or
multi-start, eq. 9 SEs, non-uniqueness spread) on a forward model that solves the
flowsheet for each parameter vector. The parameter covariance adds the errors of the
reconciled feeds propagated through the model (:meth:`CircuitModel.input_covariance`):
with per-energy rates the feed rate sets the kWh/t, and eq. 9 alone understated the SE of
the fitted S^E 2.4-fold.
"""
from __future__ import annotations

import copy
import json
import math
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError, MillflowError
from millflow.fitting.models import Parameter

__all__ = ["CircuitModel", "fit_circuit", "read_fit_table", "to_toml", "leave_one_stream_out"]

TPH = 3.6


def _get(doc: dict, path: str):
    node = doc
    for part in path.split("."):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"fit.parameters.{path}: not a key of the flowsheet (at {part!r})")
        node = node[part]
    if isinstance(node, bool) or not isinstance(node, (int, float)):
        raise InputError(f"fit.parameters.{path}: the flowsheet holds {node!r} there; expected a number")
    return float(node)


def _set(doc: dict, path: str, value: float) -> None:
    parts = path.split(".")
    node = doc
    for part in parts[:-1]:
        node = node[part]
    node[parts[-1]] = float(value)


class _Spec:
    def __init__(self, names):
        self.names = names

    def label(self) -> str:
        return "circuit fit of " + ", ".join(self.names)


class _Data:
    source = "reconciled survey"


class CircuitModel:
    """A forward model for :func:`millflow.fitting.estimate.fit` from a survey.

    A forward model for :func:`millflow.fitting.estimate.fit`: flowsheet parameters -> whitened
    predictions of the reconciled measurements (rows ``rows`` of the balance).
    """

    def __init__(self, balance, names, rows=None):
        st = balance.structure
        fs = balance.survey.flowsheet
        self.balance, self.names = balance, list(names)
        self.doc = copy.deepcopy(fs.meta["document"])
        self.base_dir = fs.meta.get("base_dir")
        self._feeds_from_survey()
        feed_streams = {n for n, s in fs.streams.items() if fs.units[s.source].type == "feed"}
        inputs = [i for i, r in enumerate(st.rows) if r["kind"] == "addition" or r["stream"] in feed_streams]
        if rows is None:
            rows = [i for i in range(len(st.rows)) if i not in inputs]
        self.rows = np.asarray(rows, int)
        if self.rows.size == 0:
            raise InputError("fit: no measured stream other than the feeds; there is nothing to fit")
        Jw = balance.meta["J"]
        G = Jw @ balance.cov_t @ Jw.T
        Cfull = st.sd[:, None] * G * st.sd[None, :]
        # the model takes the reconciled feeds as inputs, so it shares their errors: weight by the
        # covariance of the other streams given the feeds, C_II - C_IF C_FF^+ C_FI
        C = Cfull[np.ix_(self.rows, self.rows)]
        if inputs:
            CIF = Cfull[np.ix_(self.rows, inputs)]
            C = C - CIF @ np.linalg.pinv(Cfull[np.ix_(inputs, inputs)], rcond=1e-10, hermitian=True) @ CIF.T
            C = 0.5 * (C + C.T)
        lam, Q = np.linalg.eigh(C)
        keep = lam > 1e-10 * lam.max()
        self.W = (Q[:, keep] / np.sqrt(lam[keep])).T
        self.y = self.W @ balance.adjusted[self.rows]
        self.weights = np.ones(self.y.size)
        self.spec = _Spec(self.names)
        self.data = _Data()
        self.start = {n: _get(self.doc, n) for n in self.names}

    # ---------------------------------------------------------------- fit's interface
    @property
    def param_names(self):
        """Names of the circuit parameters, in the order of theta."""
        return tuple(self.names)

    @property
    def n_data(self) -> int:
        """Number of reconciled measurements fitted."""
        return int(self.y.size)

    def sample_ids(self):
        """None: the whitened measurements are independent."""
        return None

    def describe(self) -> dict:
        """The parameters and the rows of the balance fitted, as JSON-able data."""
        return {"parameters": self.names, "rows": self.rows.tolist()}

    def predict(self, theta):
        """Whitened predictions (P, n_data) for parameter vector(s) theta (NaN where a solve fails)."""
        th = np.atleast_2d(theta)
        out = np.empty((th.shape[0], self.y.size))
        for k, row in enumerate(th):
            try:
                out[k] = self.W @ self.measurements(row)[self.rows]
            except (MillflowError, FloatingPointError, ValueError, np.linalg.LinAlgError):
                out[k] = np.nan
        return out

    # ------------------------------------------------------------------- the circuit
    def _feeds_from_survey(self) -> None:
        """Set the feeds and water additions to their reconciled values.

        Set the feeds (solids, sieve analysis at the sieves the survey determines, water) and the
        measured water additions to their reconciled values; record them as the model's inputs
        (``input_values`` [SI], ``input_grads`` d input / dz) for :meth:`input_covariance`.
        """
        bal = self.balance
        fs = bal.survey.flowsheet
        st = bal.structure
        self.input_values, self.input_grads, self.input_labels, self._layout = [], [], [], []

        def add(label, value, grad):
            self.input_labels.append(label)
            self.input_values.append(float(value))
            self.input_grads.append(grad)
            return len(self.input_values) - 1

        for n, s in fs.streams.items():
            if fs.units[s.source].type != "feed":
                continue
            M, _, ok = bal.solids(n)
            p, _, pok = bal.passing(n)
            if not (ok and pok.any()):
                raise InputError(f"fit: the feed stream {n} is not determined by the survey (unobservable)")
            k = st.streams.index(n)
            m = bal.z[st.m_index(k)]
            entry = {"unit": s.source, "solids": add(f"streams.{n}.solids_tph", M, st.solids_gradient(k)),
                     "sizes": bal.structure.sieves[pok], "passing": [], "water": None}
            # only the sieves the survey determines for this feed (analyses on different ranges of
            # one series leave some open); the feed reader interpolates between them
            for j in np.flatnonzero(pok):
                below = (st.live > j).astype(float)  # classes below sieve j pass it
                g = np.zeros(st.n_z)
                g[st.m_index(k)] = (below - below @ m / M) / M
                entry["passing"].append(add(f"streams.{n}.psd passing {st.sieves[j] * 1e6:.6g} um", p[j], g))
            if st.wet:
                W, _, wok = bal.water(n)
                if wok:
                    g = np.zeros(st.n_z)
                    g[st.w_index(k)] = 1.0
                    entry["water"] = add(f"streams.{n}.water_tph", W, g)
            self._layout.append(entry)
        self._additions = []
        for k, unit in enumerate(bal.structure.additions):
            v, _, ok = bal.addition(unit)
            if ok:
                g = np.zeros(st.n_z)
                g[st.a_index(k)] = 1.0
                self._additions.append((unit, add(f"water_additions.{unit}.water_tph", v, g)))
        self.input_values = np.array(self.input_values)
        self._write_inputs(self.doc, self.input_values)

    def _write_inputs(self, doc: dict, values) -> None:
        """Write input values (SI, in the order of ``input_labels``) into a flowsheet document."""
        fs = self.balance.survey.flowsheet
        for e in self._layout:
            u = doc["units"][e["unit"]]
            u["solids_tph"] = float(values[e["solids"]] * TPH)
            sizes = [float(x) * 1e6 for x in e["sizes"]]
            # within its errors a reconciled passing may pass 100 % by ~1e-4 (summary.json lists it under
            # outside_physical_range); a feed PSD must lie in [0, 100] %
            passing = [float(x) for x in np.clip(values[e["passing"]], 0.0, 1.0) * 100]
            top = fs.grid.x[0] * 1e6
            if passing[0] < 100.0 - 1e-9 and sizes[0] < top * (1 - 1e-9):
                sizes, passing = [top] + sizes, [100.0] + passing
            passing = [float(x) for x in np.minimum.accumulate(passing)]  # reconciled passing is monotone to rounding
            u["psd"] = {"form": "sieves", "size_um": sizes, "passing_pct": passing}
            for key in [key for key in u if key.startswith(("water_", "solids_content_"))]:
                del u[key]
            if e["water"] is not None:
                u["water_tph"] = float(values[e["water"]] * TPH)
        for unit, i in self._additions:
            tbl = doc["units"][unit]
            for key in [key for key in tbl if key.startswith("add_water_")]:
                del tbl[key]
            tbl["add_water_tph"] = float(values[i] * TPH)

    def input_covariance(self, theta) -> np.ndarray:
        """The part of the residuals' covariance (whitened) that the errors of the model's inputs add.

        The model takes the reconciled feeds û (solids, sieve analysis, water, additions) as exact,
        but they carry errors e_u, correlated with those of the data ŷ. To first order the residual
        is e_y - G e_u - J dtheta, with G = d(model)/du; its covariance is C_yy - G C_uy - C_yu G^T +
        G C_uu G^T, which exceeds the weighting's C_yy - K C_uu K^T (K = C_yu C_uu^+, the
        conditioning on the feed measurements) by (G - K) C_uu (G - K)^T. That excess, whitened,
        is returned (forward differences of G, one solve per input). It vanishes when the model
        depends on its inputs as the reconciliation's regression does; with per-energy rates the
        feed rate sets kWh/t, so it does not.
        """
        bal = self.balance
        st = bal.structure
        if not len(self.input_values):
            return np.zeros((self.y.size, self.y.size))
        U = np.array(self.input_grads) @ bal.N
        Y = bal.meta["J"][self.rows] * st.sd[self.rows][:, None]
        Cuu = U @ bal.cov_t @ U.T
        K = (Y @ bal.cov_t @ U.T) @ np.linalg.pinv(Cuu, rcond=1e-12, hermitian=True)
        base = self.measurements(theta)[self.rows]
        G = np.zeros((self.rows.size, self.input_values.size))
        for k, v in enumerate(self.input_values):
            if not math.sqrt(max(Cuu[k, k], 0.0)) > 1e-9 * max(abs(v), 1e-3):
                continue  # fixed by the balances (the top sieve of a feed passing 100 %): no error to carry
            h = 1e-4 * abs(v) if self.input_labels[k].endswith("_tph") else (-1e-4 if v >= 1e-4 else 1e-4)
            h = h or 1e-6
            vals = self.input_values.copy()
            vals[k] += h
            doc = self.document(theta)
            self._write_inputs(doc, vals)
            G[:, k] = (self.measurements(theta, self.solve(theta, doc))[self.rows] - base) / h
        D = self.W @ (G - K)
        return D @ Cuu @ D.T

    def document(self, theta) -> dict:
        """The flowsheet document with the parameters set to ``theta``."""
        doc = copy.deepcopy(self.doc)
        for n, v in zip(self.names, theta):
            _set(doc, n, v)
        return doc

    def solve(self, theta, doc=None):
        """The flowsheet solved at ``theta`` (or for the document ``doc``)."""
        from millflow.flowsheet import from_dict, solve

        fs = from_dict(self.document(theta) if doc is None else doc, source="<fitted circuit>",
                       base_dir=self.base_dir)
        return solve(fs)

    def measurements(self, theta, sol=None) -> np.ndarray:
        """The model's value of every measurement row of the balance (SI fractions and kg/s)."""
        return predicted_measurements(self.balance, sol if sol is not None else self.solve(theta))


def predicted_measurements(balance, sol) -> np.ndarray:
    """The measurement functions of ``balance`` evaluated on a solved flowsheet."""
    from millflow.psd import cum_passing_at

    st = balance.structure
    fs = sol.flowsheet
    z = np.zeros(st.n_z)
    for s, n in enumerate(st.streams):
        f = np.maximum(sol.flow(n), 0.0)
        M = f.sum()
        P = np.concatenate([[1.0], cum_passing_at(fs.grid, f / M, st.sieves), [0.0]]) if M > 0 else None
        cls = -np.diff(P) if P is not None else np.zeros(st.sieves.size + 1)
        z[st.m_index(s)] = M * cls[st.live]
        if st.wet:
            z[st.w_index(s)] = sol.water_flow(n)
    for k, u in enumerate(st.additions):
        z[st.a_index(k)] = fs.water_added.get(u, 0.0)
    return st.measure(z)[0]


def read_fit_table(t, where: str = "fit") -> tuple[list, dict, dict]:
    """Parameter names, {name: (min, max)} and optimizer options of a survey's ``[fit]`` table."""
    from millflow.inputs import check_keys

    if not isinstance(t, dict):
        raise InputError(f"{where}: expected a table [fit]")
    check_keys(t, {"parameters", "starts", "global_search", "leave_one_out"}, where)
    pt = t.get("parameters")
    if not isinstance(pt, dict) or not pt:
        raise InputError(f"{where}.parameters: expected a table of flowsheet keys, e.g. "
                         "\"units.cyclones.d50c_um\" = {min = 50, max = 300}")
    bounds = {}
    for name, b in pt.items():
        w = f"{where}.parameters.{name}"
        if not isinstance(b, dict):
            raise InputError(f"{w}: expected {{min = ..., max = ...}}")
        check_keys(b, {"min", "max"}, w)
        lo, hi = b.get("min"), b.get("max")
        if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) for v in (lo, hi)):
            raise InputError(f"{w}: expected numbers min and max")
        if not lo < hi:
            raise InputError(f"{w}: min = {lo} is not below max = {hi}")
        bounds[name] = (float(lo), float(hi))
    starts = t.get("starts", 3)
    if isinstance(starts, bool) or not isinstance(starts, int) or starts < 1:
        raise InputError(f"{where}.starts = {starts!r}: expected a whole number >= 1")
    gs = t.get("global_search", False)
    loo = t.get("leave_one_out", True)
    for k, v in (("global_search", gs), ("leave_one_out", loo)):
        if not isinstance(v, bool):
            raise InputError(f"{where}.{k} = {v!r}: expected true or false")
    return list(bounds), bounds, {"starts": starts, "global_search": gs, "leave_one_out": loo}


@dataclass
class CircuitFit:
    """A fitted circuit: the estimate (:class:`~millflow.fitting.estimate.FitResult`) and its model."""

    model: CircuitModel
    result: object
    leave_one_out: dict
    input_cov: np.ndarray | None = None   # parameter covariance added by the errors of the inputs

    @property
    def cov_scale(self) -> float:
        """Factor on the eq. 9 covariance.

        The residuals are whitened by the stated covariance, so SER^2 = 1 is known; eq. 9 rescales
        by the observed SER^2. The larger of the two is used (a reported SE is never below either
        estimate).
        """
        ser2 = float(self.result.ser) ** 2
        return max(1.0, 1.0 / ser2) if ser2 > 0 and math.isfinite(ser2) else 1.0

    @property
    def covariance(self) -> np.ndarray:
        """Parameter covariance, with the part the reconciled feeds' errors add.

        Parameter covariance: eq. 9's (scaled as :attr:`cov_scale` says) plus the part the
        errors of the reconciled feeds add through the model (:meth:`CircuitModel.input_covariance`,
        propagated as A M A^T with A = (J^T J)^+ J^T of the whitened Jacobian).
        """
        base = np.asarray(self.result.stats["covariance"]) * self.cov_scale
        return base if self.input_cov is None else base + self.input_cov

    @property
    def values(self) -> dict:
        return {n: self.result.params[n].value for n in self.model.names}

    def document(self) -> dict:
        """The flowsheet document with the parameters set to ``theta``."""
        return self.model.document([self.values[n] for n in self.model.names])

    def prediction_band(self, edit, quantity, step: float = 1e-4) -> tuple[float, float]:
        """Value and SD of a quantity at an operating point.

        (value, SD) of ``quantity(solution)`` at an operating point ``edit(document)`` (in place),
        the SD propagated from the parameter covariance (eq. 9) by central differences.
        """
        th = np.array([self.values[n] for n in self.model.names])

        def q(t):
            doc = self.model.document(t)
            edit(doc)
            return float(quantity(self.model.solve(t, doc)))

        cov = self.covariance
        g = np.zeros(th.size)
        for k in range(th.size):
            h = step * max(abs(th[k]), 1e-3)
            tp, tm = th.copy(), th.copy()
            tp[k] += h
            tm[k] -= h
            g[k] = (q(tp) - q(tm)) / (2 * h)
        return q(th), float(math.sqrt(max(g @ cov @ g, 0.0)))

    def to_dict(self) -> dict:
        out = {}
        cov = self.covariance
        se_all = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        for i, n in enumerate(self.model.names):
            s = self.result.stats["params"][n]
            lo, hi = s["ci95"]
            v = s["value"]
            tq = (hi - v) / s["se"] if s["se"] > 0 and math.isfinite(s["se"]) else math.nan
            se = float(se_all[i]) if math.isfinite(s["se"]) else math.inf
            out[n] = {"value": v, "se": se, "se_eq9": s["se"],
                      "se_inputs": None if self.input_cov is None else float(math.sqrt(max(self.input_cov[i, i], 0))),
                      "ci95": [v - tq * se, v + tq * se],
                      "flags": list(s.get("flags", s.get("reasons", [])))}
        st = self.result.stats
        with np.errstate(divide="ignore", invalid="ignore"):
            corr = cov / np.outer(se_all, se_all)
        return {"parameters": out, "ssr": self.result.ssr, "n_data": self.result.n_data,
                "dof": self.result.n_data - self.result.n_params, "spread": self.result.spread,
                "starts": self.result.starts, "runtime_s": self.result.runtime_s,
                "weights": "reconciled covariance (whitened, pseudo-inverse)",
                "se_rule": ("the larger of eq. 9 (scaled by SER^2) and the known-variance covariance (SER^2 = 1), "
                            "plus the errors of the reconciled feeds propagated through the model (se_inputs)"),
                "cluster_robust": CLUSTER_NOTE,
                "input_errors": getattr(self.model, "input_note", None),
                "correlation": {"names": list(self.model.names),
                                "matrix": [[float(x) if math.isfinite(x) else None for x in r]
                                           for r in np.round(corr, 4)]},
                "condition_number": _finite(st["condition_number"]),
                "condition_number_raw": _finite(st["condition_number_raw"]),
                "singular": bool(st.get("singular", False)),
                "correlated_pairs": [list(p) for p in st.get("correlated_pairs", [])],
                "leave_one_stream_out": self.leave_one_out}


#: Why a circuit fit has no cluster-robust (sandwich) SEs, in fit.json.
CLUSTER_NOTE = ("not used: the residuals are whitened by the reconciled covariance, which already carries the "
                "correlation of each stream's analysis (the balances and the closure of its fractions), and "
                "each whitened component mixes streams, so no grouping by stream is left to cluster on; a "
                "survey has fewer than 10 streams besides (the sandwich needs 10 clusters or more). The "
                "SEs are eq. 9's or the known-variance ones, whichever is larger")


def _finite(v):
    v = float(v)
    return v if math.isfinite(v) else None


def fit_circuit(balance, names, bounds: dict, *, starts: int = 3, global_search: bool = False,
                leave_one_out: bool = True, quiet: bool = True, seed: int = 0) -> CircuitFit:
    """Fit flowsheet parameters ``names`` (dotted document paths, bounds {name: (min, max)}) to ``balance``."""
    from millflow.fitting.estimate import fit

    model = CircuitModel(balance, names)
    params = {n: Parameter(n, min(max(model.start[n], bounds[n][0]), bounds[n][1]), bounds[n][0], bounds[n][1])
              for n in names}
    res = fit(model, params, global_search=global_search, starts=starts, grid_check=False, quiet=quiet,
              seed=seed, popsize=6, maxiter=30)
    loo = leave_one_stream_out(balance, names, params, res) if leave_one_out else {}
    return CircuitFit(model, res, loo, _input_cov(model, res))


def _input_cov(model: CircuitModel, res):
    """A M A^T: the parameter covariance the input errors add (None when the fit is singular)."""
    model.input_note = "not propagated: the fit is singular"
    if res.stats.get("singular"):
        return None
    th = np.array([res.params[n].value for n in model.names])
    J = np.zeros((model.y.size, th.size))
    for k in range(th.size):
        h = 1e-4 * max(abs(th[k]), 1e-3)
        tp, tm = th.copy(), th.copy()
        tp[k] += h
        tm[k] -= h
        J[:, k] = (model.predict(tp)[0] - model.predict(tm)[0]) / (2 * h)
    if not np.all(np.isfinite(J)):
        return None
    A = np.linalg.pinv(J.T @ J) @ J.T
    try:
        M = model.input_covariance(th)
    except MillflowError as exc:  # a perturbed feed the circuit cannot run: said in fit.json, not hidden
        model.input_note = f"not propagated: {exc}"
        return None
    model.input_note = "propagated through the model (se_inputs)"
    return A @ M @ A.T


def leave_one_stream_out(balance, names, params, res) -> dict:
    """Refit without each measured stream in turn and predict it.

    Per stream the RMS of the whitened prediction error (about 1 when the model predicts it
    within its errors).
    """
    from millflow.fitting.estimate import fit

    full = CircuitModel(balance, names)
    st = balance.structure
    out = {}
    best = {n: Parameter(n, res.params[n].value, params[n].min, params[n].max) for n in names}
    for stream in dict.fromkeys(st.rows[i]["stream"] for i in full.rows):
        keep = [i for i in full.rows if st.rows[i]["stream"] != stream]
        held = [i for i in full.rows if st.rows[i]["stream"] == stream]
        try:
            sub = CircuitModel(balance, names, rows=keep)
            r = fit(sub, best, global_search=False, starts=1, grid_check=False, quiet=True, profile=False)
        except InputError as exc:
            out[stream] = {"skipped": str(exc)}
            continue
        pred = sub.measurements([r.params[n].value for n in names])[held]
        one = CircuitModel(balance, names, rows=held)
        e = one.W @ (pred - balance.adjusted[held])
        out[stream] = {"rms_normalised_error": float(np.sqrt(np.mean(e ** 2))), "n": len(held)}
    return out


# ----------------------------------------------------------------------- TOML out
def _key(k: str) -> str:
    import re

    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ("nan" if math.isnan(v) else ("inf" if v > 0 else "-inf"))
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise InputError(f"cannot write {v!r} to TOML")


def to_toml(doc: dict) -> str:
    """A flowsheet document as TOML text (tables as [sections], small tables inline)."""
    lines = []

    def table(d: dict, path: list):
        scalars = {k: v for k, v in d.items() if not isinstance(v, dict)}
        subs = {k: v for k, v in d.items() if isinstance(v, dict)}
        inline = {k: v for k, v in subs.items() if not any(isinstance(x, dict) for x in v.values())
                  and len(_value(v)) <= 100 and path}
        if path and (scalars or inline):
            lines.append("[" + ".".join(_key(p) for p in path) + "]")
        for k, v in scalars.items():
            lines.append(f"{_key(k)} = {_value(v)}")
        for k, v in inline.items():
            lines.append(f"{_key(k)} = {_value(v)}")
        if path and (scalars or inline):
            lines.append("")
        for k, v in subs.items():
            if k not in inline:
                table(v, path + [k])

    table(doc, [])
    return "\n".join(lines) + "\n"

