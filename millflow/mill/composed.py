"""``Mill``: breakage, transport and classification composed into one object.

It validates its inputs once (the scene of :mod:`millflow.mill.steady`), keeps the
spectral decomposition of the plug-flow and segregated paths between calls, and
delegates to :func:`~millflow.mill.steady.steady_mill`,
:func:`~millflow.mill.steady.transfer_matrix` and
:func:`~millflow.mill.transient.transient_mill`.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from millflow.mill.accuracy import check_accuracy
from millflow.mill.scene import _check_feed, _scene
from millflow.mill.steady import _solve, steady_mill, transfer_matrix

__all__ = ["Mill"]


@dataclass(frozen=True, eq=False)
class Mill:
    """A continuous mill: breakage, transport and classification, composed.

    ``Mill(S, b, transport=rtd.TanksInSeries(600.0, 3), d=None)``: what is absent is
    None; the repr shows the composition. ``Mill(kinetics, None, transport, ...)`` with a
    :class:`millflow.nonlinear.Kinetics`: non-linear kinetics, solved by
    :mod:`millflow.mill.nonlinear` (one feed at a time, used as given). Methods delegate to :func:`steady_mill`,
    :func:`transfer_matrix` and :func:`millflow.mill.transient.transient_mill`.
    """

    S: np.ndarray = field(repr=False)
    b: np.ndarray = field(repr=False)
    transport: object
    d: np.ndarray | None = field(default=None, repr=False)
    where: str | None = None
    dispersion: np.ndarray | None = field(default=None, repr=False)
    x: np.ndarray | None = field(default=None, repr=False)
    discharge: str | None = None

    def __post_init__(self):
        from millflow.mill.nonlinear_mill import check_no_b, is_kinetics

        kin = None
        if is_kinetics(self.S):  # non-linear kinetics: S and b are the Kinetics' own, kept beside it
            kin = self.S
            check_no_b(kin, self.b, "Mill")
            object.__setattr__(self, "S", kin.S)
            object.__setattr__(self, "b", kin.b)
        object.__setattr__(self, "_kinetics", None if kin is None or kin.is_linear else kin)
        sc = _scene(self.S, self.b, self.transport, self.d, self.where, self.dispersion, discharge=self.discharge)
        object.__setattr__(self, "S", sc.S)
        object.__setattr__(self, "b", sc.b)
        object.__setattr__(self, "d", sc.d)
        object.__setattr__(self, "where", sc.where)
        object.__setattr__(self, "_scene", sc)
        object.__setattr__(self, "_cache", {})

    def __repr__(self):
        cls = "None" if self.d is None else f"d* at {self.where}"
        kin = "" if self._kinetics is None else f", kinetics={self._kinetics.describe()!r}"
        return (f"Mill(N={self.S.size}, transport={self.transport!r}, classification={cls}, "
                f"method={self.method!r}{kin})")

    @property
    def method(self) -> str:
        """The method :meth:`steady` runs ("nonlinear" for non-linear kinetics)."""
        return "nonlinear" if self._kinetics is not None else self._scene.method

    @property
    def kinetics(self):
        """The non-linear :class:`millflow.nonlinear.Kinetics` (None for first-order breakage)."""
        return self._kinetics

    def product(self, feed, tol: float = 1e-8, on_inaccuracy: str = "raise") -> np.ndarray:
        """Product flows (N,) or (N, m) for feed (N,) or (N, m): the fast path (inputs
        validated once at construction, no Dataset, the spectral decomposition of the
        plug-flow and segregated paths kept after the first call). Each feed column is
        solved scaled to a unit total; ``tol`` and ``on_inaccuracy`` as :func:`steady_mill`."""
        feed = _check_feed(feed, self.S.size)
        if self._kinetics is not None:  # non-linear: one feed at a time, used as given
            from millflow.mill.nonlinear import solve_transport

            cols = feed if feed.ndim == 2 else feed[:, None]
            out = []
            for col in cols.T:
                r = solve_transport(self._kinetics, col, self.transport, self.d, where=self.where,
                                    dispersion=self.dispersion, discharge=self.discharge, tol=tol, holdup=False)
                scale = max(float(np.abs(col).sum()), 1e-300)
                check_accuracy("Mill.product", r.method, r.mass_balance_error / scale, r.error_estimate / scale, tol,
                               on_inaccuracy)
                out.append(r.product)
            return np.array(out).T if feed.ndim == 2 else out[0]
        total = np.abs(feed).sum(axis=0)
        scale = np.where((total > 0) & np.isfinite(total), total, 1.0)
        solved = _solve(self._scene, feed / scale, tol=tol, holdup=False, cache=self._cache)
        p = solved["product"]
        mass = float(np.max(np.abs(p.sum(axis=0) - feed.sum(axis=0) / scale)))
        check_accuracy("Mill.product", solved["method"], mass, float(solved["error"]), tol, on_inaccuracy,
                       solved["extras"].get("advice"))
        return p * scale

    def steady(self, feed, **kwargs) -> xr.Dataset:
        """:func:`steady_mill` for this mill."""
        S, b = (self.S, self.b) if self._kinetics is None else (self._kinetics, None)
        return steady_mill(S, b, feed, self.transport, self.d, where=self.where,
                           dispersion=self.dispersion, discharge=self.discharge, x=self.x, **kwargs)

    def transfer_matrix(self, **kwargs) -> np.ndarray:
        """:func:`transfer_matrix` for this mill (first-order kinetics only)."""
        S = self.S if self._kinetics is None else self._kinetics
        return transfer_matrix(S, self.b, self.transport, self.d, where=self.where,
                               dispersion=self.dispersion, discharge=self.discharge, **kwargs)

    def transient(self, t, **kwargs) -> xr.Dataset:
        """:func:`millflow.mill.transient.transient_mill` for this mill."""
        from millflow.mill.transient import transient_mill  # here: scipy.integrate only for dynamics

        S, b = (self.S, self.b) if self._kinetics is None else (self._kinetics, None)
        return transient_mill(S, b, self.transport, t, d=self.d, where=self.where,
                              dispersion=self.dispersion, discharge=self.discharge, x=self.x, **kwargs)
