"""Forward models for fitting: breakage forms shared across conditions (eqs. 3-10).

A :class:`~millflow.fitting.spec.ModelSpec` says *what* is fitted (rate form, breakage
form, transport, classification, which process parameters enter the eq. 10 power law); a
:class:`ForwardModel` compiles it against a :class:`~millflow.fitting.data.PSDData`
set and a fine numerical grid (Principle IV) and evaluates the predicted measured
values for a whole *population* of parameter vectors at once (shape (P, n_params) ->
(P, n_data)), which is what differential evolution and finite-difference Jacobians
need.

Parameters (positive ones in logs, named ``ln_...``):

- rate ``power`` (eq. 5): ``ln_A0``, ``alpha``;  ``austin`` (eq. 7 without ball size):
  ``ln_A0``, ``alpha``, ``ln_mu`` (ln of mu0/x0), ``Lambda``. With process parameters
  ``austin_ball`` (eq. 7 with its ball-size terms): also ``xi`` and ``eta``, the ball
  size x_b [mm] from the process column ``ball_column`` and x_b0 its geometric mean
  over the conditions. With process parameters
  (eq. 10) A = exp(ln_A0) prod_k (p_k/p_ref_k)^a_k, one exponent ``a_<column>`` each,
  p_ref the geometric mean over the conditions (it decorrelates ln_A0 from the a_k).
- breakage ``normalized`` (eq. 6): ``phi``, ``gamma``, ``beta``; ``single``: B = r^gamma
  (eq. 6 with phi = 1): ``gamma``; ``non_normalized`` (eq. 8): ``phi`` (phi0 at the
  top of the grid), ``gamma``, ``beta``, ``theta`` (phi_j = phi0 (x_1/x_j)^theta; members
  whose phi_j leaves [0, 1] are outside the domain); ``fixed``: a given b matrix, nothing fitted (the
  hybrid, semi-back-calculation method; fixing phi, gamma, beta with ``vary=False``
  does the same for eq. 6).
- classification ``screen``: d_i* = 1 / (1 + (x_i / (c50 * screen))^n), parameters
  ``ln_c50`` and ``ln_sharp`` (n): material finer than the screen opening leaves at
  the mean rate, coarser material is held back until it breaks.
  ``screen_power``: d_i* = (x_i/x0 * screen_ref/screen)^-n_screen (screen_ref the
  geometric mean over the conditions), parameter ``n_screen``: the
  limit of ``screen`` when c50 is far below the measured sizes (then only
  A / c50^n is identifiable from product samples: the fit reports correlation 1).
  ``screen_power_cut``: the same with a hard cut at the opening (classes whose lower
  edge is at or above it cannot pass: d* = 1e-12).
- mode ``batch`` (eq. 4, times from the table), ``plug_flow`` (eq. 4 at t = tau; with
  classification class i travels at d_i* u, rates S/d*), ``well_mixed`` (eq. 3; ``n_tanks``
  > 1: equal well-mixed tanks in series, tau/n each, the same classification at each
  outlet). For continuous modes tau comes from a process column (``tau_column``) or is 1,
  in which case A is the dimensionless tau*A. Location ``holdup`` of well-mixed tanks
  predicts the mill content, proportional to p_i / d_i* in one tank: sampling product and
  hold-up separates breakage from classification.
- mode ``mill``: any transport model of :mod:`millflow.mill` (``transport`` one of
  :data:`TRANSPORTS`, its fixed parameters in ``transport_params``, tau from
  ``tau_column`` or 1), classification d_i* as above placed by ``where`` (None: the
  mill's default, the discharge for cells and the axis for plug flow and axial
  dispersion; ``"cells"`` = every cell outlet, as ``well_mixed`` with ``n_tanks``).
  Locations ``product``, ``holdup`` (mill content), ``cell:K`` (content of cell K,
  1-based, cell transports; ``cell_K`` is accepted as an alias) and ``z:Y`` (content at
  the fractional axial position Y, plug flow and axial dispersion), spelled as
  :func:`millflow.steady_mill` reads them.

Every continuous mode reaches the mill through one door,
:class:`millflow.mill.samples.SampledMill` (the modes ``plug_flow`` and ``well_mixed``
stand for the transport :func:`millflow.mill.transport.mode_transport` names): chains of
cells, networks of cells and plug flow are solved for the whole population at once;
other transports (axial dispersion, hold-up of plug flow) one refined mill per member and
condition, milliseconds each instead of one array operation for the whole population:
prefer local fits from a good start (``fit(..., global_search=False)``) or a small
differential-evolution population there.

The parameter vectors are decoded by :class:`~millflow.fitting.translate.Translator` (the
one translator of a fit vector into S, b, d* and transport values, eq. 10 included), which
puts the continuous forms on the grid by class averages (second order in the class width,
:mod:`millflow.breakage.averaged`; Austin's upper edges on a grid with ``scheme =
"upper_edge"``), so that the fitted parameters are those of the continuous model, not of
one grid (Principle IV: solve fine, reduce to the sieves). The model's cumulative passing
is exact at the grid edges; measured sizes on an edge read it there, others by a monotone
cubic in ln x (:mod:`millflow.fitting.sieves`).
"""
from __future__ import annotations

import numpy as np

from millflow.batch import batch_grind_population
from millflow.errors import InputError
from millflow.fitting.data import PSDData
from millflow.fitting.sieves import SieveReduction
from millflow.fitting.spec import FORWARD_TOL, ModelSpec, canonical_location
from millflow.fitting.translate import Translator
from millflow.grid import SizeGrid
from millflow.mill.samples import SampledMill
from millflow.mill.transport import (cell_count, is_axial,
                                     is_cells, mode_transport)
from millflow.psd import from_sieves

__all__ = ["ForwardModel", "auto_grid"]


def auto_grid(data: PSDData, ratio: float = 2 ** 0.25, conditions=None) -> SizeGrid:
    """A geometric grid spanning the data's sieve sizes.

    Geometric grid from the coarsest feed or sample size down to half the finest positive
    sieve (the finest edge then at or below it).

    Its top is the coarsest measured size itself, so that a geometric sieve series whose
    ratio is a whole power of ``ratio`` (2^(1/2) sieves on the default 2^(1/4) grid) falls
    on grid edges, where the model's passing is exact (:mod:`millflow.fitting.sieves`).
    """
    t = data.table
    sizes = t.size_m.to_numpy()
    pos = sizes[sizes > 0]
    if pos.size == 0:
        raise InputError(f"{data.source}: no positive sieve sizes")
    return SizeGrid.between(float(pos.max()), float(pos.min()) / 2.0, ratio)


class ForwardModel:
    """A :class:`ModelSpec` compiled on a grid for a set of conditions of a data set.

    ``predict(theta)`` takes the full parameter vector(s) in ``spec.param_names`` order,
    shape (n_params,) or (P, n_params), and returns the predicted measured values,
    shape (n_data,) or (P, n_data), in the order of ``self.y``.
    """

    def __init__(self, spec: ModelSpec, data: PSDData, grid: SizeGrid | None = None, conditions=None, *,
                 tracer=None, kind_weights: dict | None = None):
        self.spec, self.data = spec, data
        self.tracer, self.kind_weights = tracer, dict(kind_weights or {})
        self.grid = grid if grid is not None else auto_grid(data)
        self.conditions = list(conditions) if conditions is not None else data.conditions
        unknown = [c for c in self.conditions if c not in data.conditions]
        if unknown:
            raise InputError(f"{data.source}: conditions {unknown} have no measurements")
        x = self.grid.x
        self.x, self.n = x, x.size
        self._feeds = np.array([self._feed(c) for c in self.conditions])  # (C, N)
        self._proc = self._process_matrix()
        screen_ref = None
        if spec.classification in ("screen_power", "screen_power_cut"):
            col = spec.screen_column
            screen_ref = float(np.exp(np.log(data.process[col].to_numpy(float)).mean())) * self._factor[col]
        #: the one decoder of this model's parameter vectors (S, b, d*, transport values)
        self.translator = Translator.from_spec(spec, self._ref, screen_ref)
        samples = data.samples(self.conditions)
        self._build_groups(samples)
        self._build_tracer()
        # eq. 6 on a geometric grid (fixed ratio to rounding): eq. 3 by O(N) recurrences
        log_ratio = np.log(x[:-1] / x[1:])
        geometric = x.size > 1 and float(np.ptp(log_ratio)) <= 1e-12 * float(log_ratio.mean())
        self._ratio = (float(np.exp(log_ratio.mean())) if geometric and spec.breakage != "fixed"
                       and not spec.kinetics else None)
        self._nonlinear = None
        #: relative noise of the predictions, for the finite-difference step of the
        #: Jacobian (machine epsilon for the exact linear solves; the ODE tolerance for
        #: non-linear kinetics: see millflow.fitting.kinetics)
        self.fd_noise = float(np.finfo(float).eps)
        if spec.kinetics:
            from millflow.fitting.kinetics import AGE_TOL, ODE_RTOL, CompiledKinetics
            t_max = max([g[2] for g in self.groups] + [0.0])
            # continuous: t_ref defaults to the longest tau of all the data's conditions (not
            # only these: a subset, e.g. a validation fold, keeps the meaning of s_slow)
            tau_max = None
            if spec.mode != "batch":
                tau_max = (float(data.process[spec.tau_column].to_numpy(float).max()) * self._factor[spec.tau_column]
                           if spec.tau_column else 1.0)
            self._nonlinear = CompiledKinetics.build(spec.kinetics, dict(spec.kinetics_params), self.grid, data, t_max,
                                                     tau_max)
            if any(f != "slowing_down" for f in spec.kinetics):
                self.fd_noise = ODE_RTOL
            elif spec.mode != "batch":  # the exit-age quadrature (millflow.mill.nonlinear.age_slowing)
                self.fd_noise = AGE_TOL
            if "slowing_down" in spec.kinetics and spec.mode != "batch":
                bad = sorted({g[1] for g in self.groups if g[1] not in ("product", "holdup")})
                if bad:
                    raise InputError(f"{data.source}: locations {bad}: a continuous mill with kinetics "
                                     "'slowing_down' (kappa(t) in the particle's age) is fitted to 'product' and "
                                     "'holdup' samples (segregated flow over the exit ages has no cell or axial "
                                     "contents)")
            elif spec.mode != "batch":
                cells_ok = is_cells(self.mill_door().transport)
                bad = sorted({g[1] for g in self.groups if g[1] != "product" and not (
                    cells_ok and (g[1] == "holdup" or g[1].startswith("cell:")))})
                if bad:
                    raise InputError(f"{data.source}: locations {bad}: a mill with non-linear kinetics is fitted to "
                                     "product samples, and with well-mixed cells to holdup and cell:K samples")

    def solver_accuracy(self) -> tuple[float, str]:
        """Relative error bound of the predicted values from the forward solves, and how.

        (relative error bound of the predicted values, how): what the forward solves add
        to the predictions, beside the grid (:meth:`grid_order`).
        """
        if self._nonlinear is not None and self.fd_noise > float(np.finfo(float).eps):
            if self.spec.kinetics == ("slowing_down",):
                return self.fd_noise, ("slowing-down in the particle's age: exit-age quadrature at its tolerance "
                                       "(millflow.mill.nonlinear.age_slowing)")
            return self.fd_noise, "non-linear kinetics: stiff ODE / Newton solves at their relative tolerance"
        door = self.mill_door()
        if door is not None and door.route(self.groups) == "members":
            return FORWARD_TOL, "mill solves refined to FORWARD_TOL of the feed (millflow.mill)"
        return float(np.finfo(float).eps) * self.n, ("exact linear solves (triangular substitution or the "
                                                     "eigenbasis of eq. 4): rounding, ~N eps")

    def grid_order(self) -> tuple[int | None, str]:
        """Order of the size discretisation in the class width, and how.

        (order p of the size discretisation in the class width, how); None for a b matrix
        given on this grid (the discrete model itself: no grid error of its own).
        """
        if self.spec.breakage == "fixed":
            return None, "b given on the numerical grid: the discrete model itself, no grid error of its own"
        if self.grid.scheme == "upper_edge":
            return 1, "continuous forms at the upper class edges (Austin): first order"
        return 2, "continuous forms averaged over each class (millflow.breakage.averaged): second order"

    # ----------------------------------------------------------------- compilation
    def _build_tracer(self):
        """Tracer rows (mode "mill"): measured F(t) joined to the PSD rows.

        Tracer rows (mode "mill"): measured F(t), the fraction of a pulse that has
        left by time t (or a step response), columns ``condition``, ``time_s``, ``F``.
        They join the PSD rows in one objective; ``kind_weights`` (data kind -> weight,
        default 1: F and cumulative passing are both fractions of order one with
        comparable measurement noise) scales each kind's rows. Kinds: the PSD location
        kinds ``product``, ``holdup``, ``cell``, ``z`` (and ``mill`` for batch) and
        ``tracer``.
        """
        kinds = np.array([self._kind(self.groups[g][1]) for g in range(len(self.groups))
                          for _ in range(self.group_slices[g + 1] - self.group_slices[g])], dtype=object)
        unknown = set(self.kind_weights) - set(kinds) - {"tracer"}
        if unknown:
            raise InputError(f"kind_weights: {sorted(unknown)} are not data kinds of this fit; "
                             f"expected some of {sorted(set(kinds) | {'tracer'})}")
        self._tracer = []
        y_t, w_t = [], []
        if self.tracer is not None:
            if self.spec.mode != "mill":
                raise InputError("tracer data need mode = 'mill' (the transport model predicts them)")
            t = self.tracer
            missing = [c for c in ("condition", "time_s", "F") if c not in t.columns]
            if missing:
                raise InputError(f"tracer table: columns {missing} missing; expected condition, time_s, F")
            for cond, grp in t.groupby("condition", sort=False):
                if cond not in self.conditions:
                    continue  # a condition left out (validation folds)
                times = grp.time_s.to_numpy(float)
                F = grp.F.to_numpy(float)
                if not (np.isfinite(times).all() and (times >= 0).all() and np.isfinite(F).all()):
                    raise InputError(f"tracer table, condition {cond!r}: time_s must be finite >= 0 and F finite")
                self._tracer.append((self.conditions.index(cond), times))
                y_t.append(F)
                w_t.append(np.full(F.size, 1.0))
        w = np.array([self.kind_weights.get(k, 1.0) for k in kinds], dtype=float)
        self.y_psd = self.y
        self.weights = np.concatenate([self.weights * w] + [v * self.kind_weights.get("tracer", 1.0) for v in w_t])
        self.y = np.concatenate([self.y] + y_t)
        self.data_kind = np.concatenate([kinds, np.full(sum(v.size for v in y_t), "tracer", dtype=object)])

    @staticmethod
    def _kind(loc: str) -> str:
        return loc.split(":")[0] if ":" in loc else loc

    def transport_values(self, p):
        """Tau [s] per member and condition and the fitted transport parameters.

        Per member and condition: tau [s] (P, C) and the fitted transport parameters
        (name -> (P,)) of mode "mill" (:meth:`Translator.transport_values`).
        """
        col = self._proc[self.spec.tau_column] if self.spec.tau_column else None
        return self.translator.transport_values(p, col, len(self.conditions))

    def _transport(self, tau, extra, k):
        return self.spec.make_transport(float(tau), **{n: float(v[k]) for n, v in extra.items()})
    def _feed(self, cond):
        size, P = self.data.feed(cond)
        keep = size > 0
        size, P = size[keep], P[keep]
        if size[0] > self.grid.x[0] * (1 + 1e-9):
            raise InputError(f"feed of {cond!r}: top size {size[0]:.4g} m is above the grid top {self.grid.x[0]:.4g} m")
        if P[0] < 1 - 1e-9:  # mass above the top sieve has no size: never lumped into class 1 silently
            raise InputError(f"feed of {cond!r}: the top sieve ({size[0] * 1e3:.4g} mm) passes only "
                             f"{100 * P[0]:.4g} %, so {100 * (1 - P[0]):.3g} % of the feed has no measured size; "
                             "add a feed row at a size that passes 100 % (and a [grid] top_mm at least that size)")
        return from_sieves(size, P, self.grid)

    def _process_matrix(self):
        spec, proc = self.spec, self.data.process
        cols = list(spec.rate_process) + [col for _, col in spec.param_process]
        if spec.classification in ("screen", "screen_power", "screen_power_cut"):
            cols.append(spec.screen_column)
        if spec.rate == "austin_ball":
            cols.append(spec.ball_column)
        if spec.tau_column:
            cols.append(spec.tau_column)
        # columns read as a physical quantity take their unit from their name (tau_min is
        # minutes, screen_um micrometres); the model works in s (tau) and mm (screen, ball)
        self._factor = {}
        if spec.classification in ("screen", "screen_power", "screen_power_cut"):
            self._factor[spec.screen_column] = _column_factor(spec.screen_column, "screen_column", "length", 1e-3)
        if spec.rate == "austin_ball":
            self._factor[spec.ball_column] = _column_factor(spec.ball_column, "ball_column", "length", 1e-3)
        if spec.tau_column:
            self._factor[spec.tau_column] = _column_factor(spec.tau_column, "tau_column", "time", 1.0)
        out = {}
        for col in dict.fromkeys(cols):
            if col not in proc.columns:
                raise InputError(f"{self.data.source}: process table has no column {col!r} (needed by the model); "
                                 f"columns are {list(proc.columns)}")
            v = proc.loc[self.conditions, col].to_numpy(dtype=float)
            if np.any(v <= 0):
                raise InputError(f"process column {col!r}: values must be > 0 for power laws, got {v.min()!r}")
            out[col] = v * self._factor.get(col, 1.0)
        # references: geometric mean over all conditions of the data (not just these)
        self._ref = {c: float(np.exp(np.log(proc[c].to_numpy(dtype=float)).mean())) * self._factor.get(c, 1.0)
                     for c in list(spec.rate_process) + [col for _, col in spec.param_process]
                     + ([spec.ball_column] if spec.rate == "austin_ball" else [])}
        return out

    def _build_groups(self, samples):
        groups, ys, ws, sizes, conds = [], [], [], [], []
        cond_index = {c: k for k, c in enumerate(self.conditions)}
        for (cond, loc, t), grp in samples.groupby(["condition", "location", "time_s"], sort=False):
            loc = canonical_location(loc)
            if self.spec.mode != "batch":
                self._check_mill_location(loc, cond)
            groups.append((cond_index[cond], loc, float(t)))
            ys.append(grp.passing.to_numpy())
            ws.append(grp.weight.to_numpy())
            sizes.append(grp.size_m.to_numpy())
            conds.append(np.full(len(grp), cond))
        self.groups = groups
        self.sizes = sizes
        self.group_slices = np.cumsum([0] + [len(y) for y in ys])
        self.condition_of_value = np.concatenate(conds)
        y_cum = np.concatenate(ys)
        self.y_cum = y_cum
        # the grid's cumulative passing read at every measured size (exact on edges)
        G = len(groups)
        self._reduction = SieveReduction(self.x, sizes)
        if self.spec.objective == "fractional":
            D = np.zeros((y_cum.size, y_cum.size))
            for g in range(G):
                a, b = self.group_slices[g], self.group_slices[g + 1]
                for k in range(a, b):
                    D[k, k] = -1.0
                    if k > a:
                        D[k, k - 1] = 1.0
            self._D = D
            # value of a sample's first row: 1 - P(top sieve) (retained on it)
            self.y = self._apply_D(y_cum[None])[0]
        else:
            self._D = None
            self.y = y_cum
        self.weights = np.concatenate(ws)
        self.times = np.array(sorted({t for _, _, t in groups}))

    def sample_ids(self) -> np.ndarray:
        """For each measured value, the sample (sieve curve or tracer curve) it belongs to.

        For each measured value (in the order of ``y``), the sample it belongs to: one sieve
        curve (condition, location, time) or one tracer curve. Residuals are correlated
        within a sample, not between samples (the clusters of the robust covariance).
        """
        ids = np.repeat(np.arange(len(self.groups)), np.diff(self.group_slices))
        blocks = [ids]
        for k, (_, times) in enumerate(getattr(self, "_tracer", [])):
            blocks.append(np.full(len(times), len(self.groups) + k))
        out = np.concatenate(blocks)
        if out.size != self.n_data:  # every value belongs to one sample
            raise AssertionError(f"sample ids {out.size} != n_data {self.n_data}")
        return out

    def _check_mill_location(self, loc, cond):
        door = self.mill_door()
        if loc in ("product", "holdup"):
            return
        cells = cell_count(door.transport, door.params)
        axial = is_axial(door.transport, open_vessel=False)
        ok = "'product', 'holdup'" + (f" or 'cell:K' (K = 1..{int(cells)})" if is_cells(door.transport)
                                      else "") + (" or 'z:Y' (0 <= Y <= 1)" if axial else "")
        good = False
        if loc.startswith("cell:") and is_cells(door.transport):
            k = loc[5:]
            good = k.isdigit() and 1 <= int(k) <= int(cells)
        elif loc.startswith("z:") and axial:
            try:
                good = 0.0 <= float(loc[2:]) <= 1.0
            except ValueError:
                good = False
        if not good:
            raise InputError(f"location {loc!r} of condition {cond!r}: a mill with transport {door.transport!r} "
                             f"predicts {ok}")

    def _apply_D(self, Y):
        out = Y @ self._D.T
        starts = self.group_slices[:-1]
        out[:, starts] += 1.0
        return out

    def _measured_sizes(self) -> list:
        """The finest and coarsest measured sieve size [m].

        [finest, coarsest] sieve size of the measured samples (not the feed) [m]: the
        size range a prediction with this model is calibrated on.
        """
        t = self.data.table
        sizes = t.loc[t.location != "feed", "size_m"].to_numpy(float)
        sizes = sizes[sizes > 0]
        return [float(sizes.min()), float(sizes.max())] if sizes.size else []

    def _grinding_times(self) -> list:
        """The shortest and longest grinding time of the fitted data [s].

        [shortest, longest] grinding time of the fitted data [s]: the batch sample times
        (> 0), or the conditions' mean residence times of a continuous mill (tau column);
        [] when unknown (tau = 1 without a column). With the lab mill's power per hold-up it
        gives the specific-energy range the fit is calibrated on (scale-up warns outside it).
        """
        if self.spec.mode == "batch":
            t = [g[2] for g in self.groups if g[2] > 0]
        elif self.spec.tau_column:
            t = [float(v) for v in self._proc[self.spec.tau_column]]
        else:
            t = []
        return [float(min(t)), float(max(t))] if t else []

    def describe(self) -> dict:
        """The spec, grid and eq. 10 reference values as plain JSON-able data.

        The spec, grid and eq. 10 reference values as plain JSON-able data (for the fit
        JSON: what another program needs to evaluate S and B of this model elsewhere).
        """
        s = self.spec
        proc = self.data.process
        return {"mode": s.mode, "rate": s.rate, "breakage": s.breakage, "classification": s.classification,
                "rate_process": list(s.rate_process), "param_process": [list(p) for p in s.param_process],
                "tau_column": s.tau_column, "ball_column": s.ball_column if s.rate == "austin_ball" else None,
                "x0_m": s.x0_m, "n_tanks": s.n_tanks, "transport": s.transport,
                "transport_params": dict(s.transport_params), "transport_fit": list(s.transport_fit),
                "param_names": list(s.param_names),
                "grid_upper_m": [float(v) for v in self.x], "process_ref": dict(self._ref),
                "measured_size_range_m": self._measured_sizes(),
                "grinding_time_range_s": self._grinding_times(),
                "process": {str(c): {str(k): float(v) for k, v in proc.loc[c].items()
                                     if isinstance(v, (int, float, np.floating, np.integer))}
                            for c in self.conditions if c in proc.index}}

    # ------------------------------------------------------------------- evaluation
    @property
    def param_names(self):
        """Names of the parameters, in the order of the vector theta."""
        return self.spec.param_names

    @property
    def n_data(self) -> int:
        """Number of measured values fitted."""
        return int(self.y.size)

    def _unpack(self, theta):
        return self.translator.unpack(theta)

    def cond_param(self, p, name):
        """Parameter ``name`` per condition (P, C): value * prod (p_k/p_ref_k)^e_k (eq. 10)."""
        return self.translator.condition_values(p, name, self._proc, len(self.conditions))

    def breakage(self, p):
        """S and b of the members on this model's grid (eqs. 5-8 with eq. 10).

        (S (P, C, N) [1/s] (or tau*S if no tau column), b (P, N, N) or (P, C, N, N) [-]) of the
        members on this model's grid: class averages of eqs. 5-8 with eq. 10 (the grid's
        ``scheme`` "upper_edge": Austin's edge values), by :class:`Translator`.
        """
        S, b = self.translator.breakage_on_grid(p, self._proc, len(self.conditions), self.grid)
        return S, (b[:, 0] if b.shape[1] == 1 else b)

    def rates(self, p):
        """S (P, C, N) [1/s]: the leaving rates of :meth:`breakage`."""
        return self.breakage(p)[0]

    def frac_b(self, p, n_pop=None):
        """Fractional b (P, N, N), or (P, C, N, N) when it depends on the condition: that of :meth:`breakage`."""
        return self.breakage(p)[1]

    def discharge(self, p, n_pop=None):
        """Normalised discharge d* (P, C, N) of the classification.

        Normalised discharge d* (P, C, N), ones without classification (class averages of the
        curves of :mod:`millflow.classifiers`, by :meth:`Translator.discharge`).
        """
        return self.translator.discharge(p, self._proc, len(self.conditions), self.grid)

    def predict_grid(self, theta):
        """Mass fractions (P, G, N) on the grid for every sample group."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        n_pop = theta.shape[0]
        p = self._unpack(theta)
        mode = self.spec.mode
        door = self.mill_door()
        geometric = self._ratio is not None and door is not None and door.chain_cells is not None
        sep = None
        if geometric:  # eqs. 6/8 on a geometric grid: eq. 3 by the O(N) recurrences, no b formed
            S, *sep = self.translator.separable_on_grid(p, self._proc, len(self.conditions), self.grid, self._ratio)
            b = None
        else:
            S, b = self.breakage(p)
        tau = self._proc[self.spec.tau_column] if self.spec.tau_column else np.ones(len(self.conditions))
        out = np.empty((n_pop, len(self.groups), self.n))
        if self._nonlinear is not None:
            self._predict_nonlinear(S, b, p, tau, out)
        elif door is None:  # batch: eq. 4 by the core's population solve, exact also for nearly equal rates
            for c in range(len(self.conditions)):
                gsel = [g for g, grp in enumerate(self.groups) if grp[0] == c]
                t = np.array([self.groups[g][2] for g in gsel])
                out[:, gsel] = batch_grind_population(S[:, c], b[:, c] if b.ndim == 4 else b, self._feeds[c], t)
        else:  # a continuous mill: its transport resolved once, every member and condition by its route
            d = self.discharge(p, n_pop) if self.spec.classification else None
            if mode == "mill":
                tau_pc, extra = self.transport_values(p)
                door = self.mill_door(extra)
            else:
                tau_pc = np.broadcast_to(np.asarray(tau, float), (n_pop, len(self.conditions)))
            door.samples(S, b, self._feeds, tau_pc, d, self.groups, out, sep)
        return out

    def _predict_nonlinear(self, S, b, p, tau, out):
        """Predictions with non-linear kinetics, member by member and condition by condition.

        Non-linear kinetics (:mod:`millflow.fitting.kinetics`), member by member and
        condition by condition: batch (eq. 4 + R(M)), plug flow, well-mixed tanks
        (n_tanks), or mode "mill" with a transport of :data:`_NONLINEAR_TRANSPORTS`.
        """
        spec, nl = self.spec, self._nonlinear
        mode = spec.mode
        n_pop = S.shape[0]
        door = None
        if mode == "mill":
            tau_pc, extra = self.transport_values(p)
            door = self.mill_door(extra)
        elif mode != "batch":
            tau_pc, door = np.broadcast_to(np.asarray(tau, float), (n_pop, len(self.conditions))), self.mill_door()
        # classification where the mill places it: mode "mill" at the discharge (the last
        # cell's or the network's exit flows; where = "cells": every cell outlet) or along
        # the axis; mode "well_mixed" in every tank, as the linear forward model places it
        d_all = self.discharge(p, n_pop) if (spec.classification and door is not None) else None
        where = None if door is None else door.classified_at
        age = "slowing_down" in spec.kinetics
        for c in range(len(self.conditions)):
            gsel = [g for g, grp in enumerate(self.groups) if grp[0] == c]
            if door is None:  # batch: the whole population in one stacked solve
                t = np.array([self.groups[g][2] for g in gsel])
                out[:, gsel] = nl.solve_batch_population(S[:, c], b[:, c] if b.ndim == 4 else b,
                                                         self._feeds[c], t, p)
                continue
            locs = [self.groups[g][1] for g in gsel]
            for k in range(n_pop):
                bk = b[k, c] if b.ndim == 4 else b[k]
                if not (np.isfinite(S[k, c]).all() and np.isfinite(bk).all()):
                    out[k, gsel] = np.nan
                    continue
                tc = float(tau_pc[k, c])
                try:  # the transport of member k; outside rtd's domain (e.g. r < 0): this member only
                    route = {"model": door.model(tc, k)} if age else door.nonlinear_route(tc, k)
                except InputError:
                    out[k, gsel] = np.nan
                    continue
                dk = None if d_all is None else d_all[k, c]
                if age:  # kappa(t) in the particle's age: segregated flow over the exit ages of the transport
                    # (with classification, the age-structured cell balance)
                    out[k, gsel] = nl.solve_age(S[k, c], bk, self._feeds[c], route["model"], p, k, d=dk,
                                                where=where, locations=locs)
                    continue
                if dk is not None:
                    route["d"], route["where"] = dk, where
                if any(loc != "product" for loc in locs):
                    route["locations"] = locs  # hold-up and cell samples of well-mixed cells
                out[k, gsel] = nl.solve_steady(S[k, c], bk, self._feeds[c], tc, p, k, **route)

    def mill_door(self, extra: dict | None = None):
        """The mill of a continuous mode, resolved once: a :class:`~millflow.mill.samples.SampledMill`.

        Mode "mill" its transport (``extra``: fitted transport parameters per member, from
        :meth:`transport_values`), modes "plug_flow" and "well_mixed" the transport they name
        (:func:`~millflow.mill.transport.mode_transport`); None for mode "batch".
        """
        spec = self.spec
        if spec.mode == "batch":
            return None
        name, params, where = mode_transport(spec.mode, spec.n_tanks, spec.transport, spec.transport_params, spec.where)
        if spec.mode != "mill":
            return SampledMill(name, params, where, tol=FORWARD_TOL)
        extra = dict(extra or {})
        return SampledMill(name, params, where, lambda tau, k: self._transport(tau, extra, k),
                           fitted=bool(spec.transport_fit), tol=FORWARD_TOL, extra=extra)

    def _cum_at_rows(self, theta):
        """Cumulative passing of the grid solution at every measured row.

        Cumulative passing of the grid solution read at every measured row
        (:class:`~millflow.fitting.sieves.SieveReduction`); (P, rows).
        """
        M = self.predict_grid(theta)
        P = np.cumsum(M[..., ::-1], axis=-1)[..., ::-1]
        return self._reduction.reduce(P)

    def predict(self, theta):
        """Predicted values (n_data,) for theta, or (P, n_data) for P vectors."""
        theta = np.asarray(theta, dtype=float)
        single = theta.ndim == 1
        Y = self._cum_at_rows(theta)
        if self._D is not None:
            Y = self._apply_D(Y)
        if self._tracer:
            Y = np.concatenate([Y, self.predict_tracer(np.atleast_2d(theta))], axis=1)
        return Y[0] if single else Y

    def predict_tracer(self, theta):
        """Predicted tracer F(t) of every tracer row, (P, rows): the transport's cdf."""
        theta = np.atleast_2d(np.asarray(theta, dtype=float))
        p = self._unpack(theta)
        tau, extra = self.transport_values(p)
        out = []
        for c, times in self._tracer:
            rows = np.empty((theta.shape[0], times.size))
            for k in range(theta.shape[0]):
                try:
                    rows[k] = self._transport(tau[k, c], extra, k).cdf(times)
                except InputError:
                    rows[k] = np.nan  # transport parameters outside rtd's domain
            out.append(rows)
        return np.concatenate(out, axis=1) if out else np.empty((theta.shape[0], 0))

    def predict_cum(self, theta):
        """Cumulative passing at every measured row (the README metric's model values)."""
        return self._cum_at_rows(np.atleast_2d(theta))[0]

    def with_grid(self, grid: SizeGrid) -> "ForwardModel":
        """The same model on another size grid (the grid check)."""
        spec = self.spec
        if spec.breakage == "fixed":
            raise InputError("a fixed b matrix belongs to one grid; give it on the refined grid to refine")
        return ForwardModel(spec, self.data, grid, self.conditions, tracer=self.tracer, kind_weights=self.kind_weights)

    def for_conditions(self, conditions) -> "ForwardModel":
        """The same model on a subset of the conditions (validation)."""
        return ForwardModel(self.spec, self.data, self.grid, conditions, tracer=self.tracer,
                            kind_weights=self.kind_weights)

    def __repr__(self):
        return (f"ForwardModel({self.spec.label()}, {len(self.conditions)} conditions, {self.n_data} values, "
                f"grid {self.n} classes)")


def _column_factor(col: str, key: str, dim: str, target: float) -> float:
    """Factor from the unit in a process column's name to the model's unit.

    Factor from the unit in a process column's name (``tau_min``, ``screen_um``) to the
    model's unit ``target`` (in SI: 1 s, 1e-3 m); a name without a known unit is refused.
    """
    from millflow.inputs import UNITS

    suffix = col.rsplit("_", 1)[-1] if "_" in col else ""
    if suffix not in UNITS[dim]:
        raise InputError(f"process column {col!r} ({key}): its unit is not in its name; expected a name ending in "
                         f"_{', _'.join(UNITS[dim])} (e.g. {col.split('_')[0]}_{next(iter(UNITS[dim]))})")
    return UNITS[dim][suffix] / target
