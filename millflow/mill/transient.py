"""Transient mill: eq. (1) in time for start-up, a step change of feed or a tracer pulse.

Cells (perfect mixing, tanks in series, recirculating cells, any compartment
network): the hold-up m_ik of class i in cell k obeys the linear system

    dm_i/dt = T^i m_i - S_i m_i + sum_{j<i} b_ij S_j m_j + (1 - beta) u f_i(t),

T^i the transport matrix of class i with classification (:mod:`millflow.mill.cells`),
product p_i = h_i sum_k (o_k / V_k) m_ik + beta f_i. Axial dispersion: the same
system from the finite-volume discretisation of :mod:`millflow.mill.axial` (method of
lines on a fixed grid); the open vessel from :mod:`millflow.mill.axial_open` on the
whole line, with its sampled or flux discharge and the steady state's hold-up. All are
integrated by scipy's implicit ``solve_ivp`` (BDF by default, through
:func:`millflow.ode.integrate_linear`) with the constant sparse Jacobian, so stiff rates
(tau S up to 1e8) cost little. A pulse is an initial hold-up distributed like the inlet
(for axial dispersion: in the inlet control volume, an O(h) approximation of the inlet
delta).

Plug flow with one speed v (d* = v for every class, 1 without classification) is exact:
the product is the feed delayed by tau / v and ground for tau / v. With classification on
the axis the classes travel at different speeds and a step spreads into one front per
speed: :mod:`millflow.mill.plug_fronts` solves the sector between the fronts (spectral in
the similarity coordinate z / t, with its measured error estimate).
Any other rtd model, without classification, passes a pulse exactly by segregated
flow: product(t) = E(t) exp(K t) pulse (the tracer of the model, ground for its age).
With S = 0 every path reproduces the transport model's own E(t).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse as sp
import xarray as xr

from millflow.batch import batch_grind
from millflow.errors import InputError
from millflow.linalg import breakage_matrix
from millflow.mill.scene import _check_feed, _scene, _tau
from millflow.mill.steady import _size_coords
from millflow.mill.axial import solve_axial_grid
from millflow.mill.axial_open import back_layer_matrix, solve_axial_open_grid, tail_length
from millflow.mill.finite_volume import closed_faces, node_losses, open_faces, tridiagonal
from millflow.mill.cells import cell_operators, solve_cells
from millflow.mill.segregated import plug_flow
from millflow.ode import integrate_linear

__all__ = ["transient_mill"]


def _cells_system(sc, n_cls):
    """(J sparse, B_in (Nn, N) feed-to-state, C (N, Nn) state-to-product, beta, n)."""
    net = sc.network
    n = net.n
    offdiag, drain, exit_rate, G, H = cell_operators(net, sc.d, sc.where or "discharge", n_cls)
    K = breakage_matrix(sc.S, sc.b)
    transport = sp.block_diag([sp.csr_matrix(offdiag * G[i][np.newaxis, :]) for i in range(n_cls)]) - sp.diags(
        (G * drain + H * exit_rate).ravel())
    J = (transport + sp.kron(sp.csr_matrix(K), sp.identity(n))).tocsc()
    u = (1.0 - net.bypass) * np.asarray(net.inlet, dtype=float)
    B_in = sp.kron(sp.identity(n_cls), sp.csr_matrix(u[:, np.newaxis])).tocsr()
    C = sp.block_diag([sp.csr_matrix((H[i] * exit_rate)[np.newaxis, :]) for i in range(n_cls)]).tocsr()
    return J, B_in, C, float(net.bypass), n


def _fv_jacobian(sc, faces, v, tau: float, n_cls):
    """Jacobian of the method of lines on a finite-volume grid.

    J of the method of lines on a finite-volume grid: per class minus the tridiagonal
    node balances of :func:`millflow.mill.finite_volume.tridiagonal` (face fluxes, outflow
    v_i at the last node) divided by the volumes tau w_k, plus breakage K (x) I.
    """
    n = faces.z.size
    lower, diag, upper = tridiagonal(faces, node_losses(faces, v))
    scale = sp.diags(1.0 / (tau * faces.weights))
    blocks = [scale @ sp.diags([lower[i], diag[i], upper[i]], [-1, 0, 1]) for i in range(n_cls)]
    K = breakage_matrix(sc.S, sc.b)
    return (-sp.block_diag(blocks) + sp.kron(sp.csr_matrix(K), sp.identity(n))).tocsc()


def _axial_system(sc, n_cls, m_cells):
    """Method of lines for the axial FV scheme; state c (class-major, N (M + 1))."""
    T = sc.transport
    tau, pe = T.tau, T.pe
    v = np.ones(n_cls) if sc.d is None else sc.d
    w = np.ones(n_cls) if sc.dispersion is None else sc.dispersion
    M = int(m_cells)
    faces = closed_faces(pe, M, v, w)
    weights = faces.weights
    J = _fv_jacobian(sc, faces, v, tau, n_cls)
    e0 = np.zeros(M + 1)
    e0[faces.inlet] = 1.0 / (tau * weights[faces.inlet])
    B_in = sp.kron(sp.identity(n_cls), sp.csr_matrix(e0[:, np.newaxis])).tocsr()
    eM = np.zeros(M + 1)
    eM[faces.outlet] = 1.0
    C = sp.kron(sp.diags(v), sp.csr_matrix(eM[np.newaxis, :])).tocsr()
    hold = sp.kron(sp.identity(n_cls), sp.csr_matrix(tau * weights[np.newaxis, :])).tocsr()
    return J, B_in, C, hold, M


def _axial_open_system(sc, n_cls, m_cells):
    """Method of lines for the open vessel's finite-volume scheme.

    Method of lines for the open vessel's FV scheme on the whole line
    (:mod:`millflow.mill.axial_open`); state c (class-major, N n).

    Returns (J, B_in, C, D, hold, M): product = C y + D f, hold-up = hold y. Sampled
    discharge: p = v c(1), hold-up = what is upstream of z = 1 plus the back-dispersion
    layer of c(1) (the steady definitions, so the start-up ends at the steady state's
    hold-up). Flux discharge: p from the balance of (-inf, 1], f - d/dt(tau int c) +
    tau int K c, with dc/dt = J y + B_in f.
    """
    T = sc.transport
    tau, pe = T.tau, T.pe
    v = np.ones(n_cls) if sc.d is None else sc.d
    w = v.copy() if sc.dispersion is None else sc.dispersion
    M = int(m_cells)
    g = open_faces(pe, M, v, w, tail_length(sc.S, tau, pe, v, w))
    n = g.z.size
    K = breakage_matrix(sc.S, sc.b)
    J = _fv_jacobian(sc, g, v, tau, n_cls)
    e0 = np.zeros(n)
    e0[g.inlet] = 1.0 / (tau * g.weights[g.inlet])
    B_in = sp.kron(sp.identity(n_cls), sp.csr_matrix(e0[:, np.newaxis])).tocsr()
    e1 = np.zeros(n)
    e1[g.outlet] = 1.0
    at_discharge = sp.kron(sp.identity(n_cls), sp.csr_matrix(e1[np.newaxis, :])).tocsr()
    upstream = sp.kron(sp.identity(n_cls), sp.csr_matrix(tau * g.upstream[np.newaxis, :])).tocsr()
    if (sc.discharge or "sampled") == "flux":
        C = sp.csr_matrix(K) @ upstream - upstream @ J
        D = np.eye(n_cls) - (upstream @ B_in).toarray()
        hold = upstream
    else:
        C = sp.diags(v) @ at_discharge
        D = np.zeros((n_cls, n_cls))
        hold = upstream + sp.csr_matrix(tau * back_layer_matrix(sc.S, sc.b, tau, g, v)) @ at_discharge
    return J, B_in, sp.csr_matrix(C), D, sp.csr_matrix(hold), M


def _integrate(J, rhs_const, y0, t, method, rtol, atol):
    order = np.argsort(t)
    ts = t[order]
    out = np.empty((t.size, y0.size))
    at0 = ts == 0.0
    out[order[at0]] = y0
    info = {"nfev": 0, "njev": 0, "nlu": 0}
    if (~at0).any():
        sol = integrate_linear(J, (0.0, float(ts[-1])), y0, c=rhs_const, method=method, t_eval=ts[~at0], rtol=rtol,
                               atol=atol, what="transient mill")
        out[order[~at0]] = sol.y.T
        info = {"nfev": int(sol.nfev), "njev": int(sol.njev), "nlu": int(sol.nlu)}
    return out, info


def _integrate_measured(J, rhs_const, y0, t, method, rtol, atol):
    """Integrate at (rtol, atol) and at 100x tighter, measuring the time-integration error.

    Returns the tight solution, the evaluation counts of both and Y_loose - Y_tight, whose
    size measures the time integration's error (the tolerance itself is not an estimate:
    local errors accumulate, and a tracer pulse through three tanks was 13x above
    rtol max|p| + atol).
    """
    loose, info = _integrate(J, rhs_const, y0, t, method, rtol, atol)
    tight, info2 = _integrate(J, rhs_const, y0, t, method, rtol / 100, atol / 100)
    return tight, {k: info[k] + info2[k] for k in info}, loose - tight


def transient_mill(S, b, transport, t, *, feed=None, initial_feed=None, pulse=None, d=None,
                   where=None, dispersion=None, discharge=None, x=None, method: str | None = None, rtol: float = 1e-8,
                   atol: float = 1e-12, m_cells: int = 200) -> xr.Dataset:
    """Solve eq. (1) in time: start-up, step change of feed or tracer pulse.

    Parameters
    ----------
    S, b, transport, d, where, dispersion, discharge, x : as :func:`millflow.mill.steady_mill`
        (S a :class:`millflow.nonlinear.Kinetics` with b = None: non-linear kinetics,
        :mod:`millflow.mill.nonlinear_transient`).
    t : (T,) output times [s], >= 0.
    feed : (N,) feed flows from t = 0 on (default zero).
    initial_feed : (N,) the mill starts at the steady state for this feed (a step
        change from ``initial_feed`` to ``feed``); None starts empty (start-up).
    pulse : (N,) masses injected with the feed at t = 0 (tracer pulse) [mass].
    method : implicit solve_ivp method ("BDF", "Radau", "LSODA"); None: BDF for first-order
        kinetics (a constant Jacobian); for non-linear ones LSODA (dense Jacobian) on small
        cell systems, Radau otherwise (:mod:`millflow.mill.nonlinear_transient`: scipy's BDF
        took 250,000 right-hand sides where they took 3,500 and 18,000).
    rtol, atol : tolerances of the time integration.
    m_cells : control volumes of the axial-dispersion grid.

    Returns
    -------
    xarray.Dataset with ``product`` (time, size) [mass/s] and ``holdup`` (time, size)
    [mass] (per unit feed rate: [1] and [s]); ``cell_holdup`` (time, cell, size) for
    cells. Attributes ``method``, ``error_estimate`` (max abs error of ``product``) and
    ``holdup_error_estimate`` (of ``holdup``): the time integration's error measured by a
    second solve at 100x tighter tolerances (the returned solution is the tighter one),
    plus, on the axial grids, the spatial error from the same solve on half the volumes;
    ``runtime_s``, evaluation counts.
    """
    from millflow.mill.nonlinear_mill import is_kinetics

    if is_kinetics(S) and not S.is_linear:  # non-linear kinetics: the method of lines of their steady residual
        from millflow.mill.nonlinear_transient import transient_nonlinear

        return transient_nonlinear(S, b, transport, t, feed=feed, initial_feed=initial_feed, pulse=pulse, d=d,
                                   where=where, dispersion=dispersion, discharge=discharge, x=x, method=method,
                                   rtol=rtol, atol=atol, m_cells=m_cells)
    if is_kinetics(S):
        from millflow.mill.nonlinear_mill import check_no_b

        check_no_b(S, b, "transient_mill")
        S, b = S.S, S.b
    method = "BDF" if method is None else method
    start = time.perf_counter()
    sc = _scene(S, b, transport, d, where, dispersion, discharge=discharge)
    n_cls = sc.S.size
    t = np.atleast_1d(np.asarray(t, dtype=float))
    if t.ndim != 1 or np.any(~np.isfinite(t)) or np.any(t < 0):
        raise InputError(f"t = {t!r}; expected a 1-D array of times >= 0 [s]")
    zeros = np.zeros(n_cls)
    feed = zeros if feed is None else _check_feed(feed, n_cls)
    pulse_m = zeros if pulse is None else _check_feed(pulse, n_cls)
    start_feed = None if initial_feed is None else _check_feed(initial_feed, n_cls)
    extra, cells = {}, None
    if sc.method in ("well_mixed", "cells"):
        if sc.network is None:
            sc = _scene(S, b, transport, d, where, dispersion, method="cells")
        J, B_in, C, bypass, n = _cells_system(sc, n_cls)
        y0 = B_in @ pulse_m
        if start_feed is not None:
            y0 = y0 + solve_cells(sc.S, sc.b, start_feed, sc.network, sc.d, sc.where or "discharge").holdup.T.ravel()
        Y, info, dY = _integrate_measured(J, B_in @ feed, y0, t, method, rtol, atol)
        product = Y @ C.T + bypass * feed
        cells = Y.reshape(t.size, n_cls, n).transpose(0, 2, 1)
        holdup = cells.sum(axis=1)
        time_err = (dY @ C.T, dY.reshape(t.size, n_cls, n).sum(axis=2))
        name = f"cells_{method}"
    elif sc.kind == "axial":
        J, B_in, C, hold, M = _axial_system(sc, n_cls, m_cells)
        y0 = B_in @ pulse_m  # c_0 = m / (tau w_0): the pulse mass in the inlet volume
        if start_feed is not None:
            _, c, _ = solve_axial_grid(sc.S, sc.b, start_feed, transport.tau, transport.pe, M,
                                       sc.d, sc.dispersion)
            y0 = y0 + c.T.ravel()
        Y, info, dY = _integrate_measured(J, B_in @ feed, y0, t, method, rtol, atol)
        product, holdup = Y @ C.T, Y @ hold.T
        time_err = (dY @ C.T, dY @ hold.T)
        name = f"axial_fv_{method}"
        extra["control_volumes"] = M
        # the spatial error, which the time integrator's tolerance does not see: the same
        # solve on half the volumes; the scheme is of order >= 1 in h, so |p_M - p_M/2|
        # bounds the error of p_M (pessimistic by up to 3x where it is second order)
        M2 = max(M // 2, 2)
        J2, B2, C2, hold2, _ = _axial_system(sc, n_cls, M2)
        y02 = B2 @ pulse_m
        if start_feed is not None:
            _, c2, _ = solve_axial_grid(sc.S, sc.b, start_feed, transport.tau, transport.pe, M2,
                                        sc.d, sc.dispersion)
            y02 = y02 + c2.T.ravel()
        Y2, _ = _integrate(J2, B2 @ feed, y02, t, method, rtol, atol)
        extra["spatial_error_estimate"] = float(np.abs(Y2 @ C2.T - product).max(initial=0.0))
        extra["spatial_holdup_error_estimate"] = float(np.abs(Y2 @ hold2.T - holdup).max(initial=0.0))
    elif sc.kind == "axial_open" and (np.any(feed > 0) or start_feed is not None or sc.d is not None
                                      or sc.dispersion is not None or sc.discharge == "flux"):
        # (a pulse through the unclassified, sampled open vessel is exact by segregated flow, below)
        # start-up, steps and pulses on the whole line; the spatial error as for the
        # closed vessel, from the same solve on half the volumes
        runs = []
        for M in (m_cells, max(m_cells // 2, 2)):
            J, B_in, C, D, hold, M = _axial_open_system(sc, n_cls, M)
            y0 = B_in @ pulse_m
            if start_feed is not None:
                _, c, _, _ = solve_axial_open_grid(sc.S, sc.b, start_feed, transport.tau, transport.pe, M, sc.d,
                                                   sc.dispersion, sc.discharge or "sampled")
                y0 = y0 + c.T.ravel()
            Y, info_m, dY = _integrate_measured(J, B_in @ feed, y0, t, method, rtol, atol)
            runs.append((Y @ C.T + D @ feed, Y @ hold.T, info_m, M, (dY @ C.T, dY @ hold.T)))
        (product, holdup, info, M, time_err), (product2, holdup2, _, _, _) = runs
        name = f"axial_open_fv_{method}"
        extra["control_volumes"] = M
        extra["discharge"] = sc.discharge or "sampled"
        extra["spatial_error_estimate"] = float(np.abs(product2 - product).max(initial=0.0))
        extra["spatial_holdup_error_estimate"] = float(np.abs(holdup2 - holdup).max(initial=0.0))
    elif sc.kind == "plug":
        tau = _tau(transport)
        if pulse is not None and np.any(pulse_m > 0):
            raise InputError("pulse: plug flow passes a pulse as a delta at t = tau; expected feed or "
                             "initial_feed steps (or a transport with dispersion)")
        old = zeros if start_feed is None else start_feed
        speeds = np.ones(n_cls) if sc.d is None else np.asarray(sc.d, dtype=float)
        if np.ptp(speeds) > 0:  # classes at different speeds: the fronts' sector
            from millflow.mill.plug_fronts import plug_fronts

            K = breakage_matrix(sc.S, sc.b)
            product, holdup, diff, info = plug_fronts(lambda C: C @ K.T,
                                                      lambda C: np.broadcast_to(K, (C.shape[0],) + K.shape),
                                                      speeds, tau, feed, old, t)
            extra["spatial_error_estimate"] = diff["product"]  # nodes and tolerances (plug_fronts)
            extra["spatial_holdup_error_estimate"] = diff["holdup"]
            name = "plug_flow_fronts"
        else:  # one speed v: plug flow with the residence time tau / v, exact
            tau_v = tau / speeds[0]
            after = batch_grind(sc.S, sc.b, feed, tau_v)[0]
            before = batch_grind(sc.S, sc.b, old, tau_v)[0]
            product = np.where((t >= tau_v)[:, np.newaxis], after, before)
            # hold-up: ages below min(t, tau / v) come from the new feed, older ones from the
            # old one; G(a) = int_0^a exp(K s) ds (the flux ground for its age)
            full = plug_flow(sc.S, sc.b, old, tau_v)[1]
            holdup = np.empty((t.size, n_cls))
            for k, tk in enumerate(t):
                a = min(tk, tau_v)
                if a <= 0:
                    holdup[k] = full
                    continue
                new_part = plug_flow(sc.S, sc.b, np.stack([feed, old], axis=1), a)[1]
                holdup[k] = new_part[:, 0] + full - new_part[:, 1]
            info, name = {}, "plug_flow_delay"
    else:
        if np.any(feed > 0) or start_feed is not None or sc.d is not None:
            raise InputError(f"transport {transport!r}: only a tracer pulse (no feed, no "
                             "classification) is solved for a general rtd model; expected "
                             "cells, rtd.PlugFlow or rtd.AxialDispersion for start-up and steps")
        ages = batch_grind(sc.S, sc.b, pulse_m, t)
        product = np.asarray(transport.pdf(t), dtype=float)[:, np.newaxis] * ages
        survival = 1.0 - np.asarray(transport.cdf(t), dtype=float)
        holdup = survival[:, np.newaxis] * ages
        info, name = {}, "segregated_pulse"
    runtime = time.perf_counter() - start
    coords = _size_coords(n_cls, x)
    coords["time"] = ("time", t, {"units": "s"})
    data = {
        "product": (("time", "size"), product, {"units": "mass/s", "long_name": "product (discharge) flow"}),
        "holdup": (("time", "size"), holdup, {"units": "mass", "long_name": "hold-up in the mill"}),
    }
    if cells is not None:
        coords["cell"] = ("cell", np.arange(1, cells.shape[1] + 1))
        data["cell_holdup"] = (("time", "cell", "size"), cells, {"units": "mass", "long_name": "hold-up per cell"})
    ds = xr.Dataset(data, coords=coords)
    err = hold_err = 0.0
    if name.endswith(method):  # the measured time-integration error (a 100x tighter second solve)
        err = float(np.abs(time_err[0]).max(initial=0.0))
        hold_err = float(np.abs(time_err[1]).max(initial=0.0))
        extra["time_error_estimate"] = err
    err += extra.get("spatial_error_estimate", 0.0)
    hold_err += extra.get("spatial_holdup_error_estimate", 0.0)
    from millflow.mill.steady import _GRID_NOTE

    ds.attrs.update(solver_error_estimate=err, grid_error_estimate=0.0, grid_error_method=_GRID_NOTE)
    ds.attrs.update(method=name, error_estimate=err, holdup_error_estimate=hold_err, runtime_s=runtime,
                    transport=repr(transport),
                    classification="none" if sc.d is None else f"d* at {sc.where}", **info, **extra)
    return ds
