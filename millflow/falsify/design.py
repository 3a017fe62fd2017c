"""The sampling design of a falsification study: grid, sieves, feed, conditions, times.

A :class:`Design` states *what would be measured*: the sieve sizes, the feed, the
operating conditions (with their process columns, e.g. ``tau_s`` for a continuous
mill) and either sampling times (batch tests, location ``mill``) or the sampled
locations of a continuous mill (``product``). Truth and assumed model are evaluated on
the same numerical grid, so the study measures model error only, not discretisation
error (Principle IV is the fitting package's grid check, a separate question).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pandas as pd

from millflow.errors import InputError
from millflow.fitting.data import PSDData, psd_data_from_frames
from millflow.grid import SizeGrid

__all__ = ["Design", "batch_design", "continuous_design"]


@dataclass(frozen=True)
class Design:
    """Sampling design.

    Attributes
    ----------
    grid : numerical grid shared by truth and assumed model.
    sieves_m : sieve sizes [m], strictly decreasing, positive.
    feed_passing : cumulative passing of the feed at ``sieves_m`` (fractions).
    conditions : condition names.
    process : column -> values per condition (e.g. ``{"tau_s": (30, 60, ...)}``).
    times_s : batch sampling times [s] (every condition); empty for continuous mills.
    locations : sampled locations of a continuous mill (default ``("product",)``).
    """

    grid: SizeGrid
    sieves_m: tuple
    feed_passing: tuple
    conditions: tuple = ("c1",)
    process: tuple = ()
    times_s: tuple = ()
    locations: tuple = ("product",)

    def __post_init__(self):
        s = np.asarray(self.sieves_m, float)
        f = np.asarray(self.feed_passing, float)
        if s.ndim != 1 or s.size < 2 or not np.all(np.isfinite(s)) or np.any(s <= 0) or np.any(np.diff(s) >= 0):
            raise InputError(f"design.sieves_m: expected at least 2 positive, strictly decreasing sizes, "
                             f"got {s.tolist()}")
        if f.shape != s.shape or np.any(f < 0) or np.any(f > 1) or np.any(np.diff(f) > 0):
            raise InputError("design.feed_passing: expected one cumulative passing fraction in [0, 1] per sieve, "
                             "non-increasing from coarse to fine")
        if s[0] > self.grid.x[0] * (1 + 1e-9):
            raise InputError(f"design.sieves_m: top sieve {float(s[0])!r} m is above the grid top "
                             f"{float(self.grid.x[0])!r} m")
        proc = dict(self.process.items() if isinstance(self.process, dict) else self.process)
        for col, vals in proc.items():
            v = np.asarray(vals, float)
            if v.shape != (len(self.conditions),) or np.any(~np.isfinite(v)) or np.any(v <= 0):
                raise InputError(f"design.process.{col}: expected {len(self.conditions)} positive numbers "
                                 "(one per condition)")
        t = np.asarray(self.times_s, float)
        if t.size and (np.any(~np.isfinite(t)) or np.any(t <= 0) or np.any(np.diff(t) <= 0)):
            raise InputError(f"design.times_s: expected positive, strictly increasing times, got {t.tolist()}")
        if len(set(self.conditions)) != len(self.conditions) or not self.conditions:
            raise InputError(f"design.conditions: expected distinct names, got {list(self.conditions)}")
        object.__setattr__(self, "sieves_m", tuple(float(v) for v in s))
        object.__setattr__(self, "feed_passing", tuple(float(v) for v in f))
        object.__setattr__(self, "process", tuple((str(k), tuple(float(x) for x in v)) for k, v in proc.items()))
        object.__setattr__(self, "times_s", tuple(float(v) for v in t))
        object.__setattr__(self, "conditions", tuple(str(c) for c in self.conditions))

    @property
    def is_batch(self) -> bool:
        """True for a batch design (sampled at times), False for a continuous one."""
        return len(self.times_s) > 0

    def data(self, passing=None, keys=None) -> PSDData:
        """The design as a PSD data set, filled with the given passing values.

        The design as a PSD data set; ``passing`` (one value per sample row, in the order of
        ``keys`` = [(condition, location, time_s), ...] times the sieves) fills the samples
        (None: a placeholder curve, for compiling models).
        """
        s = np.asarray(self.sieves_m)
        rows = [pd.DataFrame({"condition": "*", "location": "feed", "time_s": 0.0, "size_m": s,
                              "passing": np.asarray(self.feed_passing)})]
        keys = keys if keys is not None else self.sample_keys()
        for k, (c, loc, t) in enumerate(keys):
            vals = np.linspace(1.0, 0.0, s.size) if passing is None else passing[k * s.size:(k + 1) * s.size]
            rows.append(pd.DataFrame({"condition": c, "location": loc, "time_s": t, "size_m": s, "passing": vals}))
        proc = None
        if self.process:
            proc = pd.DataFrame({"condition": list(self.conditions), **{k: list(v) for k, v in self.process}})
        return psd_data_from_frames(pd.concat(rows, ignore_index=True), proc, source="falsify design",
                                    strict=passing is None)

    def sample_keys(self) -> list:
        """(condition, location, time_s) of every sample, in the order of the data table."""
        if self.is_batch:
            return [(c, "mill", t) for c in sorted(self.conditions) for t in self.times_s]
        return [(c, loc, 0.0) for c in sorted(self.conditions) for loc in sorted(self.locations)]

    def passing_at_sieves(self, mass) -> np.ndarray:
        """Cumulative passing at the sieves of mass fractions on the grid.

        (..., N) -> (..., n_sieves), interpolated linearly in size as the fitting models do (P = 0 at
        0, 1 above the grid).
        """
        mass = np.asarray(mass, float)
        P = np.cumsum(mass[..., ::-1], axis=-1)[..., ::-1]  # passing the upper edge x_i
        xc = np.concatenate([[0.0], self.grid.x[::-1]])
        flat = P.reshape(-1, P.shape[-1])
        out = np.array([np.interp(self.sieves_m, xc, np.concatenate([[0.0], row[::-1]]), right=1.0) for row in flat])
        return out.reshape(P.shape[:-1] + (len(self.sieves_m),))

    def process_dict(self) -> dict:
        """The process columns as arrays, column -> values per condition."""
        return {k: np.asarray(v) for k, v in self.process}


def _sieves(top_m: float, n: int, ratio: float) -> np.ndarray:
    return top_m * ratio ** (-np.arange(n))


def batch_design(times_s, *, top_m: float = 4e-3, n_sieves: int = 16, sieve_ratio: float = 2 ** 0.5,
                 grid_per_sieve: int = 2, conditions=("c1",)) -> Design:
    """A batch design: feed in the top sieve interval, root-2 sieves, sampled at ``times_s`` [s].

    Parameters
    ----------
    times_s : sequence of float
        Sampling times [s].
    top_m : float
        Top sieve size [m]; the feed is all in the interval below it.
    n_sieves : int
        Number of sieves, >= 3.
    sieve_ratio : float
        Ratio of neighbouring sieves, > 1 (root 2 by default).
    grid_per_sieve : int
        Grid classes per sieve interval, >= 1 (the sieves are grid edges; one more sieve
        interval below the finest sieve, so the sink is not a measured class).
    conditions : sequence of str
        Names of the batch tests (each sampled at every time).

    Returns
    -------
    Design

    Raises
    ------
    InputError
        A sieve count, ratio or grid density out of range.

    Examples
    --------
    >>> d = batch_design([60, 240], n_sieves=8)
    >>> d.is_batch, d.times_s, len(d.sieves_m), d.grid.n
    (True, (60.0, 240.0), 8, 17)
    """
    return _design(top_m, n_sieves, sieve_ratio, grid_per_sieve, conditions=tuple(conditions), times_s=tuple(times_s))


def continuous_design(tau_s, *, top_m: float = 4e-3, n_sieves: int = 16, sieve_ratio: float = 2 ** 0.5,
                      grid_per_sieve: int = 2, extra_process: dict | None = None) -> Design:
    """A continuous-mill design: one condition per mean residence time ``tau_s`` [s].

    The product of each condition is sampled; the process column ``tau_s`` holds the mean
    residence times.

    Parameters
    ----------
    tau_s : sequence of float
        Mean residence times [s], one condition each (named tau1, tau2, ...).
    top_m : float
        Top sieve size [m]; the feed is all in the interval below it.
    n_sieves : int
        Number of sieves, >= 3.
    sieve_ratio : float
        Ratio of neighbouring sieves, > 1 (root 2 by default).
    grid_per_sieve : int
        Grid classes per sieve interval, >= 1 (the sieves are grid edges; one more sieve
        interval below the finest sieve, so the sink is not a measured class).
    extra_process : dict or None
        More process columns, name -> one value per condition (e.g. ``screen_mm``).

    Returns
    -------
    Design

    Examples
    --------
    >>> d = continuous_design([30, 120], n_sieves=8)
    >>> d.conditions, d.process_dict()["tau_s"].tolist()
    (('tau1', 'tau2'), [30.0, 120.0])
    """
    names = tuple(f"tau{k + 1}" for k in range(len(tau_s)))
    proc = {"tau_s": tuple(tau_s), **{k: tuple(v) for k, v in (extra_process or {}).items()}}
    return _design(top_m, n_sieves, sieve_ratio, grid_per_sieve, conditions=names, process=proc)


def _design(top_m, n_sieves, sieve_ratio, grid_per_sieve, **kw) -> Design:
    if not (isinstance(n_sieves, int) and n_sieves >= 3):
        raise InputError(f"design.n_sieves = {n_sieves!r}: expected an integer >= 3")
    if not (isinstance(grid_per_sieve, int) and grid_per_sieve >= 1):
        raise InputError(f"design.grid_per_sieve = {grid_per_sieve!r}: expected an integer >= 1")
    if not (sieve_ratio > 1):
        raise InputError(f"design.sieve_ratio = {sieve_ratio!r}: expected a number > 1")
    s = _sieves(top_m, n_sieves, sieve_ratio)
    # grid edges: every sieve plus grid_per_sieve - 1 between, and one more sieve interval
    # below the finest sieve so that the sink is not a measured class
    grid = SizeGrid.geometric(top_m, sieve_ratio ** (1.0 / grid_per_sieve), grid_per_sieve * n_sieves + 1)
    feed = np.zeros(n_sieves)
    feed[0] = 1.0
    return Design(grid, tuple(s), tuple(feed), **kw)
