"""A fit's parameter vector translated into S, b, d* and transport values: the one decoder.

A breakage fit estimates a vector of named parameters (:attr:`ModelSpec.param_names
<millflow.fitting.spec.ModelSpec.param_names>`: logs of the positive ones, ``ln_A0``,
``ln_mu``, ``ln_c50``, ...). :class:`Translator` is the only code that reads such a vector:
the fit's forward model (:mod:`millflow.fitting.forward`) and the scale-up of a fit to a
plant (:mod:`millflow.scaleup.fitted`) both call it, at the process values of their own
conditions. What it does, for a population of vectors at once (shape (P, n_params)):

- eq. 10 on the rate prefactor and on any parameter made condition-dependent,
  ln A = ln A0 + sum_k a_k ln(p_k / p_ref,k) (:func:`millflow.breakage.rates.
  ln_process_power_law`, p_ref the geometric mean over the fitted conditions), A =
  exp(min(ln A, 600)) so that nothing overflows, times a scale-up factor if given;
- the continuous rate S(y) of eq. 5 (``power``) or eq. 7 (``austin``: mu0 = exp(ln_mu)
  x0, times a scale-up factor; ``austin_ball`` with its ball-size terms)
  (:mod:`millflow.breakage.rates`) and the breakage distribution B(x; y) of eq. 6
  (``normalized``, ``single`` with phi = 1) or eq. 8 (``non_normalized``, phi0 at the top
  of the grid) (:mod:`millflow.breakage.distributions`);
- those put on a size grid: class averages by default (second order in the class width,
  :func:`millflow.breakage.averaged.averaged_power_population`), Austin's values at the
  upper class edges on a grid with ``scheme = "upper_edge"`` (first order), a given b
  matrix (breakage ``fixed``) as given, with the class-mean rate;
- the discharge d_i* of an internal screen (:mod:`millflow.classifiers`), class averaged;
- tau and the fitted transport parameters of mode "mill" (ln_tau, ln_pe, r).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millflow.breakage.averaged import average_at_nodes, averaged_power_population, averaged_power_terms, node_sizes
from millflow.breakage.distributions import breakage_population, continuous_B
from millflow.breakage.rates import (X0_DEFAULT, austin_rates_population, ln_process_power_law,
                                     power_law_rates_population)
from millflow.classifiers import screen_discharge, screen_power_discharge
from millflow.grid import as_sizes

__all__ = ["Translator", "LN_A_MAX"]

#: ln A is clipped at this value before exp (exp(600) ~ 1e260 1/s: far outside any fit's
#: bounds; it keeps a stray optimiser member finite instead of inf).
LN_A_MAX = 600.0


@dataclass(frozen=True, eq=False)
class Translator:
    """Decoder of a fit's parameter vectors (module docstring).

    Attributes
    ----------
    names : parameter names, in the order of the vector.
    rate, breakage, classification : form names of :mod:`millflow.fitting.spec`.
    rate_process : process columns of eq. 10 on A (exponents ``a_<column>``).
    param_process : (parameter, column) pairs of eq. 10 on other parameters.
    x0_m : reference size of eqs. 5/7 [m].
    reference : column -> eq. 10 reference value (the model's units: mm for sizes).
    ball_column, screen_column : process columns of the ball size and the screen opening [mm].
    screen_reference_mm : geometric-mean screen opening of ``screen_power`` [mm].
    b_matrix : (N, N) fractional b of breakage ``fixed`` (on the fit's grid).
    transport_fit : fitted transport parameters of mode "mill" ("tau", "pe", "r").
    """

    names: tuple
    rate: str = "power"
    breakage: str = "normalized"
    classification: str | None = None
    rate_process: tuple = ()
    param_process: tuple = ()
    x0_m: float = X0_DEFAULT
    reference: dict = field(default_factory=dict)
    ball_column: str | None = None
    screen_column: str | None = None
    screen_reference_mm: float | None = None
    b_matrix: np.ndarray | None = field(default=None, repr=False)
    transport_fit: tuple = ()

    @classmethod
    def from_spec(cls, spec, reference: dict, screen_reference_mm: float | None = None) -> "Translator":
        """The translator of a :class:`~millflow.fitting.spec.ModelSpec` with its eq. 10 references."""
        return cls(tuple(spec.param_names), spec.rate, spec.breakage, spec.classification,
                   tuple(spec.rate_process), tuple(tuple(p) for p in spec.param_process), float(spec.x0_m),
                   dict(reference), spec.ball_column if spec.rate == "austin_ball" else None,
                   spec.screen_column if spec.classification else None, screen_reference_mm,
                   spec.b_matrix, tuple(spec.transport_fit))

    @classmethod
    def from_description(cls, d: dict) -> "Translator":
        """The translator of a fit result's ``model_spec`` (what ``millflow fit --json`` writes)."""
        return cls(tuple(d["param_names"]), d.get("rate", "power"), d.get("breakage", "normalized"),
                   d.get("classification"), tuple(d.get("rate_process", ())),
                   tuple(tuple(p) for p in d.get("param_process", ())), float(d.get("x0_m", X0_DEFAULT)),
                   {str(k): float(v) for k, v in (d.get("process_ref") or {}).items()}, d.get("ball_column"),
                   None, None, None, tuple(d.get("transport_fit", ())))

    # ------------------------------------------------------------------ decoding
    def unpack(self, theta) -> dict:
        """Name -> (P,) values of parameter vector(s) theta, (n_params,) or (P, n_params)."""
        t = np.atleast_2d(np.asarray(theta, dtype=float))
        if t.shape[-1] != len(self.names):
            raise ValueError(f"parameter vectors of length {t.shape[-1]}; expected {len(self.names)} "
                             f"({', '.join(self.names)})")
        return {name: t[:, k] for k, name in enumerate(self.names)}

    def physical(self, theta) -> np.ndarray:
        """Mask (P,) of parameter vectors inside the physical domain of the forms.

        Mask (P,) of parameter vectors inside the physical domain of the rate and breakage
        forms: gamma > 0; eq. 6: 0 <= phi <= 1, beta > 0; eq. 7: Lambda > 0.
        """
        p = self.unpack(theta)
        ok = p["gamma"] > 0 if "gamma" in p else np.ones(next(iter(p.values())).shape, bool)
        if self.breakage in ("normalized", "non_normalized"):
            ok &= (p["phi"] >= 0) & (p["phi"] <= 1) & (p["beta"] > 0)
        if self.rate in ("austin", "austin_ball"):
            ok &= p["Lambda"] > 0
        return ok

    def depends(self, name: str) -> bool:
        """True when eq. 10 makes parameter ``name`` condition-dependent."""
        return any(par == name for par, _ in self.param_process)

    def condition_values(self, p: dict, name: str, process: dict, n: int) -> np.ndarray:
        """Parameter ``name`` per member and condition (P, n): value * prod (p_k/p_ref,k)^e_k (eq. 10)."""
        v = np.repeat(p[name][:, None], n, axis=1)
        for par, col in self.param_process:
            if par == name:
                v = v * np.exp(ln_process_power_law(0.0, {col: process[col]}, {col: p[f"{name}_{col}"][:, None]},
                                                    {col: self.reference[col]}))
        return v

    def ln_A(self, p: dict, process: dict, n: int, A_factor: float = 1.0) -> np.ndarray:
        """The ln A per member and condition (P, n) by eq. 10, plus ln of a scale-up factor."""
        cols = self.rate_process
        ln0 = p["ln_A0"][:, None] + math.log(A_factor)
        lnA = ln_process_power_law(ln0, {c: process[c] for c in cols},
                                   {c: self.condition_values(p, f"a_{c}", process, n) for c in cols},
                                   {c: self.reference[c] for c in cols})
        return np.broadcast_to(lnA, (ln0.shape[0], n))

    def rate_at(self, p: dict, process: dict, n: int, y, A_factor: float = 1.0, mu_factor: float = 1.0):
        """The continuous rate S(y) [1/s] of eq. 5 or 7 at sizes y [m] (no sink): (P, n, len(y))."""
        y = np.asarray(y, dtype=float)
        yy = np.append(y, y[-1] * 0.5)  # the population forms zero their last size (a sink): a dummy one
        A = np.exp(np.minimum(self.ln_A(p, process, n, A_factor), LN_A_MAX))
        alpha = self.condition_values(p, "alpha", process, n)
        x0 = self.x0_m
        if self.rate in ("austin", "austin_ball"):
            mu0 = (np.exp(p["ln_mu"]) * x0 * mu_factor)[:, None]
            if self.rate == "austin":
                S = austin_rates_population(yy, A, alpha, mu0, p["Lambda"][:, None], x0=x0)
            else:  # x_b per condition [mm -> m], x_b0 its geometric mean
                col = self.ball_column
                S = austin_rates_population(yy, A, alpha, mu0, p["Lambda"][:, None], p["xi"][:, None],
                                            np.asarray(process[col], float) * 1e-3, self.reference[col] * 1e-3,
                                            p["eta"][:, None], x0=x0)
        else:
            S = power_law_rates_population(yy, A, alpha, x0)
        return S[..., :-1]

    def distribution(self, p: dict, process: dict, n: int):
        """(phi0, gamma, beta, theta) of eq. 6/8, each broadcasting to (P, n) (gamma may be per condition)."""
        gamma = self.condition_values(p, "gamma", process, n) if self.depends("gamma") else p["gamma"][:, None]
        if self.breakage == "single":  # B = r^gamma: eq. 6 with phi = 1
            return np.ones_like(gamma), gamma, gamma, np.zeros_like(gamma)
        theta = p["theta"][:, None] if self.breakage == "non_normalized" else np.zeros_like(p["phi"][:, None])
        return p["phi"][:, None], gamma, p["beta"][:, None], theta

    def condition_free_breakage(self) -> bool:
        """True when b is the same for every condition (only A varies by condition: it cancels in b)."""
        return not (self.depends("gamma") or self.depends("alpha") or self.rate == "austin_ball")

    # ------------------------------------------------------------- on a grid
    def breakage_on_grid(self, p: dict, process: dict, n: int, grid, A_factor: float = 1.0,
                         mu_factor: float = 1.0):
        """(S (P, n, N) [1/s], b (P, n or 1, N, N) [-]) on ``grid`` (see the module docstring).

        ``grid`` a :class:`~millflow.grid.SizeGrid` (its ``scheme`` chooses class averages
        or upper edges) or upper edges [m] (class averages).
        """
        x = as_sizes(grid)
        scheme = getattr(grid, "scheme", "class_average")
        P = p[self.names[0]].shape[0]
        N = x.size
        if self.breakage == "fixed":
            b = np.broadcast_to(np.asarray(self.b_matrix, float), (P, 1, N, N))
            if scheme == "upper_edge":
                return self._edge_rates(p, process, n, x, A_factor, mu_factor), b
            S = average_at_nodes(self.rate_at(p, process, n, node_sizes(x), A_factor, mu_factor))
            S[..., -1] = 0.0
            return S, b
        phi0, gamma, beta, theta = self.distribution(p, process, n)
        if scheme == "upper_edge":
            return self._edge_rates(p, process, n, x, A_factor, mu_factor), self.edge_b(p, process, n, x)
        free = self.condition_free_breakage()
        S_nodes = self.rate_at(p, process, n, node_sizes(x), A_factor, mu_factor)
        if free and n > 1:  # b of the first condition serves all (A cancels in b); S per condition, O(N)
            _, b = averaged_power_population(x, S_nodes[:, :1], phi0, gamma, beta, theta)
            S, _, _ = averaged_power_terms(x, S_nodes, phi0, gamma, beta, theta)
            return S, b
        return averaged_power_population(x, S_nodes, phi0, gamma, beta, theta)

    def separable_on_grid(self, p: dict, process: dict, n: int, grid, ratio: float, A_factor: float = 1.0,
                          mu_factor: float = 1.0):
        """The separable form of S and b on a geometric grid.

        (S, w1, c1, w2, c2) for :func:`millflow.mill.well_mixed.well_mixed_population_separable`
        on a geometric grid of ``ratio`` (eqs. 6/8; not for breakage ``fixed``).
        """
        x = as_sizes(grid)
        phi0, gamma, beta, theta = self.distribution(p, process, n)
        c1, c2 = np.exp(-gamma * math.log(ratio)), np.exp(-beta * math.log(ratio))
        if getattr(grid, "scheme", "class_average") == "upper_edge":
            S = self._edge_rates(p, process, n, x, A_factor, mu_factor)
            phi_j = phi0[..., None] * (x[0] / x) ** theta[..., None]
            return S, phi_j * S, c1, (1.0 - phi_j) * S, c2
        S_nodes = self.rate_at(p, process, n, node_sizes(x), A_factor, mu_factor)
        S, a1, a2 = averaged_power_terms(x, S_nodes, phi0, gamma, beta, theta)
        return S, c1[..., None] * a1, c1, c2[..., None] * a2, c2

    def edge_b(self, p: dict, process: dict, n: int, x) -> np.ndarray:
        """Austin's discrete b (P, n or 1, N, N) of eqs. 6/8 at the upper edges x [m]."""
        phi0, gamma, beta, theta = self.distribution(p, process, n)
        if gamma.shape[-1] == 1:
            return breakage_population(x, phi0[:, 0], gamma[:, 0], beta[:, 0], theta[:, 0], kind="b")[:, None]
        return breakage_population(x, phi0, gamma, beta, theta, kind="b")

    def _edge_rates(self, p, process, n, x, A_factor, mu_factor):
        S = self.rate_at(p, process, n, x, A_factor, mu_factor)
        S[..., -1] = 0.0  # the sink does not break
        return S

    def cumulative(self, theta, x, y, top: float | None = None) -> np.ndarray:
        """The continuous B(x; y) [-] of one parameter vector (eq. 6/8), sizes broadcasting [m]."""
        p = self.unpack(theta)
        phi0, gamma, beta, th = (float(np.asarray(v).ravel()[0]) for v in self.distribution(p, {}, 1))
        return continuous_B(x, y, phi0, gamma, beta, th, top)

    def discharge(self, p: dict, process: dict, n: int, grid) -> np.ndarray:
        """Normalised discharge d* (P, n, N) of the classification.

        Normalised discharge d* (P, n, N) of the classification (ones without), class averaged
        (at the upper edges on an "upper_edge" grid).
        """
        x = as_sizes(grid)
        P = p[self.names[0]].shape[0]
        if self.classification is None:
            return np.ones((P, n, x.size))
        averaged = getattr(grid, "scheme", "class_average") == "class_average" and x.size > 1
        sizes = node_sizes(x) if averaged else x
        screen = np.asarray(process[self.screen_column], float) * 1e-3
        if self.classification in ("screen_power", "screen_power_cut"):
            # normalised so that d* = 1 at x = x0 for the geometric-mean screen: ln_A0 is
            # then the rate at x0 for a typical screen, which decorrelates it from n_screen
            ref = self.screen_reference_mm * 1e-3
            n_screen = self.condition_values(p, "n_screen", process, n)
            d = screen_power_discharge(sizes, n_screen, self.x0_m * screen / ref)
        else:
            d50 = np.exp(p["ln_c50"])[:, None] * screen[None, :]
            d = screen_discharge(sizes, d50, np.exp(p["ln_sharp"])[:, None])
        if averaged:
            d = average_at_nodes(d)
        if self.classification == "screen_power_cut":
            # hard cut: a class whose lower edge is at or above the opening cannot pass
            # (d* = 1e-12: it leaves only as breakage products, as in the flowsheet mill)
            lower = np.r_[x[1:], 0.0]
            d = np.where((lower[None, :] >= screen[:, None])[None], 1e-12, d)
        return d

    def transport_values(self, p: dict, tau_column, n: int):
        """Tau [s] per member and condition and the fitted transport parameters of mode "mill".

        tau [s] per member and condition (P, n) and the fitted transport parameters
        (name -> (P,)) of mode "mill": ``tau_column`` the conditions' tau [s] (or None: 1).
        """
        col = np.asarray(tau_column, float) if tau_column is not None else np.ones(n)
        P = p[self.names[0]].shape[0]
        if "tau" in self.transport_fit:
            scale = col / float(np.exp(np.log(col).mean())) if tau_column is not None else col
            tau = np.exp(p["ln_tau"])[:, None] * scale[None, :]
        else:
            tau = np.broadcast_to(col, (P, col.size))
        extra = {}
        if "pe" in self.transport_fit:
            extra["pe"] = np.exp(p["ln_pe"])
        if "r" in self.transport_fit:
            extra["r"] = p["r"]
        return tau, extra

