"""What a fit fits: the model description, its parameters, bounds and defaults.

A :class:`ModelSpec` says *what* is fitted (rate form, breakage form, transport,
classification, which process parameters enter the eq. 10 power law);
:func:`default_parameters` gives each of its parameters a starting value and bounds
(:class:`Parameter`, lmfit-style). The forms and their parameters are listed in
:mod:`millflow.fitting.forward`; the translation of a parameter vector into S, b and d*
is :mod:`millflow.fitting.translate`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from millflow.breakage.rates import X0_DEFAULT
from millflow.errors import InputError
from millflow.mill.transport import TRANSPORT_FIT as _TRANSPORT_FIT
from millflow.mill.transport import classification_places, is_cells, is_tanks

__all__ = ["Parameter", "ModelSpec", "RATE_FORMS", "BREAKAGE_FORMS", "MODES", "canonical_location",
           "CLASSIFICATIONS", "TRANSPORTS", "TRANSPORT_FIT", "FORWARD_TOL", "default_parameters"]


RATE_FORMS = {"power": ("ln_A0", "alpha"), "austin": ("ln_A0", "alpha", "ln_mu", "Lambda"),
              "austin_ball": ("ln_A0", "alpha", "ln_mu", "Lambda", "xi", "eta")}
BREAKAGE_FORMS = {"normalized": ("phi", "gamma", "beta"), "single": ("gamma",), "fixed": (),
                  "non_normalized": ("phi", "gamma", "beta", "theta")}
MODES = ("batch", "plug_flow", "well_mixed", "mill")
#: Transport models of mode "mill": name -> (rtd class name, required, optional parameters).
#: Error target of the mill solves inside the fit (relative to the feed): the discretised
#: paths refine to it (an axial mill at Pe ~ 1e3 reaches ~2e-6 at 16384 volumes);
#: cumulative-passing data resolve ~1e-4 at best, ten times coarser.
FORWARD_TOL = 1e-5

def _transports() -> dict:
    """Transport name -> (rtd class name, required, optional), from :mod:`rtd.names`.

    name -> (rtd class name, required, optional): a view of rtd's one table
    (:mod:`rtd.names`); a fixed keyword such as the axial vessel's ``bc`` may be overridden.
    """
    from rtd import names

    return {name: (e.cls.__name__, e.required, e.optional + tuple(k for k, _ in e.fixed))
            for name, e in names.TRANSPORTS.items()}


TRANSPORTS = _transports()
#: Transport parameters that mode "mill" can fit: name -> (fit parameter, transports);
#: its home is :mod:`millflow.mill.transport`.
TRANSPORT_FIT = _TRANSPORT_FIT


def canonical_location(loc) -> str:
    """One spelling of a sampling location (``cell:K``, ``z:Y``).

    One spelling of a sampling location: ``cell:K`` (content of cell K, 1-based) and
    ``z:Y`` (fractional axial position), as :func:`millflow.steady_mill` reads them;
    the fit's earlier spelling ``cell_K`` is accepted as an alias.
    """
    loc = str(loc)
    if loc.startswith("cell_") and loc[5:].isdigit():
        return "cell:" + loc[5:]
    return loc
CLASSIFICATIONS = {None: (), "screen": ("ln_c50", "ln_sharp"), "screen_power": ("n_screen",),
                   "screen_power_cut": ("n_screen",)}

_DEFAULTS = {  # value, min, max
    "ln_A0": (0.0, -12.0, 12.0), "alpha": (1.0, -2.0, 4.0), "ln_mu": (1.0, -5.0, 8.0), "Lambda": (3.0, 0.5, 8.0),
    "phi": (0.5, 0.0, 1.0), "gamma": (1.0, 0.05, 4.0), "beta": (4.0, 1.0, 10.0),
    "ln_c50": (0.0, -4.0, 1.5), "ln_sharp": (1.0, -1.0, 3.5), "n_screen": (2.0, 0.0, 12.0),
    # theta > 0 can lift phi_j = phi0 (x_1/x_j)^theta above 1 at fine sizes (outside eq. 8's domain)
    "xi": (0.0, -3.0, 3.0), "eta": (0.0, -3.0, 3.0), "theta": (0.0, -1.0, 0.0),
    # fitted transport (mode "mill", transport_fit): tau [s] in logs, Peclet number in logs,
    # recirculation ratio r
    "ln_tau": (6.0, 0.0, 11.5), "ln_pe": (2.0, -2.0, 6.0), "r": (1.0, 0.0, 10.0),
    # non-linear kinetics (millflow.fitting.kinetics): 0 is the linear model
    "s_slow": (0.0, 0.0, 10.0), "lam_pop": (0.0, -5.0, 5.0), "beta0": (0.0, 0.0, 0.1),
}
#: Transports of mode "mill" with a non-linear steady solve (millflow.mill.nonlinear).
_NONLINEAR_TRANSPORTS = tuple(TRANSPORTS)


@dataclass(frozen=True)
class Parameter:
    """One model parameter, lmfit-style: starting value, bounds, and whether it varies."""

    name: str
    value: float
    min: float = -math.inf
    max: float = math.inf
    vary: bool = True

    def __post_init__(self):
        if not (self.min <= self.value <= self.max):
            raise InputError(f"parameter {self.name}: value {self.value!r} outside [{self.min!r}, {self.max!r}]")
        if self.vary and not (math.isfinite(self.min) and math.isfinite(self.max)):
            raise InputError(f"parameter {self.name}: a varying parameter needs finite bounds (global search)")


@dataclass(frozen=True)
class ModelSpec:
    """What is fitted; see the module docstring for the forms and their parameters.

    Attributes
    ----------
    mode : "batch", "plug_flow", "well_mixed" or "mill".
    transport : mode "mill" only: one of :data:`TRANSPORTS`.
    transport_params : mode "mill": fixed transport parameters other than tau, a dict
        (e.g. ``{"n": 10}``, ``{"pe": 8.0}``, ``{"n": 5, "r": 1.0}``); stored as sorted pairs.
    where : mode "mill": where classification acts (None: the mill's default), see
        :func:`millflow.mill.steady_mill`.
    transport_fit : mode "mill": transport parameters fitted with S and B,
        a subset of :data:`TRANSPORT_FIT` for the transport: "tau" (parameter ``ln_tau``,
        tau [s]; with a ``tau_column`` it scales the column: tau_c = exp(ln_tau) *
        column_c / geometric mean), "pe" (``ln_pe``, axial dispersion) and "r" (``r``,
        recirculation ratio of recirculating cells). The number of cells n stays fixed
        (an integer: compare fits with different n instead).
    rate, breakage, classification : form names (classification None or "screen").
    rate_process : process-table columns entering A by eq. 10.
    screen_column : process column holding the screen opening for "screen" (its unit from
        its name: screen_mm, screen_um, screen_m).
    ball_column : process column holding the ball size for rate "austin_ball" (ball_mm, ...).
    tau_column : process column holding tau for continuous modes (tau_s, tau_min, tau_h;
        None: tau = 1). A column whose name carries no unit is refused.
    x0_m : reference size of eq. 5 [m].
    b_matrix : (N, N) fractional b on the numerical grid for breakage "fixed".
    objective : "cumulative" (residuals of cumulative passing) or "fractional"
        (residuals of the mass fraction between neighbouring sieves).
    """

    mode: str = "batch"
    rate: str = "power"
    breakage: str = "normalized"
    classification: str | None = None
    rate_process: tuple = ()
    param_process: tuple = ()
    screen_column: str = "screen_mm"
    ball_column: str = "ball_mm"
    tau_column: str | None = None
    x0_m: float = X0_DEFAULT
    n_tanks: int = 1
    b_matrix: np.ndarray | None = field(default=None, compare=False)
    objective: str = "cumulative"
    transport: str | None = None
    transport_params: tuple = ()
    where: str | None = None
    transport_fit: tuple = ()
    kinetics: tuple = ()
    kinetics_params: tuple = ()

    def __post_init__(self):
        for key, val, ok in (("mode", self.mode, MODES), ("rate", self.rate, RATE_FORMS),
                             ("breakage", self.breakage, BREAKAGE_FORMS),
                             ("classification", self.classification, CLASSIFICATIONS),
                             ("objective", self.objective, ("cumulative", "fractional"))):
            if val not in ok:
                raise InputError(f"model.{key} = {val!r}: expected one of {[k for k in ok]}")
        if int(self.n_tanks) != self.n_tanks or self.n_tanks < 1:
            raise InputError(f"model.n_tanks = {self.n_tanks!r}: expected an integer >= 1")
        self._check_transport()
        from millflow.fitting.kinetics import check_kinetics
        kp = self.kinetics_params
        forms, consts = check_kinetics(self.kinetics, dict(kp) if not isinstance(kp, dict) else kp, self.mode)
        object.__setattr__(self, "kinetics", forms)
        object.__setattr__(self, "kinetics_params", consts)
        if "slowing_down" in forms and self.mode != "batch":
            self._check_age_slowing(dict(consts))
        if forms and self.mode == "mill" and self.transport not in _NONLINEAR_TRANSPORTS:
            raise InputError(f"model.kinetics with transport {self.transport!r}: non-linear kinetics are fitted with "
                             f"transports {list(_NONLINEAR_TRANSPORTS)}")
        if forms and self.mode == "mill" and is_tanks(self.transport):
            n = dict(self.transport_params).get("n")
            if n is not None and float(n) != int(n):
                raise InputError(f"model.transport_params.n = {n!r}: a mill with non-linear kinetics solves "
                                 "tanks in series cell by cell; expected an integer number of tanks")
        if self.breakage == "fixed" and self.b_matrix is None:
            raise InputError("model.breakage = 'fixed' needs b_matrix (the fractional b on the numerical grid)")
        object.__setattr__(self, "rate_process", tuple(self.rate_process))
        pp = tuple((str(a), str(b)) for a, b in self.param_process)
        object.__setattr__(self, "param_process", pp)
        allowed = [n for n in ("alpha", "gamma", "n_screen") if n in self.base_names]
        allowed += [f"a_{col}" for col in self.rate_process]
        for name, _ in pp:
            if name not in allowed:
                raise InputError(f"model.param_process: {name!r} cannot depend on process parameters here; "
                                 f"expected one of {allowed}")

    def _check_age_slowing(self, consts: dict):
        """Refuse what slowing-down in the particle's age cannot fit in a continuous mill."""
        # classification takes every transport here: the age-structured balance of the cells
        # (millflow.mill.age_cells) and the age-position balance of plug flow and the two
        # axial-dispersion vessels (millflow.mill.age_axis); model.where is checked with the
        # transport
        if "tau" in self.transport_fit and "t_ref_s" not in consts:
            raise InputError("model.kinetics = 'slowing_down' with model.transport_fit = ['tau']: the default t_ref "
                             "(the longest tau) would move with the fit; expected model.kinetics_params.t_ref_s "
                             "(or t_ref_min)")

    def _check_transport(self):
        tp = self.transport_params
        items = tp.items() if isinstance(tp, dict) else tp
        try:
            tp = tuple(sorted((str(k), v) for k, v in items))
        except (TypeError, ValueError) as exc:
            raise InputError(f"model.transport_params = {self.transport_params!r}: expected a dict "
                             "name -> value") from exc
        object.__setattr__(self, "transport_params", tp)
        fitted = tuple(str(v) for v in self.transport_fit)
        object.__setattr__(self, "transport_fit", fitted)
        if self.mode != "mill":
            if fitted:
                raise InputError(f"model.transport_fit needs mode = 'mill' (mode is {self.mode!r})")
            if self.transport is not None or tp or self.where is not None:
                raise InputError(f"model.transport, transport_params and where need mode = 'mill' "
                                 f"(mode is {self.mode!r})")
            return
        from rtd import names as rtd_names
        try:  # canonical name from rtd's table; its aliases (tis, cells, ad-closed, ...) accepted
            object.__setattr__(self, "transport", rtd_names.canonical_name(self.transport))
        except ValueError:
            raise InputError(f"model.transport = {self.transport!r}: mode 'mill' needs one of {list(TRANSPORTS)} "
                             f"(or an alias: {', '.join(rtd_names.ALIASES)})") from None
        _, required, optional = TRANSPORTS[self.transport]
        names = dict(tp)
        unknown = sorted(set(names) - set(required) - set(optional))
        missing = [k for k in required if k not in names and k not in fitted]
        if unknown or missing:
            raise InputError(f"model.transport_params for {self.transport!r}: "
                             + (f"unknown {unknown}; " if unknown else "") + (f"missing {missing}; " if missing else "")
                             + f"expected {list(required)} (required) and {list(optional)} (optional); "
                             "tau comes from tau_column or transport_fit")
        for name in fitted:
            if name not in TRANSPORT_FIT or self.transport not in TRANSPORT_FIT[name][1]:
                ok = [k for k, (_, trs) in TRANSPORT_FIT.items() if self.transport in trs]
                raise InputError(f"model.transport_fit: {name!r} cannot be fitted for transport {self.transport!r}; "
                                 f"expected some of {ok}")
        # fitted parameters given a placeholder for the check (the fit supplies the value)
        self.make_transport(1.0, **{k: 1.0 for k in fitted if k != "tau"})  # values checked by rtd
        if self.where is not None and self.classification is None:
            raise InputError("model.where is given but there is no classification")
        places = classification_places(self.transport)
        if isinstance(self.where, str) and self.where not in places:
            raise InputError(f"model.where = {self.where!r} is not possible for transport {self.transport!r}; "
                             f"expected one of {list(places)}" + (" or cell numbers" if is_cells(self.transport)
                                                                  else ""))

    def make_transport(self, tau: float, **fitted):
        """The rtd transport model of mode "mill" with mean residence time ``tau`` [s].

        The rtd transport model of mode "mill" with mean residence time ``tau`` [s]
        (``fitted``: values of fitted transport parameters, e.g. pe=8.0, r=1.0).
        """
        import rtd
        from rtd import names as rtd_names
        entry = rtd_names.TRANSPORTS[self.transport]
        try:
            return entry.cls(float(tau), **{**dict(entry.fixed), **dict(self.transport_params), **fitted})
        except (rtd.RTDError, TypeError, ValueError) as exc:
            raise InputError(f"model.transport = {self.transport!r} with transport_params "
                             f"{dict(self.transport_params)}: {exc}") from exc

    @property
    def base_names(self) -> tuple:
        """Parameters of the rate, breakage and classification forms, before eq. 10."""
        return (RATE_FORMS[self.rate] + BREAKAGE_FORMS[self.breakage] + CLASSIFICATIONS[self.classification])

    @property
    def param_names(self) -> tuple:
        """Names of the fitted parameters, in the order of the vector theta."""
        names = list(RATE_FORMS[self.rate][:1])
        for name in [f"a_{p}" for p in self.rate_process] + list(self.base_names[1:]):
            names.append(name)
            names += [f"{name}_{col}" for par, col in self.param_process if par == name]
        from millflow.fitting.kinetics import KINETICS_FORMS
        names += [n for f in self.kinetics for n in KINETICS_FORMS[f]]
        names += [TRANSPORT_FIT[k][0] for k in self.transport_fit]
        return tuple(names)

    def label(self) -> str:
        """A short label of the model (mode, forms, transport)."""
        parts = [self.mode, f"rate={self.rate}", f"B={self.breakage}"]
        if self.mode == "mill":
            parts.insert(1, f"transport={self.transport}" + "".join(f",{k}={v}" for k, v in self.transport_params
                                                                    if k not in self.transport_fit)
                         + "".join(f",{k}=fitted" for k in self.transport_fit))
        if self.classification:
            parts.append(f"class={self.classification}")
        if self.rate_process:
            parts.append("A~" + "*".join(self.rate_process))
        for par, col in self.param_process:
            parts.append(f"{par}~{col}")
        if self.kinetics:
            parts.append("kinetics=" + "+".join(self.kinetics))
        return " ".join(parts)


def default_parameters(spec: ModelSpec, overrides: dict | None = None, where: str = "params") -> dict:
    """Parameters of a spec with default values and bounds, updated by ``overrides``.

    Parameters of a spec with default values and bounds, updated by ``overrides``
    (name -> table with any of value, min, max (numbers), vary (true/false)). A varied
    parameter needs min < max and its value inside; a fixed one may have min = max.
    """
    from millflow.inputs import boolean, check_keys, number

    overrides = dict(overrides or {})
    out = {}
    for name in spec.param_names:
        v, lo, hi = _DEFAULTS.get(name, (0.0, -5.0, 5.0))
        o = overrides.pop(name, {})
        w = f"{where}.{name}"
        if not isinstance(o, dict):
            raise InputError(f"{w} = {o!r}: expected a table with value, min, max, vary")
        check_keys(o, {"value", "min", "max", "vary"}, w)
        lo, hi = number(o, "min", w, lo), number(o, "max", w, hi)
        vary = boolean(o, "vary", w, True)
        v = number(o, "value", w, min(max(v, lo), hi))
        if lo > hi or (vary and lo == hi):
            raise InputError(f"{w}: min = {lo:g} and max = {hi:g}; expected min < max for a varied parameter "
                             "(or vary = false)")
        if not lo <= v <= hi:
            raise InputError(f"{w}.value = {v:g}: outside [min, max] = [{lo:g}, {hi:g}]")
        out[name] = Parameter(name, v, lo, hi, vary)
    if overrides:
        raise InputError(f"params: {sorted(overrides)} are not parameters of this model; "
                         f"expected {list(spec.param_names)}")
    return out

