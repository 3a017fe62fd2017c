"""``Mill``: breakage, transport and classification composed into one object.

It validates its inputs once (the scene of :mod:`millflow.mill.steady`), keeps the
spectral decomposition of the plug-flow and segregated paths between calls, and
delegates to :func:`~millflow.mill.steady.steady_mill`,
:func:`~millflow.mill.steady.transfer_matrix` and
:func:`~millflow.mill.transient.transient_mill`.

:meth:`Mill.from_forms` builds a mill from continuous forms (a rate and a distribution
model, optionally a classification curve of size) on a size grid: class averages
(:func:`millflow.breakage.averaged.breakage_on_grid`, second order in the class width), and
its steady solves carry a grid error estimated by a solve on the grid refined 2x in ln x
(Richardson at the scheme's order with the safety factor of :func:`millflow.grid.richardson`).
A mill made from S_i and b_ij arrays is the discrete model itself: no grid error.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import xarray as xr

from millflow.grid import SAFETY_FACTOR, SizeGrid
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

    @classmethod
    def from_forms(cls, rate, breakage, transport, grid, classification=None, *, where=None, dispersion=None,
                   discharge=None) -> "Mill":
        """A mill from continuous forms on ``grid`` (module docstring).

        Parameters
        ----------
        rate : rate model of size (e.g. :class:`millflow.breakage.PowerLawRate`) [1/s].
        breakage : distribution model with ``cumulative(x, y, top)`` (e.g. NormalizedBreakage).
        transport : rtd model.
        grid : :class:`~millflow.grid.SizeGrid` (its ``scheme``: "class_average", the default, or
            "upper_edge", Austin's values at the upper edges, first order).
        classification : None, or a function of size x [m] -> d* (normalised discharge rate),
            class-averaged on the grid as the forms are.
        where, dispersion, discharge : as :class:`Mill`.

        Examples
        --------
        >>> import rtd
        >>> import millflow as mf
        >>> from millflow.mill import Mill
        >>> grid = mf.SizeGrid.geometric(2e-3, 2 ** 0.25, 30)
        >>> mill = Mill.from_forms(mf.PowerLawRate(A=0.02, alpha=1.0, x0=1e-3), mf.NormalizedBreakage(0.5, 0.8, 3.0),
        ...                        rtd.TanksInSeries(600.0, 3), grid)
        >>> ds = mill.steady([1.0] + [0.0] * 29)
        >>> ds.attrs["grid_error_estimate"] > 0
        True
        """
        from millflow.breakage.averaged import breakage_on_grid, curve_on_grid

        if not isinstance(grid, SizeGrid):
            grid = SizeGrid(grid)
        S, b, how = breakage_on_grid(rate, breakage, grid)
        d = None if classification is None else curve_on_grid(classification, grid)
        mill = cls(S, b, transport, d, where, dispersion, grid.x, discharge)
        object.__setattr__(mill, "_forms", (rate, breakage, classification, grid, how))
        return mill

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
        """Product flows for a feed: the fast path.

        Product flows (N,) or (N, m) for feed (N,) or (N, m): the fast path (inputs
        validated once at construction, no Dataset, the spectral decomposition of the
        plug-flow and segregated paths kept after the first call). Each feed column is
        solved scaled to a unit total; ``tol`` and ``on_inaccuracy`` as :func:`steady_mill`.
        """
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
        """:func:`steady_mill` for this mill; made by :meth:`from_forms`, with its grid error.

        The grid part (attrs ``grid_error_estimate`` [feed units], the largest over the classes,
        ``grid_error_method``, and ``p80_grid_error``, relative) comes from the same mill on the
        grid refined 2x in ln x, the feed moved there by :func:`millflow.psd.regrid` and the
        refined product summed back to these classes (nested grids: exact), Richardson at the
        scheme's order p (2 for class averages, 1 for upper edges): F_s 2^p/(2^p - 1) |p_h - p_h/2|,
        F_s = 3. ``error_estimate`` is then the solver part plus the grid part.
        """
        S, b = (self.S, self.b) if self._kinetics is None else (self._kinetics, None)
        ds = steady_mill(S, b, feed, self.transport, self.d, where=self.where,
                         dispersion=self.dispersion, discharge=self.discharge, x=self.x, **kwargs)
        forms = self.__dict__.get("_forms")
        if forms is None or forms[4] == "discrete (as given)":
            return ds
        return self._with_grid_error(ds, feed, forms, kwargs)

    def _with_grid_error(self, ds, feed, forms, kwargs):
        from millflow.psd import percentile_size, regrid

        rate, breakage, classification, grid, how = forms
        feed = np.asarray(feed, dtype=float)
        if feed.ndim != 1:
            return ds  # several feeds at once: the grid error is estimated for one feed
        fine = grid.refine(2)
        total = float(feed.sum())
        feed_f = regrid(feed / total, grid, fine) * total
        m2 = Mill.from_forms(rate, breakage, self.transport, fine, classification, where=self.where,
                             dispersion=self.dispersion, discharge=self.discharge)
        kw = {k: v for k, v in kwargs.items() if k not in ("positions", "locations")}
        ds2 = steady_mill(m2.S, m2.b, feed_f, m2.transport, m2.d, where=m2.where, dispersion=m2.dispersion,
                          discharge=m2.discharge, x=fine.x, **kw)
        p_f = ds2["product"].values
        reduced = np.append(p_f[:-1].reshape(grid.n - 1, 2).sum(axis=1), p_f[-1])
        p = 1 if how == "upper edge" else 2
        factor = SAFETY_FACTOR * 2.0 ** p / (2.0 ** p - 1.0)
        err = factor * float(np.max(np.abs(ds["product"].values - reduced)))
        solver = float(ds.attrs["solver_error_estimate"])
        p80_err = float("nan")
        try:
            a = percentile_size(grid, ds["product_fraction"].values, 80.0)
            b = percentile_size(fine, ds2["product_fraction"].values, 80.0)
            p80_err = factor * abs(a - b) / b
        except Exception:  # noqa: BLE001  (P80 inside the sink: no P80 to estimate)
            pass
        ds.attrs.update(grid_error_estimate=err, error_estimate=solver + err, p80_grid_error=p80_err,
                        grid_error_method=(f"the mill on the grid refined 2x in ln x ({fine.n} classes; forms by "
                                           f"{how}), product summed back to these classes: Richardson at order {p} "
                                           f"with safety factor {SAFETY_FACTOR:g}, {factor:.3g} x the change"))
        return ds

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
