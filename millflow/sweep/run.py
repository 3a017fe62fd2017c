"""Solving a sweep's cases: serially, on a LocalCluster, or on a Dask scheduler."""
from __future__ import annotations

import copy
import math
import os
import re
import time

import numpy as np
import xarray as xr

from millflow.errors import InputError, MillflowError
from millflow.sweep.cases import Axis, grid_cases, latin_hypercube_cases, set_key

__all__ = ["CaseSolver", "solve_case", "run_sweep", "SCHEDULERS"]

#: "local": a dask.distributed LocalCluster on this machine; "serial": this process; any
#: other value is the address of a running Dask scheduler (e.g. tcp://10.0.0.5:8786).
SCHEDULERS = ("local", "serial")


def _products(data: dict) -> list[str]:
    """Streams that end in a product unit, in file order."""
    units = data.get("units", {})
    return [n for n, s in data.get("streams", {}).items()
            if isinstance(s, dict) and units.get(s.get("to"), {}).get("type") == "product"]


class CaseSolver:
    """Solves cases of one flowsheet document, rebuilding only the units a case changes.

    Solves cases of one flowsheet document: the base flowsheet is built once; a case
    that changes keys of units (``units.<unit>.<key>``) rebuilds those units only
    (:func:`millflow.flowsheet.io.with_units`: a mill keeps its class-averaged breakage),
    each unit variant once (units are stateless: the cases of a grid that share a unit's
    values share the unit); any other key (grid, materials, streams) builds the case's
    whole flowsheet again.
    Each case is summarised by :func:`millflow.flowsheet.results.key_figures` (the product
    streams' P80 and P50, circulating loads, kWh/t, mass balance). :meth:`solve_all` solves
    a chunk of cases inside one single-threaded BLAS context
    (:func:`millflow.threads.single_threaded_blas`, which each :func:`~millflow.flowsheet.solve`
    would otherwise enter and leave).
    """

    def __init__(self, data: dict, source: str = "<sweep>"):
        from millflow.flowsheet import from_dict

        self.data, self.source = data, source
        self.products = _products(data)  # the streams whose P80 and P50 a sweep keeps
        self._units = {}  # (unit, its varied values) -> (unit, water added, table): units are stateless
        self._plans = {}  # the keys of a case -> which unit each key changes (None: build whole)
        try:
            self.base = from_dict(copy.deepcopy(data), source=source)
        except MillflowError:
            self.base = None  # every case is built whole (and says why it fails)
        else:
            for unit in self.base.units.values():  # the mills' forms on the grid, kept by the cases' mills
                if unit.type == "mill":
                    try:  # (rates per energy then ask for tau and raise: the forms are kept all the same)
                        unit.breakage_functions(self.base.grid)
                    except MillflowError:
                        pass

    def _plan(self, keys: tuple):
        """Which units a case's keys vary.

        ((unit, (its varied keys, sorted)), ...) of a case's keys when every key is a unit's
        (``units.<unit>.<key>...``), else None; once per set of keys (a sweep's cases share them).
        """
        plan = self._plans.get(keys, ...)
        if plan is ...:
            units = {}
            for key in keys:
                parts = key.split(".")
                if parts[0] != "units" or len(parts) < 3 or self.base is None:
                    units = None
                    break
                units.setdefault(parts[1], []).append(key)
            plan = None if units is None else tuple((u, tuple(sorted(k))) for u, k in units.items())
            if len(self._plans) >= 64:
                self._plans.pop(next(iter(self._plans)))
            self._plans[keys] = plan
        return plan

    def flowsheet(self, case: dict):
        """The case's flowsheet (raises MillflowError naming what is wrong)."""
        plan = self._plan(tuple(case))
        if plan is None:
            from millflow.flowsheet import from_dict

            d = copy.deepcopy(self.data)
            for key, value in case.items():
                set_key(d, key, value)
            return from_dict(d, source=self.source)
        from millflow.flowsheet.io import with_units

        tables, built = {}, {}
        for uname, keys in plan:
            memo = (uname, tuple([case[k] for k in keys]))
            got = self._units.get(memo)
            if got is None:  # a grid repeats each unit's values in many cases: built once each
                got = self._build_unit(uname, keys, case)
                if len(self._units) >= _UNITS_KEPT:
                    self._units.pop(next(iter(self._units)))
                self._units[memo] = got
            built[uname], tables[uname] = got[:2], got[2]
        return with_units(self.base, tables, built)

    def _build_unit(self, uname: str, keys: tuple, case: dict) -> tuple:
        """(unit, water added, its table) of unit ``uname`` with the case's values of ``keys``."""
        from millflow.flowsheet.io import unit_from_table

        source = self.data.get("units", {})
        wrap = {"units": {uname: source[uname]} if uname in source else {}}
        for key in keys:
            _set_copied(wrap, key, case[key])  # copies along the key's path: the document is shared
        table = wrap["units"][uname]
        unit, added = unit_from_table(self.base, uname, table)
        return unit, added, table

    def solve(self, case: dict) -> dict:
        """One case solved, reduced to the figures a sweep keeps.

        One case solved: ``{"p80_um": {stream: v}, "p50_um": {...}, "circulating_load":
        {recycle stream: v}, "specific_energy_kWh_per_t", "mass_balance_error", "runtime_s",
        "reason"}``; a case that cannot be built or solved returns NaNs and its one-line reason.
        """
        return self.solve_all([case])[0]

    def solve_all(self, cases) -> list[dict]:
        """Solve cases in order.

        :meth:`solve` of each case, in order, inside one single-threaded BLAS context
        (:func:`millflow.threads.single_threaded_blas`), in blocks of :data:`BLOCK` cases:
        a block's flowsheets are built, then solved, then reduced to their key figures. The
        work is that of case after case; a step repeated over a block runs with its code and
        data in the processor's caches, which the other steps would evict (measured ~5 %
        of a case).
        """
        from millflow.flowsheet import solve
        from millflow.flowsheet.results import key_figures
        from millflow.threads import single_threaded_blas

        clock, out = time.perf_counter, []
        with single_threaded_blas():
            for start in range(0, len(cases), BLOCK):
                block = [[case, 0.0] for case in cases[start:start + BLOCK]]  # [what it has become, seconds]
                for step in (self.flowsheet, solve, lambda sol: key_figures(sol, self.products)):
                    for item in block:
                        if isinstance(item[0], MillflowError):
                            continue
                        t0 = clock()
                        try:
                            item[0] = step(item[0])
                        except MillflowError as exc:
                            item[0] = exc
                        item[1] += clock() - t0
                for result, seconds in block:
                    if isinstance(result, MillflowError):
                        out.append({"reason": " ".join(str(result).split()), "runtime_s": seconds})
                    else:
                        result.update(runtime_s=seconds, reason="")
                        out.append(result)
        return out


#: Cases a CaseSolver builds, then solves, then reduces together (see :meth:`CaseSolver.solve_all`).
BLOCK = 32

#: Unit variants a CaseSolver keeps (a grid of 100 x 100 cases has 200 of them).
_UNITS_KEPT = 4096


def _set_copied(tables: dict, key: str, value: float) -> None:
    """Set a key on copies of the tables along its path.

    :func:`set_key` on copies of the tables along the key's path (the document the
    sweep shares between its cases is never written).
    """
    node = tables
    for part in key.split(".")[:-1]:
        if not isinstance(node, dict) or not isinstance(node.get(part), dict):
            break  # set_key names the missing table
        node[part] = dict(node[part])
        node = node[part]
    set_key(tables, key, value)


def solve_case(data: dict, case: dict, source: str = "<sweep>") -> dict:
    """One case solved on its own.

    One case on its own: the flowsheet dict with the case's values set, built whole,
    solved and reduced to the figures :meth:`CaseSolver.solve` returns (a sweep keeps one
    CaseSolver for all its cases instead).
    """
    from millflow.flowsheet import from_dict, solve
    from millflow.flowsheet.results import key_figures

    t0 = time.perf_counter()
    try:
        d = copy.deepcopy(data)
        for key, value in case.items():
            set_key(d, key, value)
        out = key_figures(solve(from_dict(d, source=source)), _products(data))
    except MillflowError as exc:
        return {"reason": " ".join(str(exc).split()), "runtime_s": time.perf_counter() - t0}
    out.update(runtime_s=time.perf_counter() - t0, reason="")
    return out


def _solve_chunk(data: dict, cases: list[dict], source: str) -> list[dict]:
    return CaseSolver(data, source).solve_all(cases)


def _num(v) -> float:
    return float("nan") if v is None or not isinstance(v, (int, float)) or not math.isfinite(v) else float(v)


def run_sweep(path, vary: list[Axis], *, samples: int | None = None, seed: int = 0, scheduler: str = "local",
              workers: int | None = None, chunk: int | None = None, progress: bool = True) -> xr.Dataset:
    """Solve the flowsheet file ``path`` for every case of ``vary``.

    Solve the flowsheet file ``path`` for every case of ``vary`` (a grid, or
    ``samples`` Latin-hypercube cases); see the package docstring for the Dataset.
    """
    from millflow.flowsheet import from_dict
    from millflow.inputs import read_toml

    if not vary:
        raise InputError("sweep: give at least one --vary KEY=START:STOP:N")
    keys = [a.key for a in vary]
    if len(set(keys)) != len(keys):
        raise InputError(f"sweep: a key is varied twice ({', '.join(keys)})")
    _check_design(vary, samples, seed, scheduler)
    data = read_toml(path, "flowsheet file")
    source = str(path)
    from_dict(copy.deepcopy(data), source=source)  # the base flowsheet must be valid
    for key in keys:  # and every varied key must exist and be a number
        set_key(copy.deepcopy(data), key, 0.0)
    cases = grid_cases(vary) if samples is None else latin_hypercube_cases(vary, samples, seed)
    results = _execute(data, cases, source, scheduler, workers, chunk, progress)
    products = _products(data)
    loads = sorted({u for r in results for u in r.get("circulating_load", {})})
    n = len(cases)
    p80 = np.array([[_num(r.get("p80_um", {}).get(s)) for s in products] for r in results]).reshape(n, len(products))
    p50 = np.array([[_num(r.get("p50_um", {}).get(s)) for s in products] for r in results]).reshape(n, len(products))
    cl = np.array([[_num(r.get("circulating_load", {}).get(u)) for u in loads] for r in results]).reshape(n, len(loads))
    scalar = {k: np.array([_num(r.get(k)) for r in results])
              for k in ("specific_energy_kWh_per_t", "mass_balance_error", "runtime_s")}
    reason = np.array([r.get("reason", "") for r in results], dtype=object)
    ds = xr.Dataset(
        {"p80_um": (("case", "product"), p80, {"units": "um", "long_name": "P80 of the product stream"}),
         "p50_um": (("case", "product"), p50, {"units": "um", "long_name": "P50 of the product stream"}),
         "circulating_load": (("case", "recycle_stream"), cl, {"units": "1", "long_name": "recycle / new feed"}),
         "specific_energy_kWh_per_t": ("case", scalar["specific_energy_kWh_per_t"], {"units": "kWh/t"}),
         "mass_balance_error": ("case", scalar["mass_balance_error"], {"units": "1"}),
         "runtime_s": ("case", scalar["runtime_s"], {"units": "s"}),
         "reason": ("case", reason.astype(str), {"long_name": "why a case failed ('' if solved)"})},
        coords={"case": np.arange(n), "product": products, "recycle_stream": loads,
                **{k: ("case", np.array([c[k] for c in cases]), {"long_name": f"varied: {k}"}) for k in keys}})
    ds.attrs.update(source_file=source, design="grid" if samples is None else f"latin hypercube, seed {seed}",
                    n_cases=n, n_failed=int(np.sum(reason != "")), scheduler=scheduler,
                    varied=", ".join(f"{a.key}={a.start:g}:{a.stop:g}:{a.n}" for a in vary))
    # a dimension of length 0 (an open circuit has no recycle stream; when every case
    # fails none is known) is read back by netCDF as the unlimited one and breaks the file,
    # and it empties the tidy table: such variables are left out and said so
    for dim in ("recycle_stream", "product"):
        if ds.sizes[dim] == 0:
            gone = [v for v in ds.data_vars if dim in ds[v].dims]
            ds = ds.drop_vars(gone + [dim])
            ds.attrs[f"no_{dim}"] = f"no {dim.replace('_', ' ')} in the solved cases: {', '.join(gone)} left out"
    if samples is None and len(keys) == 1:  # a grid: one dimension per varied key
        ds = ds.swap_dims(case=keys[0]).drop_vars("case")
    elif samples is None:
        ds = ds.set_index(case=keys).unstack("case")
    return ds


#: Most cases a sweep takes: each case is a flowsheet solve (~0.01-1 s) and a row of the
#: results; beyond this the case list alone would not fit in memory.
MAX_CASES = 1_000_000

_ADDRESS = re.compile(r"^(?:[a-z][a-z0-9+]*://)?[\w.\-\[\]:]+:\d+$")


def _check_design(vary, samples, seed, scheduler) -> None:
    """Refuse, before anything is built, a sweep that cannot run.

    Too many cases, a seed numpy does not take, a scheduler that is neither a name nor an
    address.
    """
    n = samples if samples is not None else math.prod(a.n for a in vary)
    if samples is not None and samples < 1:
        raise InputError(f"--samples {samples}: expected a whole number >= 1")
    if n > MAX_CASES:
        raise InputError(f"sweep: {n:.4g} cases; at most {MAX_CASES:,} are run (split the sweep, or use "
                         "--samples for a Latin hypercube)")
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or not 0 <= seed < 2**32:
        raise InputError(f"--seed {seed}: expected a whole number 0 .. 2**32 - 1")
    if scheduler not in SCHEDULERS and not (isinstance(scheduler, str) and _ADDRESS.match(scheduler)):
        raise InputError(f"--scheduler {scheduler!r}: expected 'local', 'serial' or a Dask scheduler address "
                         "such as tcp://10.0.0.5:8786")


def _execute(data, cases, source, scheduler, workers, chunk, progress) -> list[dict]:
    """Results in case order. Chunks of cases are the tasks (per-case overhead small)."""
    n_workers = workers or os.cpu_count() or 1
    size = chunk or max(1, math.ceil(len(cases) / (4 * n_workers)))
    chunks = [cases[i:i + size] for i in range(0, len(cases), size)]
    if scheduler == "serial":
        out = []
        bar = _bar(len(cases), progress)
        solver = CaseSolver(data, source)  # one base flowsheet and one set of unit variants for every chunk
        for c in chunks:
            out += solver.solve_all(c)
            bar.update(len(c))
        bar.close()
        return out
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise InputError("sweep on Dask needs dask[distributed]: python -m pip install 'dask[distributed]' "
                         "(or --scheduler serial)") from None
    cluster = None
    if scheduler == "local":
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, dashboard_address=None)
        client = Client(cluster)
    else:
        try:
            client = Client(scheduler, timeout="10s")
        except OSError as exc:
            raise InputError(f"--scheduler {scheduler}: cannot connect ({exc})") from None
    try:
        futures = client.map(_solve_chunk, [data] * len(chunks), chunks, [source] * len(chunks),
                             retries=2, pure=False)  # a lost worker's chunk is run again
        index = {f.key: k for k, f in enumerate(futures)}
        parts = [None] * len(chunks)
        bar = _bar(len(cases), progress)
        for fut in as_completed(futures):
            k = index[fut.key]
            parts[k] = fut.result()
            bar.update(len(chunks[k]))
        bar.close()
    finally:
        client.close()
        if cluster is not None:
            cluster.close()
    return [r for p in parts for r in p]


def _bar(total: int, progress: bool):
    """A tqdm bar on stderr (off with progress=False, or when tqdm is absent)."""
    class _Null:
        def update(self, n):
            pass

        def close(self):
            pass
    if not progress:
        return _Null()
    try:
        from tqdm import tqdm
    except ImportError:
        return _Null()
    return tqdm(total=total, unit="case", desc="sweep", mininterval=1.0)
