"""Data reconciliation of a survey: weighted least squares with exact node balances.

Minimise the weighted sum of squared adjustments

    SSR = sum_i ((h_i(z) - y_i) / sd_i)^2

over the component flows z (solids per stream and sieve class, water, water additions:
:mod:`millflow.survey.structure`) subject to the node balances A z = b, exactly. The
balances are linear in z, so they are eliminated exactly, not penalised: z = z_p + N t
with z_p the least-squares solution of A z = b (a residual means the exact values
contradict the balances: an error) and N an orthonormal basis of the null space of A.
What remains is the bilinear flow x fraction problem as an unconstrained non-linear
least-squares problem in t, solved by Gauss-Newton (analytic Jacobian, minimum-norm
steps, step halving). This is the Lagrangian
formulation of JKMBal-style reconciliation with the constraint linearisation made
exact by the choice of variables (component flows), so no outer iteration on the
constraints is needed and every balance closes to rounding.

Statistics at the solution, with J the whitened Jacobian dh/dt / sd (linearised
covariance, exact for the linear part):

- the rank r of J; the SSR is compared with chi-square on n_measured - r degrees of
  freedom (the redundancy);
- cov(t) = (J^T J)^+ on the observable subspace; a derived quantity q(z) (an unmeasured
  flow, a circulating load) is *observable* when its gradient has no component in the
  null space of J, and only then gets a value and an SD; otherwise it is reported as
  unobservable (NaN), never invented;
- adjusted measurements h(z) with covariance sd J cov J^T sd; leverage H_ii; the
  adjustment e_i has variance sd_i^2 (1 - H_ii), so the normalised adjustment is
  e_i / (sd_i sqrt(1 - H_ii)) (measurement test; a measurement with H_ii = 1 is not
  redundant: its adjustment is zero and it cannot be tested). Gross-error candidates
  exceed the two-sided Bonferroni threshold z_{1 - 0.05 / (2 n_redundant)}.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import linalg, stats

from millflow.errors import InputError, SolverError
from millflow.survey.structure import Structure, build_structure

__all__ = ["Balance", "reconcile", "GROSS_ERROR_ALPHA"]

#: Family-wise significance of the gross-error (measurement) test, Bonferroni-corrected.
GROSS_ERROR_ALPHA = 0.05
#: Singular values of the whitened Jacobian below this fraction of the largest are zero.
RANK_RTOL = 1e-9
#: Measurements whose normalised adjustments correlate by |rho| at least this much are reported as
#: not separable by the measurement test: a 7-SD shift (a 10-SD error at redundancy 0.5) then names
#: the wrong one of a pair in Phi(-7 sqrt(0.05)) = 6 % of cases or more.
INSEPARABLE_RHO = 0.9
#: A derived quantity is unobservable when its gradient's null-space part exceeds this fraction.
OBSERVABLE_RTOL = 1e-6


def test_power(k, redundancy, threshold: float):
    """Power of the measurement test for a gross error of ``k`` SD.

    P(|N(k sqrt(r), 1)| > threshold): the power of the measurement test for a gross error of
    ``k`` SD in a measurement of redundancy ``r`` (linearised reconciliation).
    """
    m = np.asarray(k, float) * np.sqrt(np.clip(redundancy, 0.0, 1.0))
    return stats.norm.sf(threshold - m) + stats.norm.cdf(-threshold - m)


@dataclass
class Balance:
    """A reconciled survey: adjusted values, covariances and the statistics.

    z : adjusted variables (see :class:`~millflow.survey.structure.Structure`) [kg/s].
    adjusted, adjusted_sd : adjusted measurements h(z) and their SDs (rows of ``structure.rows``).
    leverage : H_ii of each measurement (1: not redundant).
    chi_square : dict ssr, dof, critical_95, p_value, passed.
    gross_errors : the measurements whose normalised adjustment exceeds ``threshold``, largest first.
    """

    survey: object
    structure: Structure
    z: np.ndarray
    N: np.ndarray
    z_p: np.ndarray
    cov_t: np.ndarray
    null_t: np.ndarray
    adjusted: np.ndarray
    adjusted_sd: np.ndarray
    leverage: np.ndarray
    rank: int
    chi_square: dict
    threshold: float
    nfev: int
    runtime_s: float
    balance_error: float
    meta: dict = field(default_factory=dict)

    # ------------------------------------------------------------------ measurements
    @property
    def measured(self) -> np.ndarray:
        """The measured values."""
        return self.structure.y

    @property
    def sd(self) -> np.ndarray:
        """The standard deviations of the measurements."""
        return self.structure.sd

    @property
    def adjustment(self) -> np.ndarray:
        """Adjusted minus measured values."""
        return self.adjusted - self.structure.y

    @property
    def redundant(self) -> np.ndarray:
        """Mask of the redundant measurements."""
        return 1.0 - self.leverage > 1e-8

    @property
    def normalised(self) -> np.ndarray:
        """Normalised adjustments (NaN where a measurement is not redundant)."""
        v = np.clip(1.0 - self.leverage, 0.0, None)
        with np.errstate(divide="ignore", invalid="ignore"):
            out = self.adjustment / (self.sd * np.sqrt(v))
        return np.where(self.redundant, out, np.nan)

    @property
    def redundancy(self) -> np.ndarray:
        """Redundancy r_i = 1 - H_ii of each measurement.

        r_i = 1 - H_ii of each measurement: the share of an error in it that shows in its own
        adjustment (0: not redundant, 1: fully redundant). A gross error of k SD shifts the
        normalised adjustment by k sqrt(r_i) (linearised).
        """
        return np.where(self.redundant, np.clip(1.0 - self.leverage, 0.0, 1.0), 0.0)

    def detection_power(self, k: float = 10.0) -> np.ndarray:
        """Probability that a gross error of ``k`` SD in each measurement is detected.

        Probability that a gross error of ``k`` SD in each measurement alone (the others with
        their stated errors) takes its normalised adjustment past the threshold: the power of the
        measurement test, P(|N(k sqrt(r_i), 1)| > threshold) in the linearised reconciliation.
        """
        return np.where(self.redundant, test_power(k, self.redundancy, self.threshold), 0.0)

    def detectable_sd(self, power: float = 0.9) -> np.ndarray:
        """The gross error, in SDs of each measurement, detected with probability ``power``.

        (threshold + z_power) / sqrt(r_i) (the far tail neglected; inf where not redundant).
        """
        with np.errstate(divide="ignore"):
            k = (self.threshold + stats.norm.ppf(power)) / np.sqrt(self.redundancy)
        return np.where(self.redundant, k, np.inf)

    @property
    def gross_errors(self) -> list:
        """The measurements whose normalised adjustment exceeds the threshold, largest first."""
        n = self.normalised
        order = [int(i) for i in np.argsort(-np.nan_to_num(np.abs(n), nan=-1.0)) if np.isfinite(n[i])]
        return [self._describe(i) for i in order if abs(n[i]) > self.threshold]

    def ranked(self, count: int = 5) -> list:
        """The ``count`` measurements with the largest |normalised adjustment|, largest first."""
        n = self.normalised
        order = [int(i) for i in np.argsort(-np.nan_to_num(np.abs(n), nan=-1.0)) if np.isfinite(n[i])]
        return [self._describe(i) for i in order[:count]]

    def label(self, i: int) -> str:
        """The name of measurement ``i``."""
        r = self.structure.rows[i]
        return r["key"] + (f" {r['label']}" if "label" in r else "")

    def _describe(self, i: int) -> dict:
        return {"measurement": self.label(i), "row": i,
                "normalised_adjustment": float(self.normalised[i]),
                "adjustment_in_sd": float(self.adjustment[i] / self.sd[i]),
                "not_separable_from": [self.label(j) for j in self.inseparable(i)]}

    def adjustment_correlation(self) -> np.ndarray:
        """Correlation of the normalised adjustments (linearised).

        rho_ik = P_ik / sqrt(P_ii P_kk) with P = I - H the projector onto the redundancy space of
        the whitened Jacobian; rows and columns of measurements that are not redundant are 0.

        A gross error of k SD in measurement i shifts the normalised adjustment of measurement j
        by k sqrt(r_i) rho_ji, so measurements with |rho| near 1 respond to it almost alike and
        the measurement test cannot tell them apart: in a node whose size class is measured in
        every stream, an error in one stream's class moves the others' as much (an *equivalent
        set* of the gross-error literature). The one that is named first among them is then
        decided by the noise: P(j before i) = Phi(-k sqrt(r_i) sqrt((1 - |rho_ij|) / 2)).
        """
        if "rho" not in self.meta:
            J = self.meta["J"]
            if J.size == 0:
                self.meta["rho"] = np.zeros((self.sd.size, self.sd.size))
            else:
                U = linalg.svd(J, full_matrices=True)[0]
                P = np.eye(J.shape[0]) - U[:, :self.rank] @ U[:, :self.rank].T
                red = self.redundant
                d = np.sqrt(np.where(red, np.clip(np.diag(P), 1e-300, None), 1.0))
                C = P / d[:, None] / d[None, :]
                C[~red, :] = 0.0
                C[:, ~red] = 0.0
                self.meta["rho"] = C
        return self.meta["rho"]

    def inseparable(self, i: int, rho_min: float = INSEPARABLE_RHO) -> list[int]:
        """The measurements whose adjustments a gross error in measurement i resembles.

        The other measurements whose normalised adjustments correlate with measurement i's by
        |rho| >= ``rho_min``: a gross error in any of them looks like one in i to the test.
        """
        C = self.adjustment_correlation()
        row = np.abs(C[i]).copy()
        row[i] = 0.0
        return [int(j) for j in np.argsort(-row) if row[j] >= rho_min]

    # --------------------------------------------------------------- derived quantities
    def derived(self, gz: np.ndarray, value: float) -> tuple[float, float, bool]:
        """(value, SD, observable) of a quantity with gradient ``gz`` (dq/dz at the solution)."""
        gt = gz @ self.N
        norm = float(np.linalg.norm(gt))
        if norm == 0.0:
            return float(value), 0.0, True  # fixed by the exact values and balances alone
        leak = float(np.linalg.norm(self.null_t.T @ gt)) if self.null_t.size else 0.0
        if leak > OBSERVABLE_RTOL * norm:
            return math.nan, math.nan, False
        return float(value), float(math.sqrt(max(gt @ self.cov_t @ gt, 0.0))), True

    def solids(self, stream: str) -> tuple[float, float, bool]:
        """Reconciled solids flow of ``stream`` [kg/s], its SD, and whether it is observable."""
        s = self.structure.streams.index(stream)
        g = self.structure.solids_gradient(s)
        return self.derived(g, float(g @ self.z))

    def water(self, stream: str) -> tuple[float, float, bool]:
        """Reconciled water flow of ``stream`` [kg/s], its SD, and whether it is observable."""
        st = self.structure
        if not st.wet:
            return math.nan, math.nan, False
        g = np.zeros(st.n_z)
        g[st.w_index(st.streams.index(stream))] = 1.0
        return self.derived(g, float(self.z[st.w_index(st.streams.index(stream))]))

    def addition(self, unit: str) -> tuple[float, float, bool]:
        """Reconciled water addition of ``unit`` [kg/s], its SD, and whether it is observable."""
        st = self.structure
        g = np.zeros(st.n_z)
        g[st.a_index(st.additions.index(unit))] = 1.0
        return self.derived(g, float(g @ self.z))

    def passing(self, stream: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Cumulative passing at every sieve of the common series: values, SDs, observable."""
        st = self.structure
        s = st.streams.index(stream)
        m = self.z[st.m_index(s)]
        M = m.sum()
        vals, sds, obs = [], [], []
        for j in range(st.sieves.size):
            below = (st.live > j).astype(float)  # classes j + 1 .. n pass sieve j
            q = below @ m / M if M != 0 else math.nan
            g = np.zeros(st.n_z)
            g[st.m_index(s)] = (below - q) / M if M != 0 else 0.0
            v, sd, ok = self.derived(g, q)
            vals.append(v), sds.append(sd), obs.append(ok)
        return np.array(vals), np.array(sds), np.array(obs)

    def circulating_loads(self) -> dict:
        """Circulating load of each recycle stream (its solids over its loop's new feed), with SD."""
        from millflow.flowsheet.results import recycle_streams

        fs = self.survey.flowsheet
        st = self.structure
        lab = dict(zip(fs.units, fs.components()))
        out = {}
        for n in recycle_streams(fs):
            loop = lab[fs.streams[n].source]
            g_new = np.zeros(st.n_z)
            for m, s in fs.streams.items():
                if lab[s.source] != lab[s.target] and lab[s.target] == loop:
                    g_new += st.solids_gradient(st.streams.index(m))
            g_rec = st.solids_gradient(st.streams.index(n))
            F, R = g_new @ self.z, g_rec @ self.z
            if F <= 0:
                out[n] = (math.nan, math.nan, False)
                continue
            cl = R / F
            out[n] = self.derived((g_rec - cl * g_new) / F, cl)
        return out

    def observability(self) -> dict:
        """Which stream quantities the survey determines: lists of observable and unobservable keys."""
        st = self.structure
        ok, bad = [], []
        for n in st.streams:
            for key, res in (("solids_tph", self.solids(n)),) + ((("water_tph", self.water(n)),) if st.wet else ()):
                (ok if res[2] else bad).append(f"streams.{n}.{key}")
            p_ok = self.passing(n)[2]
            if p_ok.all() or not p_ok.any():
                (ok if p_ok.all() else bad).append(f"streams.{n}.psd")
            else:  # an analysis on a shorter range than the common series: the sieves it leaves open
                bad.append(f"streams.{n}.psd at " + ", ".join(f"{x * 1e6:.6g}" for x in st.sieves[~p_ok]) + " um")
        for u in st.additions:
            (ok if self.addition(u)[2] else bad).append(f"water_additions.{u}.water_tph")
        return {"observable": ok, "unobservable": bad}


def _particular(st: Structure, source: str = "survey") -> tuple[np.ndarray, np.ndarray]:
    """z_p with A z_p = b and the null-space basis N of A; contradictory exact values raise."""
    A, b = st.A, st.b
    if A.shape[0] == 0:
        return np.zeros(st.n_z), np.eye(st.n_z)
    U, s, Vt = linalg.svd(A, full_matrices=True)
    tol = max(A.shape) * np.finfo(float).eps * (s[0] if s.size else 1.0) * 10
    r = int(np.sum(s > tol))
    z_p = Vt[:r].T @ ((U[:, :r].T @ b) / s[:r])
    resid = A @ z_p - b
    scale = max(float(np.max(np.abs(b))), 1e-300)
    if np.max(np.abs(resid), initial=0.0) > 1e-9 * scale:
        keys = ", ".join(k for k, _ in st.exact)
        worst = st.constraint_names[int(np.argmax(np.abs(resid)))]
        raise InputError(f"{source}: the exact values (SD 0) {keys} contradict the balances (they cannot all hold: "
                         f"{worst} is off by {abs(resid).max() * 3.6:.4g} t/h); give them SDs > 0")
    return z_p, Vt[r:].T


def _solve(st: Structure, z_p, N, t_start, max_iter: int, source: str, tol: float = 1e-6):
    """Gauss-Newton on the balance-eliminated problem.

    Each step the minimum-norm least-squares solution of the linearised problem (LAPACK, so
    directions the data leave undetermined are not moved), halved until the SSR does not rise;
    (t, evaluations).
    """
    w = 1.0 / st.sd

    def resid(t):
        h, J = st.measure(z_p + N @ t, sparse=True)
        return (h - st.y) * w, J

    with np.errstate(divide="ignore", invalid="ignore"):
        r, Jz = resid(t_start)
    if not np.all(np.isfinite(r)):
        raise InputError(f"{source}: a stream with a measured analysis or % solids starts with no solids "
                         "flow; give it a solids_tph")
    if N.shape[1] == 0:
        return np.zeros(0), 1
    t, ssr, nfev = np.asarray(t_start, float), float(r @ r), 1
    for _ in range(max_iter):
        J = np.asarray(Jz @ N) * w[:, None]
        step = linalg.lstsq(J, -r, lapack_driver="gelsy", cond=RANK_RTOL)[0]
        lam = 1.0
        while True:
            with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
                r_new, Jz_new = resid(t + lam * step)
            nfev += 1
            s_new = float(r_new @ r_new)
            if np.isfinite(s_new) and s_new <= ssr * (1 + 1e-12) + 1e-300:
                break
            lam *= 0.5
            if lam < 1e-10:
                raise SolverError(f"{source}: the reconciliation does not converge (no step lowers the weighted "
                                  "sum of squares); check for a stream whose solids flow goes to zero")
        moved = lam * float(np.linalg.norm(step))
        t, r, Jz, old, ssr = t + lam * step, r_new, Jz_new, ssr, s_new
        # converged when the SSR no longer moves (1e-9 relative) and the variables move less than
        # 1e-6 of their size: far below any measurement's precision (SDs of 0.1 % and more); the
        # balances hold exactly at every step whatever the tolerance
        if old - ssr <= 1e-3 * tol * max(ssr, 1.0) and moved <= tol * (float(np.linalg.norm(t)) + 1e-12):
            return t, nfev
    raise SolverError(f"{source}: the reconciliation did not converge in {max_iter} Gauss-Newton steps")


def reconcile(survey, *, max_iter: int = 100, reweight: int = 2) -> Balance:
    """Reconcile ``survey`` (a :class:`~millflow.survey.reader.Survey`); see the module docstring.

    Raises InputError for a survey that cannot be balanced: exact values that contradict
    the balances, solids flows that no measurement determines (unobservable system), or
    a weighted SSR so far beyond its chi-square distribution (more than
    ``ABSURD_SSR_PER_DOF`` per degree of freedom) that no gross error explains it; and
    SolverError when no start reaches a physical solution (every stream's solids flow
    positive, no water flow or addition negative by more than 3 SD), unless the least SSR
    reached has only water below 0 at an SSR a gross error explains (not absurd): that
    result is kept and ``meta["unphysical"]`` (the summary's ``physical_range_violations``)
    says what is below 0, beside the gross-error candidates that cause it. Partly unobservable
    surveys are reconciled; :meth:`Balance.observability` lists what the data leave
    undetermined.

    Starts (:mod:`millflow.survey.start`): the flows derived from the measured flows, water
    meters and % solids by the linear n-product balance; when its solution is not physical
    or fails the chi-square test at 0.1 %, also the measured-or-typical start and the derived
    one scaled by 0.5 and 2. Of the physical solutions the one of least SSR is kept; the
    summary says how many starts were tried.

    reweight : passes in which the SDs that come from the error model (relative flow
        SDs, the sqrt(p(1-p)) rule of sieve fractions) are re-evaluated at the reconciled
        values before solving again (0: SDs at the measured values, as given). At the
        measured values a gross error inflates its own SD and hides; at the reconciled
        values it does not.
    """
    from millflow.survey.start import derived_start, naive_start

    t0 = time.perf_counter()
    st = build_structure(survey)
    if st.y.size == 0:
        raise InputError(f"{survey.source}: nothing is measured with an SD > 0; there is nothing to reconcile")
    z_p, N = _particular(st, survey.source)
    sd_measured = st.sd.copy()
    derived = derived_start(st, survey)
    starts = [("derived from the measured flows and % solids", derived)] if derived is not None else []
    starts.append(("measured flows, typical elsewhere", naive_start(st, survey)))
    if derived is not None:
        starts += [(f"derived x {k:g}", derived * k) for k in (0.5, 2.0)]
    tried, best, least, failures = 0, None, None, []
    for label, z0 in starts:
        st.sd = sd_measured.copy()
        tried += 1
        try:
            bal = _solve_from(st, survey, z_p, N, z0, max_iter, reweight, sd_measured)
        except SolverError as exc:
            failures.append(f"{label}: {exc}")
            continue
        bal.meta["start"] = label
        bal.meta["unphysical"] = unphysical(bal)
        if least is None or bal.chi_square["ssr"] < least.chi_square["ssr"] * (1 - 1e-9):
            least = bal
        if bal.meta["unphysical"]:
            failures.append(f"{label}: {bal.meta['unphysical'][0]}")
        elif best is None or bal.chi_square["ssr"] < best.chi_square["ssr"] * (1 - 1e-9):
            best = bal
        if best is not None and (best.chi_square["p_value"] >= 1e-3 or best.chi_square["dof"] <= 0):
            break
    if best is None and least is not None and not _absurd(least) and not any(
            "solids" in p for p in least.meta["unphysical"]):
        # every start ends with a water flow or addition below 0 beyond its errors, at an SSR a gross
        # error explains: the result is kept, with the violation in the summary beside the candidates
        best = least
    if best is None:
        raise SolverError(f"{survey.source}: the reconciliation reaches no physical solution from {tried} starts "
                          f"({failures[0]}" + (f"; weighted SSR {least.chi_square['ssr']:.4g} on "
                                               f"{least.chi_square['dof']} degrees of freedom" if least else "")
                          + "); check the flows and % solids of that stream and the units of the measured flows")
    best.meta["starts_tried"] = tried
    best.runtime_s = time.perf_counter() - t0
    measured_flows = [n for n in st.streams if best.solids(n)[2]]
    if not measured_flows:
        raise InputError(f"{survey.source}: unobservable system: no stream's solids flow is determined by the "
                         "survey (give at least one solids_tph, e.g. the fresh feed's weightometer)")
    chi = best.chi_square
    if _absurd(best):
        top = ", ".join(f"{c['measurement']} ({c['normalised_adjustment']:+.3g})" for c in best.ranked(3))
        raise InputError(f"{survey.source}: the measurements contradict each other far beyond their SDs (weighted "
                         f"SSR {chi['ssr']:.4g} on {chi['dof']} degrees of freedom, more than "
                         f"{ABSURD_SSR_PER_DOF:g} per degree of freedom, from {tried} starts); largest normalised "
                         f"adjustments: {top}: check these values and their units, or give them larger SDs")
    return best


#: A weighted SSR above this many times its degrees of freedom is refused: a single gross
#: error of k SD adds about k^2 r to the SSR, so reaching 100 per degree of freedom takes
#: errors of hundreds of SDs (a wrong unit, a typo) or SDs understated tenfold throughout.
ABSURD_SSR_PER_DOF = 100.0


def _absurd(bal) -> bool:
    chi = bal.chi_square
    return chi["dof"] > 0 and chi["ssr"] > ABSURD_SSR_PER_DOF * chi["dof"]


def unphysical(bal) -> list[str]:
    """What makes a reconciled solution impossible.

    A stream whose solids flow is not positive, a water flow or water addition negative by more
    than 3 of its SDs (or negative and unobservable). Small negatives within the errors are not
    refused; :func:`negatives` reports them.
    """
    st = bal.structure
    out = []
    scale = float(np.max(np.abs(bal.z[: st.S * st.K]).reshape(st.S, st.K).sum(axis=1), initial=0.0)) or 1.0
    for s, n in enumerate(st.streams):
        M = float(bal.z[st.m_index(s)].sum())
        if not M > 1e-9 * scale:
            out.append(f"stream {n} has solids {M * 3.6:.4g} t/h")
    if st.wet:
        checks = [(st.w_index(s), bal.water, n, f"stream {n} has water") for s, n in enumerate(st.streams)]
        checks += [(st.a_index(k), bal.addition, u, f"water added at {u} is") for k, u in enumerate(st.additions)]
        for index, sd_of, name, what in checks:
            v = float(bal.z[index])
            if v < -1e-9 * scale:
                _, sd, ok = sd_of(name)
                if not ok or v < -3.0 * sd:  # below 0 by more than its error (or no error known)
                    out.append(f"{what} {v * 3.6:.4g} t/h")
    return out


def negatives(bal) -> list[dict]:
    """Reconciled values outside their physical range but within their errors.

    Reported rather than clipped: a size class's solids flow below 0 (its adjusted fraction
    negative, the passing above it over 100 %), a stream's water or a water addition below 0.
    """
    st = bal.structure
    out = []
    for s, n in enumerate(st.streams):
        m = bal.z[st.m_index(s)]
        M = m.sum()
        for k in np.flatnonzero(m < 0):
            c = int(st.live[k])
            lo = st.sieves[c] * 1e6 if c < st.sieves.size else 0.0
            hi = st.sieves[c - 1] * 1e6 if c > 0 else None
            label = (f"+{lo:.6g} um" if hi is None else f"-{hi:.6g} +{lo:.6g} um" if lo > 0 else f"-{hi:.6g} um")
            out.append({"stream": n, "quantity": f"class {label}", "value_pct": float(100 * m[k] / M),
                        "unit": "% of the stream's solids"})
        if st.wet and bal.z[st.w_index(s)] < 0:
            out.append({"stream": n, "quantity": "water", "value_tph": float(bal.z[st.w_index(s)] * 3.6)})
    for k, u in enumerate(st.additions if st.wet else []):
        if bal.z[st.a_index(k)] < 0:
            out.append({"unit": u, "quantity": "water addition", "value_tph": float(bal.z[st.a_index(k)] * 3.6)})
    return out


def _solve_from(st: Structure, survey, z_p, N, z0, max_iter: int, reweight: int, sd_measured) -> Balance:
    """Solve from the start ``z0`` (projected onto the balances) and collect the statistics."""
    t0 = time.perf_counter()
    t = N.T @ (z0 - z_p)
    nfev = 0
    for k in range(1 + reweight):  # the passes before the last only set the weights: 1e-3 is enough
        t, n = _solve(st, z_p, N, t, max_iter, survey.source, 1e-6 if k == reweight else 1e-3)
        nfev += n
        if reweight:  # the error model at the reconciled values: a gross error does not inflate its own SD
            st.sd = st.model_sd(st.measure(z_p + N @ t)[0])
    w = 1.0 / st.sd
    z = z_p + N @ t
    h, Jz = st.measure(z)
    J = (Jz @ N) * w[:, None]
    ssr = float(np.sum(((h - st.y) * w) ** 2))
    if J.size:
        U, s, Vt = linalg.svd(J, full_matrices=True)
        rank = int(np.sum(s > RANK_RTOL * s[0])) if s.size and s[0] > 0 else 0
        Ur, sr, Vr = U[:, :rank], s[:rank], Vt[:rank].T
        cov_t = (Vr / sr ** 2) @ Vr.T
        null_t = Vt[rank:].T
    else:
        rank, Ur = 0, np.zeros((st.y.size, 0))
        cov_t, null_t = np.zeros((0, 0)), np.zeros((0, 0))
    leverage = np.sum(Ur ** 2, axis=1)
    adjusted_sd = st.sd * np.sqrt(np.clip(leverage, 0.0, None))
    dof = st.y.size - rank
    chi = {"ssr": ssr, "dof": dof, "n_measured": int(st.y.size), "rank": rank,
           "critical_95": float(stats.chi2.ppf(0.95, dof)) if dof > 0 else math.nan,
           "p_value": float(stats.chi2.sf(ssr, dof)) if dof > 0 else math.nan}
    chi["passed"] = bool(ssr <= chi["critical_95"]) if dof > 0 else None
    n_red = int(np.sum(1.0 - leverage > 1e-8))
    threshold = float(stats.norm.ppf(1 - GROSS_ERROR_ALPHA / (2 * max(n_red, 1))))
    resid_bal = st.A @ z - st.b if st.A.size else np.zeros(0)
    flows = np.abs(z[: st.S * st.K]).sum() or 1.0
    # the structure is shared by the starts; the balance keeps its own SDs
    import copy

    own = copy.copy(st)
    own.sd = st.sd.copy()
    return Balance(survey, own, z, N, z_p, cov_t, null_t, h, adjusted_sd, leverage, rank, chi, threshold, nfev,
                   time.perf_counter() - t0, float(np.max(np.abs(resid_bal), initial=0.0) / flows),
                   {"sd_at_measured": sd_measured, "reweight_passes": reweight, "J": J})
