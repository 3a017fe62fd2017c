"""A population of linear mills sampled where a survey or a lab samples them.

A fit evaluates the same mill for a whole population of parameter sets (the members of a
differential-evolution generation, the columns of a finite-difference Jacobian) and reads
it where the data were taken: the product, the mill's hold-up, the content of cell K
(``cell:K``) or the content at the fractional axial position Y (``z:Y``).
:class:`SampledMill` resolves a transport once to the cheapest exact route and evaluates
every member and condition by it:

- a chain of n equal well-mixed cells (perfect mixing, tanks in series with integer n):
  eq. 3 per cell (tau/n each) for all members at once
  (:func:`~millflow.mill.well_mixed.well_mixed_population`, or on a geometric grid with
  eq. 6/8 breakage the O(N) recurrences of
  :func:`~millflow.mill.well_mixed.well_mixed_population_separable`), d* at the last cell
  or at every cell outlet (``where="cells"``); cell content per unit feed rate
  tau_k p_k / d* (classified outlet) or tau_k p_k;
- a network of cells with back-flow (recirculating cells): the class-by-class batched
  block solve of :func:`~millflow.mill.cells.solve_cells_population`;
- plug flow (product and ``z:Y`` samples): eq. 4 in the contact time with d* in the
  velocity (rates tau S / d*) by :func:`millflow.batch.batch_grind_population`; content
  at Y tau M(Y) / d* per unit length;
- anything else (axial dispersion, hold-up of plug flow, cells named by number): one
  :class:`~millflow.mill.Mill` (product) or :func:`~millflow.mill.steady_mill` (other
  samples) per member and condition, at the forward tolerance.

The fit's modes ``well_mixed`` (n equal tanks, d* at every tank) and ``plug_flow`` name
their transport; :func:`~millflow.mill.transport.mode_transport` resolves them, so they run
by the same routes. Samples are returned as mass fractions (each row normalised); members
outside the model's domain (non-finite rates, a transport rtd refuses) give NaN rows.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from millflow.errors import InputError
from millflow.mill.transport import (build_transport, equal_cells, is_axial, is_axial_dispersion, is_network, is_plug,
                                     is_tanks)
from millflow.mill.well_mixed import well_mixed_population, well_mixed_population_separable

__all__ = ["SampledMill"]


@dataclass(frozen=True)
class SampledMill:
    """A transport resolved once for population solves at sample locations.

    Attributes
    ----------
    transport : canonical transport name (:mod:`millflow.mill.transport`).
    params : its fixed parameters besides tau.
    where : where classification acts (None: the transport's default; ``"discharge"``,
        ``"cells"``, 1-based cell numbers, ``"axis"``).
    make : callable ``make(tau_s, k)`` returning the rtd model of member k (fitted
        transport parameters); None: built from ``transport`` and ``params``.
    fitted : whether the transport's parameters differ between members.
    tol : tolerance of the member-by-member solves (relative to the feed).
    extra : fitted transport parameters per member (name -> (P,) array), those ``make`` uses.
    """

    transport: str
    params: dict = field(default_factory=dict)
    where: object = None
    make: Callable | None = None
    fitted: bool = False
    tol: float = 1e-10
    extra: dict = field(default_factory=dict)

    def model(self, tau: float, k: int = 0):
        """The rtd model of member ``k`` with mean residence time ``tau`` [s]."""
        if self.make is not None:
            return self.make(float(tau), k)
        return build_transport(self.transport, float(tau), self.params)

    @property
    def chain_cells(self) -> int | None:
        """Number of equal well-mixed cells in a row (the vectorised eq. 3 route), or None."""
        n = equal_cells(self.transport, self.params)
        if n is not None and is_tanks(self.transport) and self.where not in (None, "discharge", "cells"):
            return None
        return n

    @property
    def classified_at(self):
        """Where d* acts: :attr:`where`, by default the axis (plug flow, axial dispersion) or the discharge."""
        return self.where or ("axis" if is_axial(self.transport) else "discharge")

    def route(self, groups) -> str:
        """The route :meth:`samples` takes for these sample groups.

        ``"chain"``, ``"network"`` and ``"plug"`` (exact vectorised solves, rounding only) or
        ``"members"`` (one refined mill solve per member and condition, to :attr:`tol`).
        """
        if self.chain_cells is not None:
            return "chain"
        if is_network(self.transport) and self.where in (None, "discharge", "cells"):
            return "network"
        if is_plug(self.transport) and all(g[1] != "holdup" for g in groups):
            return "plug"
        return "members"

    def nonlinear_route(self, tau: float, k: int) -> dict:
        """Keyword arguments of :func:`~millflow.mill.transport.solve_nonlinear` for member ``k``.

        The transport name, its chain of ``n_tanks`` cells, the closed vessel's Peclet
        number, and the rtd model of a network of cells (``network``) or of the open
        vessel (``model``) at mean residence time ``tau`` [s].

        Raises
        ------
        InputError
            Where rtd refuses member k's transport parameters (e.g. r < 0).
        """
        tr = self.transport
        kw = {"transport": tr, "n_tanks": int(self.params.get("n", 1)) if is_tanks(tr) else 1}
        if is_axial_dispersion(tr, open_vessel=False):
            kw["pe"] = float(self.extra["pe"][k]) if "pe" in self.extra else float(self.params["pe"])
        if is_network(tr) or is_axial_dispersion(tr, open_vessel=True):
            kw["network" if is_network(tr) else "model"] = self.model(tau, k)
        return kw

    def samples(self, S, b, feeds, tau, d, groups, out, sep=None) -> None:
        """Fill ``out`` (P, G, N) with the samples of every member.

        Parameters
        ----------
        S : (P, C, N) rates [1/s] per member and condition (or tau S with tau = 1).
        b : (P, N, N) or (P, C, N, N) fractional breakage; None with ``sep`` (a chain on a
            geometric grid: the recurrences' terms).
        feeds : (C, N) feed mass fractions per condition.
        tau : (P, C) mean residence times [s].
        d : (P, C, N) normalised discharge d*, or None (no classification).
        groups : G tuples (condition index, location, ...) with location ``"product"``,
            ``"holdup"``, ``"cell:K"`` or ``"z:Y"``.
        out : (P, G, N) array written in place (mass fractions per row).
        sep : the separable terms of eq. 6/8 on a geometric grid (chains only).
        """
        route = self.route(groups)
        if route == "chain":
            self._chain(S, b, feeds, d, tau, groups, out, sep)
        elif route == "network":
            self._network(S, b, feeds, d, tau, groups, out)
        elif route == "plug":
            self._plug(S, b, feeds, d, tau, groups, out)
        else:
            self.samples_by_member(S, b, feeds, d, tau, groups, out)

    def _chain(self, S, b, feeds, d, tau, groups, out, sep):
        n = self.chain_cells
        ones = np.ones_like(S)
        stream = np.broadcast_to(feeds, S.shape)
        contents = []
        if b is not None:
            b_pc = b if b.ndim == 4 else b[:, None]
        for k in range(n):
            classified = d is not None and (self.where == "cells" or k == n - 1)
            dk = d if classified else ones
            if b is None:
                stream = well_mixed_population_separable(S, stream, *sep, tau / n, dk)
            else:
                stream = well_mixed_population(S, b_pc, stream, tau / n, dk)
            contents.append(stream / dk)
        for g, (c, loc, *_) in enumerate(groups):
            if loc == "product":
                m = stream[:, c]
            elif loc == "holdup":
                m = sum(h[:, c] for h in contents)
            else:  # cell:K
                m = contents[int(loc[5:]) - 1][:, c]
            out[:, g] = m / m.sum(axis=1, keepdims=True)

    def _plug(self, S, b, feeds, d, tau, groups, out):
        from millflow.batch import batch_grind_population

        rates = S * tau[:, :, None] if d is None else S * tau[:, :, None] / d
        for c in range(feeds.shape[0]):
            gsel = [g for g, grp in enumerate(groups) if grp[0] == c]
            pos = np.array([1.0 if groups[g][1] == "product" else float(groups[g][1][2:]) for g in gsel])
            M = batch_grind_population(rates[:, c], b[:, c] if b.ndim == 4 else b, feeds[c], pos)
            for r, g in enumerate(gsel):
                m = M[:, r] if (groups[g][1] == "product" or d is None) else M[:, r] / d[:, c]
                with np.errstate(invalid="ignore"):
                    out[:, g] = m / m.sum(axis=1, keepdims=True)

    def _network(self, S, b, feeds, d, tau, groups, out):
        from millflow.mill.cells import network_of, solve_cells_population

        n_pop, C = S.shape[:2]
        nets = np.empty((n_pop, C), dtype=object)
        bad = np.zeros((n_pop, C), dtype=bool)
        for c in range(C):
            for k in range(n_pop if self.fitted else 1):
                try:
                    net = network_of(self.model(tau[k, c], k))
                except InputError:  # outside rtd's domain (e.g. r < 0): this member only
                    net, bad[k, c] = None, True
                if self.fitted:
                    nets[k, c] = net
                else:
                    nets[:, c] = [net] * n_pop
                    bad[:, c] = bad[0, c]
        if bad.any():  # a valid placeholder, then NaN
            ok = next((v for v in nets.ravel() if v is not None), None)
            if ok is None:
                out[:] = np.nan
                return
            nets[bad] = ok
        b_pc = b if b.ndim == 4 else b[:, None]
        where = "cells" if self.where == "cells" else "discharge"
        prod, hold = solve_cells_population(S, b_pc, feeds[None], nets, d, where)
        for g, (c, loc, *_) in enumerate(groups):
            if loc == "product":
                m = prod[:, c]
            elif loc == "holdup":
                m = hold[:, c].sum(axis=1)
            else:  # cell:K
                m = hold[:, c, int(loc[5:]) - 1]
            with np.errstate(invalid="ignore"):
                out[:, g] = m / m.sum(axis=1, keepdims=True)
        out[bad.any(axis=1)] = np.nan

    def samples_by_member(self, S, b, feeds, d, tau, groups, out) -> None:
        """The samples of :meth:`samples` by one mill per member and condition (the general route).

        One :class:`~millflow.mill.Mill` (product samples) or
        :func:`~millflow.mill.steady_mill` per member and condition, at :attr:`tol`: the
        reference the vectorised routes are tested against. Arguments as :meth:`samples`
        (``b`` not None).
        """
        from millflow.mill import Mill, steady_mill

        loc_of = {"product": "discharge", "holdup": "holdup"}
        for c in range(feeds.shape[0]):
            gsel = [g for g, grp in enumerate(groups) if grp[0] == c]
            locs = [groups[g][1] for g in gsel]
            only_product = all(loc == "product" for loc in locs)
            specs = [loc_of.get(loc, loc) for loc in locs]
            zs = sorted({float(loc[2:]) for loc in locs if loc.startswith("z:")})
            kw = {"positions": zs} if zs else {}
            tr = None if self.fitted else self.model(tau[0, c], 0)  # fixed: a bad transport is the user's error
            for k in range(S.shape[0]):
                Sk = S[k, c]
                bk = b[k, c] if b.ndim == 4 else b[k]
                dk = None if d is None else d[k, c]
                if not (np.isfinite(Sk).all() and np.isfinite(bk).all() and (dk is None or np.isfinite(dk).all())):
                    out[k, gsel] = np.nan  # outside the model's domain: reported, not solved
                    continue
                if self.fitted:
                    try:
                        tr = self.model(tau[k, c], k)
                    except InputError:
                        out[k, gsel] = np.nan
                        continue
                # self.tol of the feed; above it the solve raises
                if only_product:
                    out[k, gsel] = Mill(Sk, bk, tr, dk, self.where).product(feeds[c], tol=self.tol)
                else:
                    ds = steady_mill(Sk, bk, feeds[c], tr, dk, where=self.where, locations=specs, tol=self.tol, **kw)
                    vals = ds["sample"].values
                    for r, (g, loc) in enumerate(zip(gsel, locs)):
                        out[k, g] = ds["product"].values if loc == "product" else vals[r]
