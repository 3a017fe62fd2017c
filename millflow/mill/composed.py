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
    None; the repr shows the composition. Methods delegate to :func:`steady_mill`,
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
        sc = _scene(self.S, self.b, self.transport, self.d, self.where, self.dispersion, discharge=self.discharge)
        object.__setattr__(self, "S", sc.S)
        object.__setattr__(self, "b", sc.b)
        object.__setattr__(self, "d", sc.d)
        object.__setattr__(self, "where", sc.where)
        object.__setattr__(self, "_scene", sc)
        object.__setattr__(self, "_cache", {})

    def __repr__(self):
        cls = "None" if self.d is None else f"d* at {self.where}"
        return (f"Mill(N={self.S.size}, transport={self.transport!r}, classification={cls}, "
                f"method={self.method!r})")

    @property
    def method(self) -> str:
        """The method :meth:`steady` runs."""
        return self._scene.method

    def product(self, feed, tol: float = 1e-8, on_inaccuracy: str = "raise") -> np.ndarray:
        """Product flows (N,) or (N, m) for feed (N,) or (N, m): the fast path (inputs
        validated once at construction, no Dataset, the spectral decomposition of the
        plug-flow and segregated paths kept after the first call). Each feed column is
        solved scaled to a unit total; ``tol`` and ``on_inaccuracy`` as :func:`steady_mill`."""
        feed = _check_feed(feed, self.S.size)
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
        return steady_mill(self.S, self.b, feed, self.transport, self.d, where=self.where,
                           dispersion=self.dispersion, discharge=self.discharge, x=self.x, **kwargs)

    def transfer_matrix(self, **kwargs) -> np.ndarray:
        """:func:`transfer_matrix` for this mill."""
        return transfer_matrix(self.S, self.b, self.transport, self.d, where=self.where,
                               dispersion=self.dispersion, discharge=self.discharge, **kwargs)

    def transient(self, t, **kwargs) -> xr.Dataset:
        """:func:`millflow.mill.transient.transient_mill` for this mill."""
        from millflow.mill.transient import transient_mill  # here: scipy.integrate only for dynamics

        return transient_mill(self.S, self.b, self.transport, t, d=self.d, where=self.where,
                              dispersion=self.dispersion, discharge=self.discharge, x=self.x, **kwargs)
