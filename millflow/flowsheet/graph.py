"""The flowsheet: units and the streams connecting them, checked on construction.

A :class:`Flowsheet` holds only connections (units are stateless): each stream leaves
one outlet port of one unit and enters one unit. Construction checks that every outlet
port carries exactly one stream, that streams name existing units and ports, that feeds
have no inlets and every other unit has at least one, and that there is a product.
Recycle loops are found as strongly connected components of the unit graph (used for
circulating loads and to name loops in errors).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from millflow.errors import InputError
from millflow.grid import SizeGrid

__all__ = ["Stream", "Flowsheet"]


@dataclass(frozen=True)
class Stream:
    """A stream from ``source`` unit (outlet ``port``) to ``target`` unit."""

    name: str
    source: str
    port: str
    target: str


@dataclass(frozen=True, eq=False)
class Flowsheet:
    """Units and streams on one size grid.

    Parameters
    ----------
    grid : SizeGrid
    units : dict name -> unit (see :mod:`millflow.flowsheet.units`)
    streams : dict name -> Stream (order kept: it is the order of results)
    title : str
    passing_sizes : tuple of sizes [m] at which % passing is reported
    slurry : :class:`~millflow.flowsheet.water.Slurry` or None (densities of solids and water)
    water_added : dict unit -> water added to its feed [kg/s]
    """

    grid: SizeGrid
    units: dict
    streams: dict
    title: str = ""
    passing_sizes: tuple = ()
    source_file: str = ""
    meta: dict = field(default_factory=dict)
    slurry: object = None
    water_added: dict = field(default_factory=dict)

    def __post_init__(self):
        self._check()

    # ------------------------------------------------------------------ checks
    def _check(self) -> None:
        used: dict[tuple[str, str], str] = {}
        n_in = {u: 0 for u in self.units}
        for name, s in self.streams.items():
            where = f"streams.{name}"
            if s.source not in self.units:
                raise InputError(f"{where}.from: unknown unit {s.source!r}; units: {', '.join(self.units)}")
            if s.target not in self.units:
                raise InputError(f"{where}.to: unknown unit {s.target!r}; units: {', '.join(self.units)}")
            ports = self.units[s.source].ports
            if s.port not in ports:
                valid = ", ".join(f"{s.source}.{p}" for p in ports) or "none: it has no outlets"
                raise InputError(f"{where}.from: unit {s.source!r} has no outlet {s.port!r}; valid: {valid}")
            key = (s.source, s.port)
            if key in used:
                raise InputError(f"{where}: outlet {s.source}.{s.port} is doubly connected "
                                 f"(also to stream {used[key]!r}); split it with a splitter unit")
            used[key] = name
            n_in[s.target] += 1
        for uname, unit in self.units.items():
            for p in unit.ports:
                if (uname, p) not in used:
                    raise InputError(f"units.{uname}: outlet {uname}.{p} is dangling (no stream leaves it); "
                                     f"add a stream with from = \"{uname}.{p}\"")
            if unit.max_inlets == 0 and n_in[uname]:
                raise InputError(f"units.{uname}: a {unit.type} takes no inlet streams, but "
                                 f"{', '.join(self.inlets(uname))} enter it")
            if unit.max_inlets != 0 and n_in[uname] == 0:
                raise InputError(f"units.{uname}: dangling {unit.type} (no stream enters it); "
                                 f"add a stream with to = \"{uname}\"")
        if not any(u.type == "product" for u in self.units.values()):
            raise InputError("units: the flowsheet has no product unit (type = \"product\")")
        if not any(u.type == "feed" for u in self.units.values()):
            raise InputError("units: the flowsheet has no feed unit (type = \"feed\")")

    # ----------------------------------------------------------------- queries
    @property
    def stream_names(self) -> list[str]:
        return list(self.streams)

    def inlets(self, unit: str) -> list[str]:
        return [n for n, s in self.streams.items() if s.target == unit]

    def outlets(self, unit: str) -> list[str]:
        return [n for n, s in self.streams.items() if s.source == unit]

    def outlet(self, unit: str, port: str) -> str:
        for n, s in self.streams.items():
            if s.source == unit and s.port == port:
                return n
        raise KeyError(f"{unit}.{port}")

    def components(self) -> np.ndarray:
        """Strongly connected component label of each unit (order of ``units``): Tarjan's
        algorithm on the unit graph (a few units: plain Python, no sparse matrix), labels
        numbered in the order the components are completed."""
        names = list(self.units)
        succ = {u: [] for u in names}
        for s in self.streams.values():
            succ[s.source].append(s.target)
        index, low, label, stack, on_stack = {}, {}, {}, [], set()
        count = 0
        for root in names:
            if root in index:
                continue
            work = [(root, iter(succ[root]))]
            index[root] = low[root] = len(index)
            stack.append(root)
            on_stack.add(root)
            while work:
                unit, it = work[-1]
                nxt = next(it, None)
                if nxt is not None:
                    if nxt not in index:
                        index[nxt] = low[nxt] = len(index)
                        stack.append(nxt)
                        on_stack.add(nxt)
                        work.append((nxt, iter(succ[nxt])))
                    elif nxt in on_stack:
                        low[unit] = min(low[unit], index[nxt])
                    continue
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[unit])
                if low[unit] == index[unit]:
                    while True:
                        member = stack.pop()
                        on_stack.discard(member)
                        label[member] = count
                        if member == unit:
                            break
                    count += 1
        return np.array([label[u] for u in names])

    def recycle_streams(self) -> list[str]:
        """Streams whose source and target lie in the same recycle loop."""
        lab = dict(zip(self.units, self.components()))
        return [n for n, s in self.streams.items() if lab[s.source] == lab[s.target]]

    def __repr__(self) -> str:
        return (f"Flowsheet({self.title!r}, {len(self.units)} units, {len(self.streams)} streams, "
                f"{self.grid!r})")
