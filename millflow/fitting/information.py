"""How much each kind of data constrains each parameter: Fisher-information shares.

For a weighted least-squares fit the information on the parameters is J^T J, J the
Jacobian of the weighted residuals sqrt(w) (model - data) (eq. 9 uses its inverse).
Rows come in blocks by data kind (tracer F(t), product, hold-up, cell:K and z:Y samples,
see :class:`~millflow.fitting.models.ForwardModel`), and J^T J = sum_k J_k^T J_k. The
share of kind k in the information on parameter j is

    share_kj = (J_k^T J_k)_jj / (J^T J)_jj,

which sums to one over the kinds: the fraction of the curvature of the SSR along
parameter j that kind k contributes. It is a diagonal (one-parameter-at-a-time) view;
how the kinds separate *correlated* parameters shows in the correlation matrix and
the standard errors of fits with and without a kind (docs/fitting.md, the worked
multi-location example).
"""
from __future__ import annotations

import numpy as np

from millflow.fitting.statistics import jacobian

__all__ = ["information_shares"]


def information_shares(result) -> dict:
    """Shares of each data kind in the information on each varying parameter of a fit.

    ``result``: a :class:`~millflow.fitting.estimate.FitResult`. Returns
    ``{kind: {parameter: share}}`` (shares in [0, 1], summing to 1 over the kinds for
    each parameter), the Jacobian taken at the estimate by the fit's own central
    differences.
    """
    model = result.model
    names = [n for n in model.param_names if result.params[n].vary]
    theta = np.array([result.params[n].value for n in model.param_names])
    idx = [model.param_names.index(n) for n in names]
    lo = np.array([result.params[n].min for n in names])
    hi = np.array([result.params[n].max for n in names])
    sw = np.sqrt(model.weights)

    def resid_pop(z):
        full = np.repeat(theta[None], z.shape[0], axis=0)
        full[:, idx] = z
        return (model.predict(full) - model.y) * sw

    J = jacobian(resid_pop, theta[idx], lo, hi)
    total = np.einsum("rj,rj->j", J, J)
    out = {}
    for kind in dict.fromkeys(model.data_kind):
        rows = model.data_kind == kind
        part = np.einsum("rj,rj->j", J[rows], J[rows])
        out[str(kind)] = {n: float(part[k] / total[k]) if total[k] > 0 else float("nan") for k, n in enumerate(names)}
    return out
