"""Predictive validation (Principle VI): leave conditions out, fit the rest, predict them.

The error measure is the RMSE of cumulative passing at every measured row of each
held-out condition, the model curve interpolated linearly in size (with P = 0 at size
0 and P = 1 above the grid top): the metric of the SPRITE knife-mill README, and a
natural one for any sieve data.
"""
from __future__ import annotations

import multiprocessing as mp
import os
from concurrent.futures import ProcessPoolExecutor

import numpy as np

from millflow.errors import InputError
from millflow.fitting.estimate import fit
from millflow.fitting.progress import reporter
from millflow.fitting.models import ForwardModel

__all__ = ["leave_out", "nested_leave_out", "condition_rmse", "CRITERIA"]

#: Criteria by which :func:`nested_leave_out` chooses a structure inside a fold.
CRITERIA = ("aic", "aicc", "bic")


def condition_rmse(model: ForwardModel, theta) -> dict:
    """RMSE of cumulative passing per condition of ``model`` at parameters ``theta``."""
    r = model.predict_cum(np.asarray(theta, float)) - model.y_cum
    return {c: float(np.sqrt(np.mean(r[model.condition_of_value == c] ** 2))) for c in model.conditions}


def leave_out(model: ForwardModel, params: dict | None, held_out="each", *, progress=None, quiet: bool = False,
              workers: int | None = None, **fit_kwargs) -> dict:
    """Fit without some conditions and predict them.

    Parameters
    ----------
    model : the forward model on all conditions (its grid is reused).
    params : parameter dict (start values and bounds) or None for defaults.
    held_out : ``"each"`` (leave one condition out at a time), a list of condition
        names (held out together, one fit), or a list of lists (one fit per group).
    workers : processes that fit folds at the same time (default: the processor count,
        at most the number of folds; 1 fits them one after the other in this process).
        The folds are independent fits, so the result is the same either way; the
        workers are forked, which needs a platform that forks (Linux, macOS): elsewhere
        the folds run in this process.
    fit_kwargs : passed to :func:`~millflow.fitting.estimate.fit` (each fold runs the
        full search: nothing from the held-out data reaches the fold's fit).

    Returns
    -------
    dict with ``folds`` (list of {held_out, rmse: {condition: value}, params}),
    ``rmse`` (condition -> prediction RMSE) and ``mean_rmse``.
    """
    say = reporter(progress, quiet, "leave_out")
    conds = model.conditions
    groups = _groups(conds, held_out)
    if workers is not None and (isinstance(workers, bool) or not isinstance(workers, (int, np.integer))
                                or workers < 1):
        raise InputError(f"leave_out: workers = {workers!r}; expected a whole number >= 1")
    n_workers = min(len(groups), int(workers or os.cpu_count() or 1))
    job = (model, params, groups, fit_kwargs)
    if n_workers > 1 and "fork" in mp.get_all_start_methods():
        _JOB[:] = [job]  # the forked workers inherit it: nothing is pickled but the fold's index and result
        try:
            with ProcessPoolExecutor(n_workers, mp_context=mp.get_context("fork")) as pool:
                futures = [pool.submit(_fold, k) for k in range(len(groups))]
                for k, fut in enumerate(futures):
                    say(f"fold {k + 1}/{len(groups)}: predicting {', '.join(groups[k][0])}")
                    fut.result()
                results = [fut.result() for fut in futures]
        finally:
            _JOB.clear()
    else:
        results = []
        for k, (group, _) in enumerate(groups):
            say(f"fold {k + 1}/{len(groups)}: predicting {', '.join(group)}")
            results.append(_run_fold(job, k))
    rmse = {}
    for fold in results:
        rmse.update(fold["rmse"])
    return {"folds": results, "rmse": rmse, "mean_rmse": float(np.mean(list(rmse.values())))}


_JOB: list = []  # (model, params, groups, fit_kwargs) of the leave_out whose forked workers run


def _fold(k: int) -> dict:
    """Fold ``k`` of the job the forked worker inherited."""
    from millflow.threads import single_threaded_blas

    with single_threaded_blas():  # two processes on two cores: no BLAS threads on top
        return _run_fold(_JOB[0], k)


def _run_fold(job, k: int) -> dict:
    """Fit fold ``k`` on its training conditions and predict its held-out ones."""
    model, params, groups, fit_kwargs = job
    group, train = groups[k]
    res = fit(model.for_conditions(train), params, grid_check=False, quiet=True, profile=False, **fit_kwargs)
    pred = condition_rmse(model.for_conditions(group), res.theta)
    return {"held_out": group, "rmse": pred, "params": {n: p.value for n, p in res.params.items()},
            "ssr_train": res.ssr, "spread": res.spread}


def _groups(conds, held_out) -> list[tuple[list, list]]:
    """(held-out conditions, training conditions) per fold, checked."""
    if isinstance(held_out, str) and held_out == "each":
        groups = [[c] for c in conds]
    elif held_out and all(isinstance(g, str) for g in held_out):
        groups = [list(held_out)]
    else:
        groups = [list(g) for g in held_out]
    out = []
    for group in groups:
        unknown = [c for c in group if c not in conds]
        if unknown:
            raise InputError(f"held-out conditions {unknown} are not in the data; conditions are {conds}")
        train = [c for c in conds if c not in group]
        if not train:
            raise InputError("every condition is held out; nothing is left to fit")
        out.append((group, train))
    return out


def nested_leave_out(candidates: dict, params: dict | None = None, held_out="each", *, criterion: str = "bic",
                     progress=None, quiet: bool = False, **fit_kwargs) -> dict:
    """Nested validation: the model structure is chosen inside each outer fold.

    A leave-out score of a structure that was itself chosen by comparing candidates on
    all the data is optimistic: the held-out conditions took part in the choice. Here,
    in each outer fold, every candidate is fitted to the training conditions only and
    ranked by ``criterion`` (AIC, AICc or BIC of that training fit); the winner, and
    only it, predicts the held-out conditions. ``mean_rmse`` then estimates the
    prediction error of the whole procedure (selection + fit), and ``chosen`` shows
    how stable the selection is across folds.

    Parameters
    ----------
    candidates : label -> :class:`ForwardModel` on all conditions (same data).
    params : label -> parameter dict (start values and bounds); None for defaults.
    held_out : as in :func:`leave_out`.
    criterion : one of :data:`CRITERIA`.
    fit_kwargs : passed to :func:`~millflow.fitting.estimate.fit` for every fit.

    Returns
    -------
    dict with ``folds`` (held_out, chosen, criteria {label: value}, rmse, params),
    ``rmse`` (condition -> prediction RMSE), ``mean_rmse``, ``chosen`` (label -> number
    of folds that chose it) and ``criterion``.
    """
    if criterion not in CRITERIA:
        raise InputError(f"criterion = {criterion!r}; expected one of {', '.join(CRITERIA)}")
    if not candidates:
        raise InputError("nested_leave_out needs at least one candidate model")
    labels = list(candidates)
    first = candidates[labels[0]]
    for label in labels[1:]:
        m = candidates[label]
        if m.conditions != first.conditions or m.y.shape != first.y.shape or not np.array_equal(m.y, first.y):
            raise InputError(f"candidate {label!r} is fitted to other data than {labels[0]!r}: "
                             "nested validation compares structures on the same data")
    say = reporter(progress, quiet, "nested_leave_out")
    params = params or {}
    folds, rmse = [], {}
    chosen = dict.fromkeys(labels, 0)
    groups = _groups(first.conditions, held_out)
    for k, (group, train) in enumerate(groups):
        say(f"outer fold {k + 1}/{len(groups)}: choosing among {len(labels)} structures without "
            f"{', '.join(group)}")
        fits = {label: fit(candidates[label].for_conditions(train), params.get(label), grid_check=False, quiet=True,
                           profile=False,
                           **fit_kwargs)
                for label in labels}
        scores = {label: float(r.criteria[criterion]) for label, r in fits.items()}
        best = min(labels, key=lambda label: scores[label])  # ties: the first listed
        chosen[best] += 1
        pred = condition_rmse(candidates[best].for_conditions(group), fits[best].theta)
        rmse.update(pred)
        folds.append({"held_out": group, "chosen": best, "criteria": scores, "rmse": pred,
                      "params": {n: p.value for n, p in fits[best].params.items()}})
    return {"folds": folds, "rmse": rmse, "mean_rmse": float(np.mean(list(rmse.values()))),
            "chosen": chosen, "criterion": criterion}
