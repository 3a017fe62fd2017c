"""Synthetic surveys of a solved flowsheet: the truth, sampled with noise from a stated error model.

Used by the tests (statistical properties of the reconciliation over replicates), the
benchmark and the docs. The sieves are edges of the flowsheet's size grid (every
``every``-th edge from the top), so the true component flows on the sieve classes are
sums of the solved class flows and close every balance exactly.

Noise (the error model of :class:`~millflow.survey.reader.ErrorModel`, SDs evaluated at
the truth): each solids and water flow times (1 + solids_rel eps); % solids plus
solids_content_sd eps; each class fraction but the pan plus its SD eps, the pan one
minus the others (as a sieve analysis normalised to its total), eps ~ N(0, 1)
independent. A class that is empty in truth (above the top size) is measured as empty.
"""
from __future__ import annotations

import numpy as np

from millflow.survey.reader import ErrorModel, PSDMeasurement, StreamMeasurement, Survey, class_fractions

__all__ = ["truth_of", "synthetic_survey"]


def truth_of(sol, sieves) -> dict:
    """True solids [kg/s], water [kg/s] and passing at ``sieves`` [m] of every stream, and circulating loads."""
    from millflow.flowsheet.results import circulating_loads
    from millflow.psd import cum_passing_at

    fs = sol.flowsheet
    out = {"solids": {}, "water": {}, "passing": {}, "solids_content": {},
           "circulating_load": circulating_loads(sol), "sieves": np.asarray(sieves, float)}
    for k, n in enumerate(fs.stream_names):
        f = np.maximum(sol.flows[k], 0.0)
        M = float(f.sum())
        out["solids"][n] = M
        out["passing"][n] = cum_passing_at(fs.grid, f / M, sieves) if M > 0 else np.full(len(sieves), np.nan)
        W = sol.water_flow(n)
        out["water"][n] = W
        out["solids_content"][n] = M / (M + W) if M + W > 0 else np.nan
    out["water_added"] = dict(fs.water_added)
    return out


def grid_sieves(grid, every: int = 8, bottom: float | None = None) -> np.ndarray:
    """Every ``every``-th upper class edge of ``grid`` from the top down to ``bottom`` [m]."""
    x = grid.x[::every]
    return x if bottom is None else x[x >= bottom * (1 - 1e-12)]


def synthetic_survey(sol, sieves, rng, *, errors: ErrorModel | None = None, solids=None, water="all",
                     psd="all", additions=(), gross: dict | None = None) -> tuple[Survey, dict]:
    """A noisy survey of the solved flowsheet ``sol`` and its truth (:func:`truth_of`).

    solids : streams whose solids flow is measured (default: the streams leaving feeds).
    water : "all" (the % solids of every stream in a wet circuit), or a list of streams.
    psd : "all" or a list of streams with a sieve analysis.
    additions : units whose water addition is measured.
    gross : {"stream": name, "class": j, "sd": 10} adds a gross error of that many SDs
        to class j of that stream's analysis (or, with ``"solids": True`` or
        ``"solids_content": True`` in place of ``"class"``, to its solids flow or its % solids).
    """
    fs = sol.flowsheet
    errors = errors or ErrorModel()
    truth = truth_of(sol, sieves)
    if solids is None:
        solids = [n for n, s in fs.streams.items() if fs.units[s.source].type == "feed"]
    wet = sol.water is not None and any(truth["water"][n] > 0 for n in fs.stream_names)
    water = (fs.stream_names if water == "all" else list(water)) if wet else []
    psd = fs.stream_names if psd == "all" else list(psd)
    gross = gross or {}
    streams = {}
    for n in fs.stream_names:
        kw = {}
        if n in solids:
            M = truth["solids"][n]
            k = gross.get("sd", 10.0) if gross.get("stream") == n and gross.get("solids") else 0.0
            sd = errors.solids_rel * M
            kw.update(solids=M + sd * (rng.standard_normal() + k), solids_sd=sd, solids_rel=errors.solids_rel)
        if n in water:
            c = truth["solids_content"][n]
            k = gross.get("sd", 10.0) if gross.get("stream") == n and gross.get("solids_content") else 0.0
            kw.update(solids_content=c + errors.solids_content_sd * (rng.standard_normal() + k),
                      solids_content_sd=errors.solids_content_sd)
        if n in psd:
            f = class_fractions(truth["passing"][n])
            sd_true = errors.fraction_sd(f)
            noisy = f.copy()
            eps = rng.standard_normal(f.size - 1)
            if gross.get("stream") == n and "class" in gross:
                eps[gross["class"]] += gross.get("sd", 10.0)
            noisy[:-1] = np.where(f[:-1] > 0, f[:-1] + sd_true[:-1] * eps, 0.0)
            noisy[-1] = 1.0 - noisy[:-1].sum()
            passing = 1.0 - np.cumsum(noisy)[:-1]
            kw["psd"] = PSDMeasurement(np.asarray(sieves, float), passing, errors.fraction_sd(noisy),
                                       (errors.psd_sd, errors.psd_floor))
        if kw:
            streams[n] = StreamMeasurement(n, **kw)
    adds = {u: (None, None) for u in fs.water_added}
    for u in additions:
        v = fs.water_added[u]
        sd = errors.water_rel * v
        adds[u] = (v + sd * rng.standard_normal(), sd)
    return Survey(fs, streams, adds if wet else {}, errors, "synthetic survey", "<synthetic>"), truth
