"""Predictive validation (Principle VI): leave conditions out, fit the rest, predict them.

The error measure is the RMSE of cumulative passing at every measured row of each
held-out condition, the model curve interpolated linearly in size (with P = 0 at size
0 and P = 1 above the grid top): the metric of the SPRITE knife-mill README, and a
natural one for any sieve data.
"""
from __future__ import annotations

import numpy as np

from millflow.errors import InputError
from millflow.fitting.estimate import fit
from millflow.fitting.models import ForwardModel

__all__ = ["leave_out", "condition_rmse"]


def condition_rmse(model: ForwardModel, theta) -> dict:
    """RMSE of cumulative passing per condition of ``model`` at parameters ``theta``."""
    r = model.predict_cum(np.asarray(theta, float)) - model.y_cum
    return {c: float(np.sqrt(np.mean(r[model.condition_of_value == c] ** 2))) for c in model.conditions}


def leave_out(model: ForwardModel, params: dict | None, held_out="each", *, progress=None, **fit_kwargs) -> dict:
    """Fit without some conditions and predict them.

    Parameters
    ----------
    model : the forward model on all conditions (its grid is reused).
    params : parameter dict (start values and bounds) or None for defaults.
    held_out : ``"each"`` (leave one condition out at a time), a list of condition
        names (held out together, one fit), or a list of lists (one fit per group).
    fit_kwargs : passed to :func:`~millflow.fitting.estimate.fit` (each fold runs the
        full search: nothing from the held-out data reaches the fold's fit).

    Returns
    -------
    dict with ``folds`` (list of {held_out, rmse: {condition: value}, params}),
    ``rmse`` (condition -> prediction RMSE) and ``mean_rmse``.
    """
    conds = model.conditions
    if held_out == "each":
        groups = [[c] for c in conds]
    elif held_out and all(isinstance(g, str) for g in held_out):
        groups = [list(held_out)]
    else:
        groups = [list(g) for g in held_out]
    folds, rmse = [], {}
    for k, group in enumerate(groups):
        unknown = [c for c in group if c not in conds]
        if unknown:
            raise InputError(f"held-out conditions {unknown} are not in the data; conditions are {conds}")
        train = [c for c in conds if c not in group]
        if not train:
            raise InputError("every condition is held out; nothing is left to fit")
        if progress:
            progress(f"fold {k + 1}/{len(groups)}: predicting {', '.join(group)}")
        res = fit(model.for_conditions(train), params, grid_check=False, **fit_kwargs)
        pred = condition_rmse(model.for_conditions(group), res.theta)
        rmse.update(pred)
        folds.append({"held_out": group, "rmse": pred, "params": {n: p.value for n, p in res.params.items()},
                      "ssr_train": res.ssr, "spread": res.spread})
    return {"folds": folds, "rmse": rmse, "mean_rmse": float(np.mean(list(rmse.values())))}
