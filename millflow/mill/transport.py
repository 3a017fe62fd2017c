"""The one place a transport is dispatched: its names, its kind, what it can fit.

A mill's transport is named in a user's file (``[units.X.transport] model = ...``,
``[model] transport = ...``) by a name of :mod:`rtd.names` (the one table of names and
aliases) and solved as an ``rtd`` model. Code outside :mod:`millflow.mill` asks this
module what a transport is, by name or by model, instead of comparing names or testing
rtd classes:

- :func:`transport_kind`: the kind of a name or model, one of :data:`KINDS`;
- predicates on it: :func:`is_cells` (well-mixed cells: ``cell:K`` samples, discharge or
  cell-outlet classification), :func:`is_tanks`, :func:`is_network`, :func:`is_plug`,
  :func:`is_axial` (on an axis: ``z:Y`` samples, classification along the axis),
  :func:`is_axial_dispersion`;
- :func:`equal_cells` and :func:`cell_count`: the cells of a cell transport;
- :func:`shape_parameter` and :func:`fit_parameters` (:data:`TRANSPORT_FIT`): its
  parameters besides tau, and those a fit can estimate;
- :data:`BUILDERS` and :func:`build_transport`: the rtd model from a name, tau [s] and
  parameters (or a ``"series"`` of parts);
- :func:`solve_nonlinear`: a mill with non-linear kinetics by the transport's own solver.

The predicates are False (and :func:`equal_cells`, :func:`cell_count`,
:func:`shape_parameter` None) for no transport (None: a fit mode without one). Besides
rtd's names, ``"well_mixed"`` (the fit's mode and the non-linear solvers' word
for perfect mixing) is read as ``"perfect_mixing"``.

Examples
--------
>>> transport_kind("tis"), is_cells("recirculating_cells"), is_axial("plug_flow")
('tanks', True, True)
>>> equal_cells("tanks_in_series", {"n": 3}), fit_parameters("axial_dispersion")
(3, ('tau', 'pe'))
"""
from __future__ import annotations

from millflow.errors import InputError
from rtd import names as _names

__all__ = ["KINDS", "TRANSPORT_NAMES", "TRANSPORT_FIT", "BUILDERS", "canonical_transport", "transport_kind",
           "is_cells", "is_tanks", "is_network", "is_plug", "is_axial", "is_axial_dispersion", "equal_cells",
           "cell_count",
           "shape_parameter", "fit_parameters", "classification_places", "build_transport", "mode_transport",
           "solve_nonlinear"]

#: Kinds of transport: well-mixed cells (one cell, a chain of equal tanks, a network of
#: cells with back-flow), plug flow, the closed and the open axial-dispersion vessel,
#: compositions, and any other rtd model (segregated flow only).
KINDS = ("perfect_mixing", "tanks", "network", "plug", "axial", "axial_open", "series", "parallel", "rtd")
#: The canonical transport names (:mod:`rtd.names`).
TRANSPORT_NAMES = tuple(_names.TRANSPORTS)
_NAME_KIND = {"perfect_mixing": "perfect_mixing", "tanks_in_series": "tanks", "recirculating_cells": "network",
              "plug_flow": "plug", "axial_dispersion": "axial", "axial_dispersion_open": "axial_open"}
#: Words for a transport besides rtd's names and aliases.
_OTHER_NAMES = {"well_mixed": "perfect_mixing"}
#: Transport parameters that a fit (mode "mill") can estimate: name -> (fit parameter, transports).
TRANSPORT_FIT = {"tau": ("ln_tau", TRANSPORT_NAMES), "pe": ("ln_pe", ("axial_dispersion",)),
                 "r": ("r", ("recirculating_cells",))}
#: Transport name -> builder of its rtd model from tau [s] and its own parameters.
BUILDERS = {name: entry.build for name, entry in _names.TRANSPORTS.items()}


def canonical_transport(name: str) -> str:
    """The canonical name of a transport name or alias.

    Parameters
    ----------
    name : a name of :mod:`rtd.names` (canonical or alias) or ``"well_mixed"``.

    Returns
    -------
    str
        The canonical name.

    Raises
    ------
    rtd.RTDError
        For an unknown name (the message lists the valid ones).
    """
    if isinstance(name, str) and name in _OTHER_NAMES:
        return _OTHER_NAMES[name]
    return _names.canonical_name(name)


def transport_kind(transport) -> str:
    """The kind (one of :data:`KINDS`) of a transport name or ``rtd`` model.

    Parameters
    ----------
    transport : a transport name (see :func:`canonical_transport`; ``"series"``: a flowsheet's
        series of parts) or an ``rtd`` model.

    Returns
    -------
    str
        ``"tanks"`` for tanks in series (a model with any n), ``"network"`` for recirculating
        cells and other compartment networks, the other kinds as :data:`KINDS` names them.

    Raises
    ------
    InputError
        For something that is neither.
    """
    if isinstance(transport, str):
        return "series" if transport == "series" else _NAME_KIND[canonical_transport(transport)]
    import rtd

    from millflow.mill.scene import _kind

    if isinstance(transport, rtd.TanksInSeries):
        return "tanks"
    return _kind(transport)


def _kind_of(transport) -> str | None:
    """:func:`transport_kind`, None for no transport (a fit mode without one)."""
    return None if transport is None else transport_kind(transport)


def is_cells(transport) -> bool:
    """True for well-mixed cells: perfect mixing, tanks in series, a network of cells."""
    return _kind_of(transport) in ("perfect_mixing", "tanks", "network")


def is_tanks(transport) -> bool:
    """True for tanks in series (equal well-mixed tanks in a row, n of them)."""
    return _kind_of(transport) == "tanks"


def is_network(transport) -> bool:
    """True for a network of cells with back-flow (recirculating cells, a compartment network)."""
    return _kind_of(transport) == "network"


def is_plug(transport) -> bool:
    """True for plug flow."""
    return _kind_of(transport) == "plug"


def is_axial(transport, *, open_vessel: bool = True) -> bool:
    """True for a transport along an axis: plug flow and axial dispersion.

    Parameters
    ----------
    transport : a transport name or ``rtd`` model.
    open_vessel : whether the open axial-dispersion vessel counts (its axis is the whole
        line, not the mill's length [0, 1]).

    Returns
    -------
    bool
    """
    return _kind_of(transport) in (("plug", "axial", "axial_open") if open_vessel else ("plug", "axial"))


def is_axial_dispersion(transport, *, open_vessel: bool | None = None) -> bool:
    """True for axial dispersion: either vessel (``open_vessel`` None), the open (True) or the closed one (False)."""
    kinds = {None: ("axial", "axial_open"), True: ("axial_open",), False: ("axial",)}[open_vessel]
    return _kind_of(transport) in kinds


def equal_cells(transport, params: dict) -> int | None:
    """Number of equal well-mixed cells in a row, or None.

    Parameters
    ----------
    transport : a transport name.
    params : its parameters besides tau.

    Returns
    -------
    int or None
        1 for perfect mixing, n for tanks in series with an integer n >= 1 (and no other
        parameter), None for every other transport.
    """
    kind = _kind_of(transport)
    params = dict(params)
    if kind == "perfect_mixing" and not params:
        return 1
    if kind == "tanks" and set(params) == {"n"} and float(params["n"]).is_integer() and params["n"] >= 1:
        return int(params["n"])
    return None


def cell_count(transport, params: dict):
    """Number of cells of a cell transport (1 for perfect mixing, else its ``n``), or None."""
    if not is_cells(transport):
        return None
    return 1 if _kind_of(transport) == "perfect_mixing" else dict(params).get("n")


def shape_parameter(transport) -> str | None:
    """The parameter that shapes the RTD besides tau: ``"n"`` (cells) or ``"pe"`` (axial), else None."""
    return {"tanks": "n", "network": "n", "axial": "pe", "axial_open": "pe"}.get(_kind_of(transport))


def classification_places(transport) -> tuple[str, ...]:
    """Where classification d* can act on a transport (the ``where`` values of a mill).

    ``("discharge", "cells")`` for well-mixed cells (a network of cells also takes 1-based
    cell numbers), ``("axis",)`` for plug flow and axial dispersion (d* the relative axial
    velocity), ``()`` for a transport with neither.
    """
    if is_cells(transport):
        return ("discharge", "cells")
    if is_axial(transport):
        return ("axis",)
    return ()


def fit_parameters(transport) -> tuple[str, ...]:
    """The transport parameters a fit can estimate for this transport (keys of :data:`TRANSPORT_FIT`)."""
    if transport is None:
        return ()
    name = canonical_transport(transport)
    return tuple(k for k, (_, names) in TRANSPORT_FIT.items() if name in names)


#: The fit's continuous modes that name a transport: mode -> (transport, where d* acts).
_MODE_TRANSPORT = {"plug_flow": ("plug_flow", "axis"), "well_mixed": ("tanks_in_series", "cells")}


def mode_transport(mode: str, n_tanks: int = 1, transport=None, params=None, where=None):
    """The transport a fit's mode stands for: (name, parameters, where d* acts).

    Parameters
    ----------
    mode : the fit's mode: ``"plug_flow"`` (eq. 4 at t = tau, d* in the velocity),
        ``"well_mixed"`` (``n_tanks`` equal well-mixed tanks, d* at every tank outlet) or
        ``"mill"`` (``transport`` with ``params`` and ``where`` as given).
    n_tanks : tanks of mode ``"well_mixed"`` (1: perfect mixing).
    transport, params, where : mode ``"mill"``'s transport, its parameters besides tau and
        where its classification acts.

    Returns
    -------
    tuple
        (canonical transport name, parameters dict, where).

    Raises
    ------
    InputError
        For mode ``"batch"`` (no transport) or an unknown mode.
    """
    if mode == "mill":
        return canonical_transport(transport), dict(params or {}), where
    if mode not in _MODE_TRANSPORT:
        raise InputError(f"mode {mode!r}: expected one of {sorted(_MODE_TRANSPORT) + ['mill']} (a mode with a "
                         "transport)")
    name, at = _MODE_TRANSPORT[mode]
    if name == "tanks_in_series" and int(n_tanks) == 1:
        return "perfect_mixing", {}, at
    return name, ({"n": int(n_tanks)} if name == "tanks_in_series" else {}), at


def build_transport(model: str, tau: float, params: dict):
    """The rtd model of a mill from its transport name and parameters.

    Parameters
    ----------
    model : a name of :data:`BUILDERS`, or ``"series"`` with ``params["parts"]`` =
        [(model, parameters, tau_fraction), ...] (rtd.Series of the parts, part k with
        tau_k = tau_fraction_k tau).
    tau : mean residence time [s].
    params : the model's parameters besides tau (``discharge``, the mill's, is left out).

    Returns
    -------
    rtd model
    """
    if model == "series":
        import rtd

        return rtd.Series(*[BUILDERS[m](tau * f, **_model_params(p)) for m, p, f in params["parts"]])
    return BUILDERS[model](tau, **_model_params(params))


def _model_params(params: dict) -> dict:
    """The rtd model's own parameters (``discharge`` is the mill's: where the open vessel's product is taken)."""
    return {k: v for k, v in params.items() if k != "discharge"}


def solve_nonlinear(kin, feed, tau: float, transport: str = "well_mixed", *, n_tanks: int = 1, pe=None, d=None,
                    where: str = "discharge", network=None, model=None, rtol: float, atol: float, tol: float,
                    m_cells: int | None = None):
    """Steady mill with non-linear kinetics by the solver of its transport.

    Parameters
    ----------
    kin : millflow.nonlinear.Kinetics
    feed : (N,) feed per unit feed rate.
    tau : mean residence time [s].
    transport : a transport name: plug flow, closed axial dispersion (with ``pe``) or well-mixed
        cells (``n_tanks`` equal tanks in series; 1: perfect mixing).
    n_tanks, pe : the cells of a chain, the Peclet number of the closed vessel.
    d, where : normalised discharge d* and where it acts.
    network : an rtd model of cells with back-flow: Newton on all cells.
    model : any other rtd transport (e.g. the open vessel), by
        :func:`millflow.mill.nonlinear.solve_transport`.
    rtol, atol : the plug-flow ODE's tolerances; ``tol`` that of :func:`solve_transport`.
    m_cells : fixed axial grid (number of volumes).

    Returns
    -------
    millflow.mill.nonlinear.NonlinearSteady
    """
    from millflow.mill import nonlinear as nl

    if model is not None:
        return nl.solve_transport(kin, feed, model, d, where=None if d is None else where, tol=tol,
                                  holdup=False, m_cells=m_cells)
    if network is not None:
        return nl.cells(kin, feed, network, d, where)
    kind = _kind_of(transport)
    if kind == "plug":
        return nl.plug_flow(kin, feed, tau, d, rtol=rtol, atol=atol, holdup=False)
    if kind == "axial":
        return nl.axial_dispersion(kin, feed, tau, pe, d, m_cells=m_cells)
    if kind not in ("perfect_mixing", "tanks", "network", "axial_open"):
        raise InputError(f"transport {transport!r}: expected well-mixed cells, plug flow or axial dispersion "
                         "(or the rtd model of another transport)")
    if n_tanks == 1:
        return nl.well_mixed(kin, feed, tau, d)
    return nl.tanks_in_series(kin, feed, tau, n_tanks, d, where)
