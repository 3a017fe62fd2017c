"""Results of a solved flowsheet: xarray Dataset, tables, summary and the output folder.

Everything is computed from :class:`~millflow.flowsheet.solve.FlowsheetSolution`
(stream flows per size class [kg/s] and unit reports). Per stream: solids rate,
mass fractions and cumulative passing on the grid, P80, P50 and % passing named sizes
(monotone PCHIP interpolation in log size, :mod:`millflow.psd`). Per unit: method,
error estimate, run time and mass balance error |out - in| / in. Circulating load of each
recycle stream (one leaving a classifier or splitter and returning into its loop): its
flow over the loop's new feed (U/F_new of a closed-circuit cyclone).
Specific energy of a mill [kWh/t] = power [kW] /
mill throughput [t/h]; of the circuit = total mill power / total product rate.

:func:`to_dataset` keeps SI units (attributes ``units`` and ``long_name`` on every
variable); tables, ``summary.json`` and the terminal use um and t/h.
"""
from __future__ import annotations

import json
import math
from bisect import bisect_right
from itertools import accumulate, repeat
from operator import neg, truediv
from pathlib import Path

import numpy as np

from millflow.errors import GridError
from millflow.flowsheet.water import slurry_properties
from millflow.psd import _crossing, _fix_sum, _percentiles_of_cum, cum_passing, cum_passing_at

__all__ = ["stream_properties", "circulating_loads", "mass_balance", "to_dataset", "summary", "key_figures",
           "error_report", "stream_table", "unit_table", "psd_table", "save"]

TPH = 3.6  # kg/s -> t/h


def _p80_p50(x, cum) -> tuple[float, float]:
    """P80 and P50 [m] from cumulative passing.

    P80 and P50 [m] from the cumulative passing of a PSD made here (non-negative,
    summing to 1: not validated again); NaN for one that lies in the sink (unknown on
    this grid).
    """
    P = cum.copy()
    P[0] = 1.0
    try:
        p80, p50 = _percentiles_of_cum(x, P, np.array([80.0, 50.0]))
        return float(p80), float(p50)
    except GridError:  # at least P50 is in the sink
        try:
            return float(_percentiles_of_cum(x, P, np.array([80.0]))[0]), float("nan")
        except GridError:
            return float("nan"), float("nan")


def stream_properties(sol) -> dict:
    """Properties of each stream.

    Per stream: ``solids_kg_s``, ``fraction``, ``cum_passing``, ``p80_m``, ``p50_m``,
    ``passing`` (at named sizes).
    """
    fs = sol.flowsheet
    out = {}
    for k, name in enumerate(fs.stream_names):
        f = sol.flows[k]
        total = math.fsum(f)
        n = fs.grid.n
        if total > 0:
            # rounding-level negatives of the linear solve (mass balance is reported
            # separately); the sum residual goes to the largest class as in psd
            frac = _fix_sum(np.maximum(f, 0.0) / math.fsum(np.maximum(f, 0.0)))
            cum = cum_passing(frac)
            p80, p50 = _p80_p50(fs.grid.x, cum)
            passing = (cum_passing_at(fs.grid, frac, np.array(fs.passing_sizes)) if fs.passing_sizes
                       else np.zeros(0))
            # below the finest edge the grid cannot tell how the sink's mass is spread:
            # not the value at x_N, but unknown ("-" in the table, null in JSON), as P80
            below = np.asarray(fs.passing_sizes, dtype=float) < fs.grid.x[-1] * (1 - 1e-12)
            passing = np.where(below, np.nan, passing) if passing.size else passing
        else:
            frac = cum = np.full(n, np.nan)
            p80 = p50 = float("nan")
            passing = np.full(len(fs.passing_sizes), np.nan)
        out[name] = {"solids_kg_s": total, "fraction": frac, "cum_passing": cum, "p80_m": p80, "p50_m": p50,
                     "passing": np.asarray(passing, dtype=float)}
        if is_wet(sol):
            water = sol.water_flow(name)
            out[name].update(water_kg_s=water, **slurry_properties(total, water, fs.slurry))
    return out


def is_wet(sol) -> bool:
    """True when any stream carries water (a wet circuit): results then show the slurry."""
    return sol.water is not None and bool(np.any(sol.water.flows > 0))


def recycle_streams(fs) -> list[str]:
    """The streams that close recycle loops.

    Back edges of a depth-first walk of each loop from where its new feed enters, following
    streams in file order (for a ball mill with cyclones, the underflow; a splitter's
    returning branch is another).
    """
    return list(_loops(fs)[1])


def _loops(fs) -> tuple:
    """Loop label per unit and the recycle streams, computed once per connection pattern.

    (loop label per unit, recycle streams) of the flowsheet's connections, computed once
    per connection pattern: a sweep's cases share their base flowsheet's streams.
    """
    got = _LOOPS.get(id(fs.streams))
    if got is None or got[0] is not fs.streams or got[1] != tuple(fs.units):
        lab = dict(zip(fs.units, fs.components()))
        got = (fs.streams, tuple(fs.units), lab, tuple(_recycle_streams(fs, lab)))
        if len(_LOOPS) >= 64:
            _LOOPS.pop(next(iter(_LOOPS)))
        _LOOPS[id(fs.streams)] = got  # holds the streams: their id is not reused while kept
    return got[2], got[3]


_LOOPS: dict = {}


def _recycle_streams(fs, lab) -> list[str]:
    out, seen = [], set()
    entries = [st.target for st in fs.streams.values() if lab[st.source] != lab[st.target]]
    for start in entries:
        if start in seen:
            continue
        stack, on_path = [(start, iter(fs.outlets(start)))], {start}
        seen.add(start)
        while stack:
            unit, it = stack[-1]
            s = next(it, None)
            if s is None:
                stack.pop()
                on_path.discard(unit)
                continue
            nxt = fs.streams[s].target
            if lab[nxt] != lab[unit]:
                continue
            if nxt in on_path:
                out.append(s)
            elif nxt not in seen:
                seen.add(nxt)
                on_path.add(nxt)
                stack.append((nxt, iter(fs.outlets(nxt))))
    return [s for s in fs.stream_names if s in out]


def circulating_loads(sol) -> dict:
    """Circulating load [-] of each recycle stream.

    Circulating load [-] of each recycle stream (:func:`recycle_streams`), as the engineer
    reads it: the stream's solids flow over the new feed of its recycle loop (the solids of
    the streams entering the loop from outside). For a closed ball-mill/cyclone circuit this
    is U/F_new (= U/O at steady state).
    """
    fs = sol.flowsheet
    return _circulating(fs, {n: math.fsum(sol.flows[k]) for k, n in enumerate(fs.stream_names)})


def _circulating(fs, tot) -> dict:
    lab, recycles = _loops(fs)
    new_feed = {}
    for n, st in fs.streams.items():
        if lab[st.source] != lab[st.target]:
            new_feed[lab[st.target]] = new_feed.get(lab[st.target], 0.0) + tot[n]
    out = {}
    for n in recycles:
        fresh = new_feed.get(lab[fs.streams[n].source], 0.0)
        out[n] = tot[n] / fresh if fresh > 0 else float("nan")
    return out


def mass_balance(sol) -> dict:
    """Relative mass balance errors, overall and per unit, of the solids and the water.

    Relative mass balance errors: ``overall`` (products vs feeds) and per unit, of the solids
    and (``water``, ``water_units``) of the water.
    """
    fs = sol.flowsheet
    tot = {n: math.fsum(sol.flows[k]) for k, n in enumerate(fs.stream_names)}
    feed = math.fsum(u.solids for u in fs.units.values() if u.type == "feed")
    prod = math.fsum(tot[s] for n, u in fs.units.items() if u.type == "product" for s in fs.inlets(n))
    out = {"overall": abs(prod - feed) / feed if feed > 0 else 0.0,
           "units": {n: r["mass_balance_error"] for n, r in sol.units.items()}}
    if sol.water is not None:
        out["water"] = sol.water.overall_error
        out["water_units"] = {n: r["water_balance_error"] for n, r in sol.water.units.items()}
    return out


def _specific_energy(sol) -> float | None:
    fs = sol.flowsheet
    power = [u.power for u in fs.units.values() if u.type == "mill" and u.power is not None]
    if not power:
        return None
    prod = math.fsum(math.fsum(sol.flow(s)) for n, u in fs.units.items() if u.type == "product"
                     for s in fs.inlets(n))
    return (math.fsum(power) / 1e3) / (prod * TPH) if prod > 0 else float("nan")


def to_dataset(sol, props=None, grid_check=None):
    """The solution as an xarray Dataset with dimensions ``stream``, ``size`` (and ``unit``, ``classifier``).

    Built from numpy arrays by :func:`millflow._dataset.dataset` (no merge or alignment,
    no dask import: the same Dataset ``xr.Dataset`` would make).
    """
    from millflow._dataset import dataset

    fs = sol.flowsheet
    props = props or stream_properties(sol)
    names = fs.stream_names
    size = fs.grid.size_coord()
    coords = {"stream": ("stream", np.array(names), {"long_name": "stream name"}),
              "size": ("size", size.values, dict(size.attrs))}
    data = {}

    def var(dims, values, units, long_name):
        return (dims, np.asarray(values), {"units": units, "long_name": long_name})

    data["mass_flow"] = var(("stream", "size"), sol.flows, "kg/s", "solids mass flow per size class")
    data["mass_fraction"] = var(("stream", "size"), [props[n]["fraction"] for n in names], "1",
                                "mass fraction per size class")
    data["cum_passing"] = var(("stream", "size"), [props[n]["cum_passing"] for n in names], "1",
                              "cumulative mass fraction passing the upper class size")
    data["solids"] = var("stream", [props[n]["solids_kg_s"] for n in names], "kg/s", "solids mass flow")
    data["p80"] = var("stream", [props[n]["p80_m"] for n in names], "m", "80 % passing size")
    data["p50"] = var("stream", [props[n]["p50_m"] for n in names], "m", "50 % passing size")
    gs = (grid_check or {}).get("streams")
    if gs:
        for key in ("p80", "p50"):
            data[f"{key}_grid_error"] = var("stream", [gs[n][f"{key}_grid_error"] for n in names], "1",
                                            f"relative grid error of {key.upper()} (Richardson, two-grid GCI)")
    data["source"] = var("stream", [f"{fs.streams[n].source}.{fs.streams[n].port}" for n in names], "",
                         "unit and outlet the stream leaves")
    data["target"] = var("stream", [fs.streams[n].target for n in names], "", "unit the stream enters")
    if is_wet(sol):
        data["water"] = var("stream", [props[n]["water_kg_s"] for n in names], "kg/s", "water mass flow")
        data["solids_content"] = var("stream", [props[n]["solids_content"] for n in names], "1",
                                     "solids mass fraction of the slurry")
        if fs.slurry is not None:
            data["volume_flow"] = var("stream", [props[n]["volume_flow_m3_s"] for n in names], "m3/s",
                                      "volumetric slurry flow")
            data["pulp_density"] = var("stream", [props[n]["pulp_density_kg_m3"] for n in names], "kg/m3",
                                       "slurry (pulp) density")
    if fs.passing_sizes:
        coords["named_size"] = ("named_size", np.array(fs.passing_sizes, dtype=float),
                                {"units": "m", "long_name": "size for % passing"})
        data["passing_named"] = var(("stream", "named_size"), [props[n]["passing"] for n in names], "1",
                                    "cumulative mass fraction passing the named size")
    units = list(fs.units)
    coords["unit"] = ("unit", np.array(units), {"long_name": "unit name"})
    data["unit_type"] = var("unit", [sol.units[u]["type"] for u in units], "", "unit type")
    data["unit_method"] = var("unit", [sol.units[u]["method"] for u in units], "", "method of the unit model")
    data["unit_mass_balance_error"] = var("unit", [sol.units[u]["mass_balance_error"] for u in units], "1",
                                          "relative mass balance error |out - in| / in")
    data["unit_error_estimate"] = var("unit", [sol.units[u]["error_estimate"] for u in units], "1",
                                      "error estimate of the unit model")
    data["unit_runtime"] = var("unit", [sol.units[u]["runtime_s"] for u in units], "s", "run time of the unit model")
    for key, name, unit_of, long_name in (("tau_s", "unit_tau", "s", "mean residence time of the mill"),
                                          ("holdup_kg", "unit_holdup", "kg", "solids hold-up of the mill"),
                                          ("power_kW", "unit_power", "kW", "mill power draw"),
                                          ("specific_energy_kWh_per_t", "unit_specific_energy", "kWh/t",
                                           "mill specific energy"),
                                          ("cyclones", "unit_cyclones", "1", "number of cyclones in the cluster"),
                                          ("d50c_m", "unit_d50c", "m", "corrected cut size of the classifier"),
                                          ("pressure_Pa", "unit_pressure", "Pa", "cyclone inlet pressure drop"),
                                          ("flow_per_cyclone_m3_s", "unit_flow_per_cyclone", "m3/s",
                                           "slurry feed flow per cyclone"),
                                          ("underflow_solids_content", "unit_underflow_solids_content", "1",
                                           "solids mass fraction of the cyclone underflow"),
                                          ("underflow_solids_volume_fraction", "unit_underflow_solids_volume",
                                           "1", "solids volume fraction of the cyclone underflow (roping "
                                                "above about 0.50-0.55)")):
        vals = [sol.units[u].get(key) for u in units]
        if any(v is not None for v in vals):
            data[name] = var("unit", np.array([np.nan if v is None else v for v in vals], dtype=float), unit_of,
                             long_name)
    for key, name, long_name in (("breakage_basis", "unit_breakage_basis", "mill breakage per time or per energy"),
                                 ("tau_from", "unit_tau_from", "how the mill's residence time is set"),
                                 ("power_role", "unit_power_role", "whether the mill power enters its kinetics")):
        vals = [sol.units[u].get(key) for u in units]
        if any(v is not None for v in vals):
            data[name] = var("unit", ["" if v is None else v for v in vals], "", long_name)
    if sol.water is not None and is_wet(sol):
        data["unit_water_in"] = var("unit", [sol.water.units[u]["water_in_kg_s"] for u in units], "kg/s",
                                    "water entering the unit (with its addition)")
        data["unit_water_balance_error"] = var("unit", [sol.water.units[u]["water_balance_error"] for u in units],
                                               "1", "relative water balance error |out - in| / in")
    cls = [u for u, unit in fs.units.items() if unit.type == "classifier"]
    if cls:
        coords["classifier"] = ("classifier", np.array(cls), {})
        data["efficiency"] = var(("classifier", "size"), [sol.unit_blocks[u][fs.units[u].ports[0]] for u in cls], "1",
                                 "fraction of each size to the coarse stream (partition curve)")
    ds = dataset(data, coords)
    mb = mass_balance(sol)
    ds.attrs.update({
        "title": fs.title, "source_file": fs.source_file,
        "method": sol.solver["method"], "structure": sol.solver["structure"],
        "relative_residual": sol.solver["relative_residual"], "runtime_s": sol.runtime_s,
        "mass_balance_error": mb["overall"],
        "water_balance_error": mb.get("water", 0.0),
        "circulating_load": json.dumps(circulating_loads(sol)),
        "tear": json.dumps(sol.solver["tear"]) if sol.solver["tear"] else "none (all units linear)",
        "kernel": _kernel_status(),
        **_provenance(fs),
        "grid_check": json.dumps(_clean(grid_check)) if grid_check else "not run",
        "error_estimate": json.dumps(_clean(error_report(sol, grid_check))),
        "conventions": "class 1 coarsest, class N the sink; size = upper class edge (Austin); continuous forms "
                       f"put on the grid by scheme {fs.grid.scheme!r}",
    })
    return ds


def _clean(v):
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_clean(x) for x in np.asarray(v, dtype=object).tolist()] if not isinstance(v, (list, tuple)) \
            else [_clean(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return None if not math.isfinite(float(v)) else float(v)
    if isinstance(v, np.integer):
        return int(v)
    return v


def _provenance(fs) -> dict:
    """The millflow version and the SHA-256 of the input file (hashed once, when it was read)."""
    from millflow import __version__

    out = {"millflow_version": __version__}
    if fs.meta.get("input_sha256"):
        out["input_sha256"] = fs.meta["input_sha256"]
    return out


def _kernel_status() -> str:
    """Which kernel ran each compiled piece (compiled C or numpy), as every result says."""
    from millflow.compiled import status

    return status()


def error_report(sol, grid_check=None) -> dict:
    """The error estimate of a solved flowsheet split by source: solver and size grid.

    The error estimate of a solved flowsheet split by source: ``solver`` (the largest of
    the recycle solve's relative residual and the units' error estimates) and ``grid``
    (the largest relative grid error of P80, P50 and circulating loads from the grid
    check, :mod:`millflow.flowsheet.gridcheck`), each with the method that estimated it.
    """
    unit_err = max((float(r.get("error_estimate") or 0.0) for r in sol.units.values()), default=0.0)
    solver = {"value": max(float(sol.solver.get("relative_residual") or 0.0), unit_err),
              "method": "largest of the recycle solve's relative residual and the units' own error estimates"}
    g = grid_check or {}
    if g.get("status") in ("ok", "grid too coarse"):
        grid = {"value": g["worst"], "at": g["worst_at"], "method": g["method"]}
    else:
        grid = {"value": None, "method": "not estimated (grid check not run)"}
    return {"solver": solver, "grid": grid}


def summary(sol, props=None, grid_check=None) -> dict:
    """JSON-ready summary: streams, circulating_load, mass_balance_error, specific energy, units, runtime_s."""
    fs = sol.flowsheet
    props = props or stream_properties(sol)
    streams = {}
    for n in fs.stream_names:
        p = props[n]
        s = fs.streams[n]
        streams[n] = {
            "from": f"{s.source}.{s.port}", "to": s.target,
            "solids_tph": p["solids_kg_s"] * TPH,
            "p80_um": p["p80_m"] * 1e6, "p50_um": p["p50_m"] * 1e6,
            "passing_pct": {f"{x * 1e6:g}": v * 100 for x, v in zip(fs.passing_sizes, p["passing"])},
            "size_um": fs.grid.x * 1e6, "cum_passing": p["cum_passing"],
        }
        gs = (grid_check or {}).get("streams", {}).get(n)
        if gs:  # relative grid errors (Richardson + GCI) and the converged values
            streams[n].update(p80_grid_error=gs["p80_grid_error"], p50_grid_error=gs["p50_grid_error"],
                              p80_converged_um=gs["p80_converged_um"], p50_converged_um=gs["p50_converged_um"])
        if "water_kg_s" in p:
            streams[n].update(water_tph=p["water_kg_s"] * TPH, solids_content_pct=p["solids_content"] * 100)
            if "volume_flow_m3_s" in p:
                streams[n].update(volume_flow_m3_h=p["volume_flow_m3_s"] * 3600,
                                  pulp_density_t_m3=p["pulp_density_kg_m3"] / 1000)
    mb = mass_balance(sol)
    units = {}
    for u, r in sol.units.items():
        units[u] = {k: v for k, v in r.items() if k not in ("solids_in_kg_s", "solids_out_kg_s")}
        units[u]["solids_in_tph"] = r["solids_in_kg_s"] * TPH
        for k in ("water_in_kg_s", "water_added_kg_s", "water_out_kg_s"):
            if k in units[u]:
                units[u][k.replace("_kg_s", "_tph")] = units[u].pop(k) * TPH
    return _clean({
        "title": fs.title, "source_file": fs.source_file,
        "grid": {"n": fs.grid.n, "top_um": fs.grid.x[0] * 1e6, "sink_below_um": fs.grid.x[-1] * 1e6},
        "streams": streams,
        "circulating_load": circulating_loads(sol),
        "mass_balance_error": mb["overall"],
        "unit_mass_balance_error": mb["units"],
        "water_balance_error": mb.get("water", 0.0),
        "specific_energy_kWh_per_t": _specific_energy(sol),
        "units": units,
        "notes": notes(sol),
        "model_range": [m for r in sol.units.values() for m in (r.get("out_of_range") or [])],
        "solver": {k: v for k, v in sol.solver.items()},
        "kernel": _kernel_status(),
        **_provenance(fs),
        "grid_check": grid_check,
        "error_estimate": error_report(sol, grid_check),
        "runtime_s": sol.runtime_s,
    })


def key_figures(sol, streams=None) -> dict:
    """The numbers a sweep keeps of a solved case, as :func:`summary` gives them.

    The numbers a sweep keeps of a solved case, as :func:`summary` gives them (the same
    arithmetic), without the rest of the summary: ``p80_um`` and ``p50_um`` of ``streams``
    (default: every stream), ``circulating_load``, ``specific_energy_kWh_per_t`` and
    ``mass_balance_error``.

    A sweep calls it once per case, so it works in Python floats on the few streams it
    needs (the kept streams, the products' inlets, the recycle loops' streams), the
    flowsheet's connections read once per connection pattern (:func:`_figure_plan`); the
    sums are exact (``math.fsum``) and the P80 / P50 reading is
    :func:`millflow.psd.percentile_sizes`' own (cumulative passing summed from the fine end,
    the same interpolating cubic and root).
    """
    fs = sol.flowsheet
    plan = _figure_plan(fs)
    index, flows, x = plan["index"], sol.flows, fs.grid.x
    rows, tot = {}, {}
    for n in plan["summed"] if streams is None else (*plan["summed"], *streams):
        if n not in tot:
            rows[n] = row = flows[index[n]].tolist()
            tot[n] = math.fsum(row)
    p80, p50 = {}, {}
    lx = None
    for n in (plan["names"] if streams is None else streams):
        if n not in tot:
            rows[n] = row = flows[index[n]].tolist()
            tot[n] = math.fsum(row)
        if tot[n] > 0:  # as stream_properties: rounding-level negatives cut, the sum's residual placed
            if lx is None:
                lx = _log_sizes(x)
            a, b = _p80_p50_floats(x, lx, rows[n], tot[n])
        else:
            a = b = float("nan")
        p80[n], p50[n] = _finite(a * 1e6), _finite(b * 1e6)
    feed = math.fsum(u.solids for u in fs.units.values() if u.type == "feed")
    prod = math.fsum(tot[n] for n in plan["product_inlets"])
    power = [u.power for u in fs.units.values() if u.type == "mill" and u.power is not None]
    energy = None if not power else ((math.fsum(power) / 1e3) / (prod * TPH) if prod > 0 else float("nan"))
    loads = {}
    for n in plan["recycles"]:  # as _circulating: the stream over its loop's new feed
        fresh = math.fsum(tot[s] for s in plan["new_feed"][n]) if plan["new_feed"][n] else 0.0
        loads[n] = _finite(tot[n] / fresh if fresh > 0 else float("nan"))
    return {"p80_um": p80, "p50_um": p50, "circulating_load": loads,
            "specific_energy_kWh_per_t": None if energy is None else _finite(energy),  # as _specific_energy
            "mass_balance_error": _finite(abs(prod - feed) / feed if feed > 0 else 0.0)}  # as mass_balance


def _figure_plan(fs) -> dict:
    """What :func:`key_figures` reads of the flowsheet's connections.

    Read once per connection
    pattern (kept with :func:`_loops`' result): stream indices, the streams entering
    product units, the recycle streams and, per recycle stream, the streams that bring its
    loop's new feed.
    """
    got = _PLANS.get(id(fs.streams))
    types = tuple(u.type for u in fs.units.values())
    if got is None or got[0] is not fs.streams or got[1] != tuple(fs.units) or got[2] != types:
        lab, recycles = _loops(fs)
        entering = {}
        for n, st in fs.streams.items():
            if lab[st.source] != lab[st.target]:
                entering.setdefault(lab[st.target], []).append(n)
        names = fs.stream_names
        product_inlets = tuple(n for n, st in fs.streams.items() if fs.units[st.target].type == "product")
        new_feed = {n: tuple(entering.get(lab[fs.streams[n].source], ())) for n in recycles}
        summed = (*product_inlets, *recycles, *(s for v in new_feed.values() for s in v))
        plan = {"index": {n: k for k, n in enumerate(names)}, "names": tuple(names),
                "product_inlets": product_inlets, "recycles": recycles, "new_feed": new_feed,
                "summed": tuple(dict.fromkeys(summed))}
        got = (fs.streams, tuple(fs.units), types, plan)
        if len(_PLANS) >= 64:
            _PLANS.pop(next(iter(_PLANS)))
        _PLANS[id(fs.streams)] = got  # holds the streams: their id is not reused while kept
    return got[3]


_PLANS: dict = {}


def _log_sizes(x) -> list:
    """Ln x of a grid's edges as Python floats (kept for the last grid asked)."""
    kept = _LOG_X
    if kept and kept[0] is x:
        return kept[1]
    lx = np.log(x).tolist()
    _LOG_X[:] = [x, lx]
    return lx


_LOG_X: list = []


def _p80_p50_floats(x, lx: list, row: list, total: float) -> tuple[float, float]:
    """P80 and P50 of the flows ``row`` as :func:`_p80_p50` reads them, in Python floats.

    ``total`` is the rows' exact sum (> 0). The same arithmetic as
    ``_p80_p50(x, cum_passing(_fix_sum(g / fsum(g))))`` with g the flows cut at 0: the
    fractions summed from the fine end (numpy's cumsum is that sequential sum), the
    crossing edge found by bisection on the non-increasing cumulative passing, the
    crossing by :func:`millflow.psd._crossing`.
    """
    if min(row) >= 0.0:
        g, s = row, total
    else:
        g = [v if v >= 0.0 else 0.0 for v in row]
        s = math.fsum(g)
    if not math.isfinite(s):
        return _p80_p50(x, cum_passing(_fix_sum(np.array(g) / s)))
    f = list(map(truediv, g, repeat(s, len(g))))
    k = f.index(max(f))
    f[k] += 1.0 - math.fsum(f)
    P = list(accumulate(reversed(f)))
    P.reverse()
    P[0] = 1.0
    out = []
    for q in (0.8, 0.5):
        if P[-1] >= q:  # as _percentiles_of_cum's GridError: P50 (or both) in the sink
            out.append(float("nan"))
            continue
        # the last edge with P >= q (the crossing lies below it): P[1:] sums non-negative
        # fractions, so P >= q holds on a leading run of edges (P[0] = 1 >= q, also where
        # P[1] rounds above 1) and bisection finds that run's end, as numpy's searchsorted
        j = bisect_right(P, -q, key=neg) - 1
        out.append(float(x[j]) if P[j] == q else math.exp(_crossing(lx, P, j, q)))
    return out[0], out[1]


def _finite(v) -> float | None:
    """A float as JSON reads it (as :func:`_clean`): None when not finite."""
    v = float(v)
    return v if math.isfinite(v) else None


def _cyclone_columns(r) -> dict:
    """Cyclone operation as numbers (units.csv): count, d50c, pressure, flow per cyclone, underflow solids."""
    def scaled(key, factor):
        v = r.get(key)
        return None if v is None else v * factor

    return {"cyclones": r.get("cyclones"), "d50c_um": scaled("d50c_m", 1e6),
            "pressure_kPa": scaled("pressure_Pa", 1e-3),
            "flow_per_cyclone_m3_h": scaled("flow_per_cyclone_m3_s", 3600.0),
            "underflow_solids_pct_w": scaled("underflow_solids_content", 100.0),
            "underflow_solids_pct_v": scaled("underflow_solids_volume_fraction", 100.0)}


def notes(sol) -> list[str]:
    """What a reader of the results must know once: mills whose power is information only.

    (Models used outside their range are warned, :class:`millflow.errors.ModelRangeWarning`, and
    listed in the summary's ``model_range``.)
    """
    out = []
    for u, unit in sol.flowsheet.units.items():
        if unit.type == "mill" and getattr(unit, "power_role", None) and unit.breakage_basis != "energy":
            out.append(f"{u}: power {unit.power / 1e3:.4g} kW is information only: the mill's rates are per time "
                       "(1/s), so power does not enter its breakage and its kWh/t is not causal; give the rates per "
                       "energy (rate A_E_t_per_kWh, or the material's per_energy) for power to drive the product")
    return out


def stream_table(sol, props=None):
    """A pandas DataFrame of one row per stream (t/h, P80 and P50 in um, % passing named sizes)."""
    import pandas as pd

    fs = sol.flowsheet
    props = props or stream_properties(sol)
    rows = []
    for n in fs.stream_names:
        p, s = props[n], fs.streams[n]
        row = {"stream": n, "from": f"{s.source}.{s.port}", "to": s.target, "solids_tph": p["solids_kg_s"] * TPH}
        if "water_kg_s" in p:
            row.update(water_tph=p["water_kg_s"] * TPH, solids_content_pct=p["solids_content"] * 100)
            if "volume_flow_m3_s" in p:
                row.update(volume_flow_m3_h=p["volume_flow_m3_s"] * 3600,
                           pulp_density_t_m3=p["pulp_density_kg_m3"] / 1000)
        row.update(p80_um=p["p80_m"] * 1e6, p50_um=p["p50_m"] * 1e6)
        for x, v in zip(fs.passing_sizes, p["passing"]):
            row[f"passing_{x * 1e6:g}um_pct"] = v * 100
        rows.append(row)
    return pd.DataFrame(rows).set_index("stream")


def unit_table(sol):
    """A pandas DataFrame of one row per unit (type, method, error estimate, run time, mass balance, energy)."""
    import pandas as pd

    from millflow.report.html import method_text  # numbers in the text at the CSV's 10 digits

    rows = []
    for u, r in sol.units.items():
        rows.append({"unit": u, "type": r["type"], "method": method_text(r["method"], 10),
                     "solids_in_tph": r["solids_in_kg_s"] * TPH,
                     "mass_balance_error": r["mass_balance_error"], "error_estimate": r["error_estimate"],
                     "runtime_s": r["runtime_s"], "tau_min": r["tau_s"] / 60 if r.get("tau_s") else None,
                     "holdup_t": r["holdup_kg"] / 1e3 if r.get("holdup_kg") else None, "power_kW": r.get("power_kW"),
                     "specific_energy_kWh_per_t": r.get("specific_energy_kWh_per_t"),
                     **_cyclone_columns(r),
                     "breakage_basis": r.get("breakage_basis"), "tau_from": r.get("tau_from"),
                     "power_role": r.get("power_role")})
    return pd.DataFrame(rows).set_index("unit")


def psd_table(sol, props=None):
    """A pandas DataFrame of the cumulative passing [%] of every stream at every grid size."""
    import pandas as pd

    fs = sol.flowsheet
    props = props or stream_properties(sol)
    data = {f"{n}_passing_pct": props[n]["cum_passing"] * 100 for n in fs.stream_names}
    df = pd.DataFrame(data, index=pd.Index(fs.grid.x * 1e6, name="size_um"))
    return df


def write_netcdf(ds, path) -> None:
    """Write a Dataset to netCDF-3 without xarray's probe for a dask scheduler.

    ``ds.to_netcdf(path, engine="scipy")`` (netCDF-3, 64-bit offsets) without xarray's
    probe for a dask scheduler: ``to_netcdf`` imports dask and dask.distributed when they
    are installed (about half a second of a command's start-up) to choose a file lock.
    Our datasets hold numpy arrays only, so a plain lock is the right one.
    """
    import threading

    from xarray.backends import ScipyDataStore

    store = ScipyDataStore(str(path), mode="w", lock=threading.Lock())
    try:
        ds.dump_to_store(store)
    finally:
        store.close()


#: CSV number format: 10 significant digits. The solve is exact to ~1e-13 relative, so
#: digits past the 10th are rounding noise (100.00000000000003 is written 100).
CSV_FLOAT_FORMAT = "%.10g"


def save(sol, out_dir, *, plots: bool = True, grid_check=None, props=None) -> dict:
    """Write results.nc, streams.csv, units.csv, psd.csv, summary.json (and PNG plots) to ``out_dir``.

    ``props``: :func:`stream_properties` of ``sol`` if the caller has them already.
    Returns a dict name -> path of the files written.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    props = props or stream_properties(sol)
    files = {}
    ds = to_dataset(sol, props, grid_check)
    files["netcdf"] = out / "results.nc"
    write_netcdf(ds, files["netcdf"])
    files["streams_csv"] = out / "streams.csv"
    stream_table(sol, props).to_csv(files["streams_csv"], float_format=CSV_FLOAT_FORMAT)
    files["units_csv"] = out / "units.csv"
    unit_table(sol).to_csv(files["units_csv"], float_format=CSV_FLOAT_FORMAT)
    files["psd_csv"] = out / "psd.csv"
    psd_table(sol, props).to_csv(files["psd_csv"], float_format=CSV_FLOAT_FORMAT)
    files["summary"] = out / "summary.json"
    files["summary"].write_text(json.dumps(summary(sol, props, grid_check), indent=2), encoding="utf-8")
    if plots:
        from millflow.flowsheet.plots import save_plots

        files.update(save_plots(sol, ds, out))
    return files
