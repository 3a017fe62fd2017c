"""TOML configuration of ``millflow fit`` (see docs/fitting.md for a full example).

Tables and keys (paths relative to the config file)::

    [data]        psd = "psd.csv", process = "process.csv"   # long tables
                  sprite_folder = "..."                      # or the SPRITE knife-mill folder
    [grid]        ratio = 1.0905, top_mm = 32, bottom_mm = 0.05   # optional (auto otherwise)
    [model]       mode, rate, breakage, classification, rate_process = [...],
                  param_process = [["alpha", "moisture"], ...]   # eq. 10 on other parameters
                  screen_column, tau_column, x0_mm, objective, n_tanks
                  mode = "mill": transport = "axial_dispersion", where = "cells" (optional)
                  b_matrix_csv = "b.csv", b_kind = "b" | "B"   # fixed breakage (hybrid fit)
                  t10_table_csv = "tn_t10.csv", t10 = 0.2      # or: B from the ore's t10 family
    [model.transport_params]  n = 10 / pe = 8.0 / n = 5, r = 1.0   # fixed, tau from tau_column
                  kinetics = "population" | "aggregation" | "slowing_down" | ["population", "aggregation"]
    [model.kinetics_params]   kernel = "constant", x_ref_um = 22, fines_um = 250, w = 1.0,
                              kappa = "hyperbolic", t_ref_min = 16     # constants (fitted: lam_pop, beta0, s_slow)
    [params.NAME] value, min, max, vary
    [optimizer]   global = true, starts = 20, popsize = 15, maxiter = 200, seed = 0
    [validation]  hold_out = "each" | ["cond", ...] | [["a", "b"], ...]
    [output]      dir = "fit-results", plots = true   (dir relative to the current folder, as
                  --out; without dir: <config stem>-fit in the current folder, as every command)
    [[candidates]] label = "...", plus any [model] keys: extra forms to rank (AIC/BIC, F)
"""
from __future__ import annotations

import os
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from millflow.breakage import b_from_B, validate_b
from millflow.errors import InputError
from millflow.inputs import (boolean, check_keys, integer, number, quantity, read_csv, read_text, string,
                             read_matrix, table_of, unit_column, unit_keys)
from millflow.fitting.data import PSDData, read_psd_table, read_sprite_folder
from millflow.fitting.models import ModelSpec, auto_grid, default_parameters
from millflow.grid import SizeGrid

__all__ = ["FitConfig", "load_config", "read_b_matrix"]

_TABLES = {"data", "grid", "model", "params", "optimizer", "validation", "output", "candidates", "weights"}
_MODEL_KEYS = {"mode", "rate", "breakage", "classification", "rate_process", "param_process", "screen_column",
               "ball_column", "tau_column", "n_tanks", "transport", "transport_params", "where", "b_matrix_csv",
               "b_kind", "t10_table_csv", "t10", "objective", "label", "transport_fit", "kinetics",
               "kinetics_params"} | unit_keys("x0", "length")
_OPT_KEYS = {"global", "starts", "popsize", "maxiter", "seed"}


@dataclass
class FitConfig:
    path: str
    data: PSDData
    spec: ModelSpec
    params: dict
    grid: SizeGrid | None
    optimizer: dict
    hold_out: object = None
    out_dir: str = "fit-results"
    plots: bool = True
    candidates: list = field(default_factory=list)   # [(label, ModelSpec, params)]
    label: str = "model"
    tracer: object = None                             # DataFrame condition, time_s, F (mode "mill")
    kind_weights: dict = field(default_factory=dict)  # [weights]: data kind -> weight

    def model(self, spec: ModelSpec | None = None, grid: SizeGrid | None = None):
        """The :class:`ForwardModel` of this config (or of a candidate ``spec``), with its
        tracer rows and weights per data kind."""
        from millflow.fitting.models import ForwardModel
        spec = self.spec if spec is None else spec
        tracer = self.tracer if spec.mode == "mill" else None
        return ForwardModel(spec, self.data, grid if grid is not None else self.grid, tracer=tracer,
                            kind_weights=self.kind_weights)


def read_b_matrix(path, grid: SizeGrid, kind: str = "b") -> np.ndarray:
    """Fractional b (N, N) from a CSV of b or cumulative B on the numerical grid.

    Format: N rows of N comma-separated numbers, no header (lines starting with ``#``
    are comments); row i = receiving class, column j = breaking class, classes coarse
    to fine as ``grid.x`` (class N is the sink). ``kind`` "B" is converted by
    :func:`millflow.breakage.b_from_B`; both are validated.
    """
    if kind not in ("b", "B"):
        raise InputError(f"b_kind = {kind!r}: expected 'b' (fractional) or 'B' (cumulative)")
    if not os.path.isfile(path):
        raise InputError(f"b_matrix_csv {path}: file not found")
    try:
        M = read_matrix(path, "b matrix (CSV)")  # encodings and non-numbers named (millflow.inputs)
    except InputError as exc:
        raise InputError(f"b_matrix_csv {exc}; expected N rows of N comma-separated numbers without a "
                         "header") from None
    n = grid.x.size
    if M.shape != (n, n):
        raise InputError(f"b_matrix_csv {path}: shape {M.shape[0]} x {M.shape[1]} does not match the numerical "
                         f"grid of {n} classes ({grid.x[0] * 1e3:.4g} to {grid.x[-1] * 1e3:.4g} mm); "
                         f"expected {n} x {n}")
    try:
        return b_from_B(M, grid.x) if kind == "B" else validate_b(M, grid.x)
    except InputError as exc:
        raise InputError(f"b_matrix_csv {path} (b_kind = {kind!r}): {exc}") from exc


def _spec(table: dict, where: str, rel=None, grid_of=None) -> tuple[str, ModelSpec]:
    unknown = set(table) - _MODEL_KEYS
    if unknown:
        raise InputError(f"{where}: unknown keys {sorted(unknown)}; expected some of {sorted(_MODEL_KEYS)}")
    for k in ("mode", "rate", "breakage", "screen_column", "ball_column", "tau_column", "objective", "transport",
              "b_matrix_csv", "b_kind", "t10_table_csv", "label", "classification"):
        if k in table:
            string(table, k, where)
    for k in ("rate_process", "transport_fit"):
        if k in table and not (isinstance(table[k], list) and all(isinstance(x, str) for x in table[k])):
            raise InputError(f"{where}.{k} = {table[k]!r}: expected a list of names, e.g. [\"speed\"]")
    if "n_tanks" in table:
        integer(table, "n_tanks", where, lo=1)
    if "where" in table and not isinstance(table["where"], (str, list)):
        raise InputError(f"{where}.where = {table['where']!r}: expected a string or a list of cell numbers")
    x0 = quantity(table, "x0", "length", where, None)  # x0_um, x0_mm or x0_m
    if "t10" in table:
        number(table, "t10", where, lo=0.0, hi=1.0)
    kw = {k: table[k] for k in ("mode", "rate", "breakage", "screen_column", "ball_column", "tau_column", "objective",
                                "n_tanks", "transport", "where")
          if k in table}
    if "transport_fit" in table:
        kw["transport_fit"] = tuple(table["transport_fit"])
    if "transport_params" in table:
        if not isinstance(table["transport_params"], dict):
            raise InputError(f"{where}: transport_params must be a table, e.g. [model.transport_params] n = 10")
        kw["transport_params"] = dict(table["transport_params"])
    if "b_kind" in table and "b_matrix_csv" not in table:
        raise InputError(f"{where}: b_kind needs b_matrix_csv")
    if "b_matrix_csv" in table:
        if kw.setdefault("breakage", "fixed") != "fixed":
            raise InputError(f"{where}: b_matrix_csv fixes B; breakage must be 'fixed' (or omitted), "
                             f"not {kw['breakage']!r}")
        kw["b_matrix"] = read_b_matrix(rel(str(table["b_matrix_csv"])), grid_of(), str(table.get("b_kind", "b")))
    elif "t10_table_csv" in table or "t10" in table:
        # hybrid fit with B from the ore's t10 family at a measured t10 (fixed)
        if "t10_table_csv" not in table or "t10" not in table:
            raise InputError(f"{where}: a t10 breakage needs both t10_table_csv = \"file.csv\" and t10 = <fraction>")
        if kw.setdefault("breakage", "fixed") != "fixed":
            raise InputError(f"{where}: t10 fixes B; breakage must be 'fixed' (or omitted), not {kw['breakage']!r}")
        from millflow.breakage.t10 import T10Breakage, read_t10_table

        model = T10Breakage(float(table["t10"]), read_t10_table(rel(str(table["t10_table_csv"]))))
        kw["b_matrix"] = model.b(grid_of())
    elif kw.get("breakage") == "fixed":
        raise InputError(f"{where}: breakage = 'fixed' needs b_matrix_csv = \"file.csv\" (b or B on the grid)"
                         " or t10_table_csv and t10")
    if "classification" in table:
        c = table["classification"]
        kw["classification"] = None if c in ("none", "", None) else c
    if "rate_process" in table:
        kw["rate_process"] = tuple(table["rate_process"])
    if "param_process" in table:
        pp = table["param_process"]
        if not all(isinstance(x, list) and len(x) == 2 for x in pp):
            raise InputError(f"{where}: param_process must be a list of [parameter, process column] pairs")
        kw["param_process"] = tuple(tuple(x) for x in pp)
    if x0 is not None:
        kw["x0_m"] = x0
    if "kinetics" in table:
        kw["kinetics"], kw["kinetics_params"] = _kinetics(table, where)
    elif "kinetics_params" in table:
        raise InputError(f"{where}.kinetics_params: given without kinetics = \"population\" (or slowing_down, "
                         "aggregation, a list)")
    try:
        spec = ModelSpec(**kw)
    except (TypeError, ValueError) as exc:
        if isinstance(exc, InputError):
            raise
        raise InputError(f"{where}: {exc}") from exc
    return str(table.get("label", spec.label())), spec


def _kinetics(table: dict, where: str) -> tuple:
    """``kinetics`` (a name or a list) and ``[model.kinetics_params]`` with units in the
    key names: kernel, kappa, w (plain), x_ref_<length>, fines_<length>, t_ref_<time>."""
    k = table["kinetics"]
    if not (isinstance(k, str) or (isinstance(k, list) and k and all(isinstance(x, str) for x in k))):
        raise InputError(f"{where}.kinetics = {k!r}: expected a name or a list of names, e.g. \"aggregation\" or "
                         "[\"population\", \"aggregation\"]")
    kp = table.get("kinetics_params", {})
    kw = f"{where}.kinetics_params"
    if not isinstance(kp, dict):
        raise InputError(f"{kw}: expected a table, e.g. [model.kinetics_params] kernel = \"constant\"")
    used: set = set()
    consts = {}
    for base, dim, name in (("x_ref", "length", "x_ref_m"), ("fines", "length", "fines_m"),
                            ("t_ref", "time", "t_ref_s")):
        v = quantity(kp, base, dim, kw, None, used=used)
        if v is not None:
            consts[name] = v
    for key in ("kernel", "kappa"):
        if key in kp:
            consts[key] = string(kp, key, kw)
            used.add(key)
    if "w" in kp:
        consts["w"] = number(kp, "w", kw, lo=0.0, lo_open=True)
        used.add("w")
    unknown = sorted(set(kp) - used)
    if unknown:
        raise InputError(f"{kw}: unknown keys {unknown}; expected some of kernel, kappa, w, x_ref_um, fines_um, "
                         "t_ref_s (or other units)")
    return (k,) if isinstance(k, str) else tuple(k), consts


def load_config(path, data_dir: str | None = None) -> FitConfig:
    """Read and check a fit configuration; ``data_dir`` overrides ``data.sprite_folder``."""
    path = os.fspath(path)
    if not os.path.isfile(path):
        raise InputError(f"{path}: config file not found")
    try:
        cfg = tomllib.loads(read_text(path, "config"))
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"{path}: not valid TOML ({exc})") from exc
    unknown = set(cfg) - _TABLES
    if unknown:
        raise InputError(f"{path}: unknown tables {sorted(unknown)}; expected some of {sorted(_TABLES)}")
    base = os.path.dirname(os.path.abspath(path))
    rel = lambda p: p if os.path.isabs(p) else os.path.normpath(os.path.join(base, p))  # noqa: E731
    where = f"{path}: "
    d = table_of(cfg, "data", where)
    check_keys(d, {"sprite_folder", "psd", "process", "tracer"}, f"{path} [data]")
    for key in d:
        string(d, key, f"{path} [data]")
    if data_dir is not None:
        data = read_sprite_folder(data_dir)
    elif "sprite_folder" in d:
        data = read_sprite_folder(rel(d["sprite_folder"]))
    elif "psd" in d:
        data = read_psd_table(rel(d["psd"]), rel(d["process"]) if "process" in d else None)
    else:
        raise InputError(f"{path}: [data] needs 'psd' (and 'process') or 'sprite_folder'")
    g = table_of(cfg, "grid", where)
    gw = f"{path} [grid]"
    for edge in ("top", "bottom"):  # a bare or misspelt unit is named before unknown keys are
        quantity(g, edge, "length", gw, None)
    check_keys(g, {"ratio"} | unit_keys("top", "length") | unit_keys("bottom", "length"), gw)
    grid = None
    if g:
        ratio = number(g, "ratio", gw, 2 ** 0.25, lo=1.0, lo_open=True)
        sizes = data.table.size_m[data.table.size_m > 0]
        top = quantity(g, "top", "length", gw, None)        # top_um, top_mm or top_m
        bottom = quantity(g, "bottom", "length", gw, None)
        top = top if top is not None else float(sizes.max())  # on the coarsest size: sieves fall on edges
        bottom = bottom if bottom is not None else float(sizes.min()) / 2
        if not bottom < top:
            raise InputError(f"{gw}: bottom {bottom * 1e3:g} mm is not below top {top * 1e3:g} mm")
        try:
            grid = SizeGrid.between(top, bottom, ratio)
        except InputError as exc:
            raise InputError(f"{gw}: {exc}") from None

    def grid_of():  # a fixed b matrix belongs to the grid: make the automatic grid explicit
        nonlocal grid
        if grid is None:
            grid = auto_grid(data)
        return grid

    label, spec = _spec(cfg.get("model", {}), f"{path} [model]", rel, grid_of)
    params = default_parameters(spec, table_of(cfg, "params", where), where=f"{path} [params]")
    opt = table_of(cfg, "optimizer", where)
    ow = f"{path} [optimizer]"
    check_keys(opt, _OPT_KEYS, ow)
    opt = {"global_search": boolean(opt, "global", ow, True), "starts": integer(opt, "starts", ow, 20, lo=1),
           "popsize": integer(opt, "popsize", ow, 15, lo=1), "maxiter": integer(opt, "maxiter", ow, 200, lo=1),
           "seed": integer(opt, "seed", ow, 0, lo=0)}
    val = table_of(cfg, "validation", where)
    check_keys(val, {"hold_out"}, f"{path} [validation]")
    out = table_of(cfg, "output", where)
    check_keys(out, {"dir", "plots"}, f"{path} [output]")
    # default: <config stem>-fit in the current folder, as every command (docs/cli.md)
    out_dir = string(out, "dir", f"{path} [output]", "") if "dir" in out else None
    plots = boolean(out, "plots", f"{path} [output]", True)
    cands = []
    for k, c in enumerate(cfg.get("candidates", [])):
        c = dict(c)
        cp = c.pop("params", {})
        lab, sp = _spec(c, f"{path} [[candidates]] #{k + 1}", rel, grid_of)
        cands.append((lab, sp, default_parameters(sp, cp, where=f"{path} [[candidates]] #{k + 1} params")))
    tracer = read_tracer_table(rel(d["tracer"])) if "tracer" in d else None
    if tracer is not None and spec.mode != "mill":
        raise InputError(f"{path} [data] tracer: tracer data need [model] mode = 'mill' (mode is {spec.mode!r})")
    wt = table_of(cfg, "weights", where)
    weights = {str(k): number(wt, k, f"{path} [weights]", lo=0.0) for k in wt}
    # in the current folder, as --out and every command's default (docs/cli.md)
    out_dir = str(Path(out_dir).absolute()) if out_dir is not None else str(Path.cwd() / f"{Path(path).stem}-fit")
    return FitConfig(path, data, spec, params, grid, opt, val.get("hold_out"), out_dir,
                     plots, cands, label, tracer, weights)


def read_tracer_table(path):
    """Tracer F(t) table (CSV): columns ``condition``, ``time_<unit>`` (``time_s``, ``time_min``,
    ``time_h``: :func:`millflow.inputs.unit_column`), ``F`` (fraction of a pulse that has left
    by t, 0..1, or a step response)."""
    import pandas as pd
    if not os.path.isfile(path):
        raise InputError(f"{path}: tracer table not found")
    try:
        t = read_csv(path, "tracer table")
    except (ValueError, pd.errors.ParserError) as exc:
        raise InputError(f"{path}: cannot read the tracer table as CSV ({exc})") from exc
    t.columns = [str(c).strip() for c in t.columns]
    tcol, factor = unit_column(t.columns, "time", "time", str(path))  # time_s, time_min, time_h
    missing = [c for c in ("condition", "F") if c not in t.columns]
    if missing:
        raise InputError(f"{path}: columns {missing} missing; expected condition, time_<unit> (time_s, time_min, "
                         "time_h), F")
    t = t.assign(time_s=pd.to_numeric(t[tcol], errors="coerce") * factor) if tcol != "time_s" else t
    for col in ("time_s", "F"):
        v = pd.to_numeric(t[col], errors="coerce")
        if v.isna().any():
            row = int(v.isna().to_numpy().argmax())
            raise InputError(f"{path}: row {row + 2}, column {col}: {t[col].iloc[row]!r} is not a number")
        t[col] = v.astype(float)
    t["condition"] = t["condition"].astype(str)
    return t[["condition", "time_s", "F"]]

