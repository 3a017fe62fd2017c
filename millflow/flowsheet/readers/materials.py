"""Materials: breakage rates (eqs. 5 and 7, per time or per energy), breakage functions
(eqs. 6 and 8, or a user's matrix), and materials from a ``millflow fit --json`` result
(eq. 10 at the process values the flowsheet states)."""
from __future__ import annotations

from pathlib import Path

from millflow.breakage import AustinRate, NonNormalizedBreakage, NormalizedBreakage, PowerLawRate
from millflow.breakage.energy import EnergySpecificRate, from_lab
from millflow.errors import InputError
from millflow.flowsheet.readers.tables import _named_file, _Table, _wrap
from millflow.grid import SizeGrid
from millflow.inputs import read_matrix


def _rate(t: _Table):
    if any(k.startswith("A_E_") for k in t.data):
        return _energy_rate(t)
    form = t.plain("form", kind=str)
    if form == "power":
        A = t.quantity("A", "rate", allow_zero=True)
        alpha = t.plain("alpha", kind=float)
        x0 = t.quantity("x0", "length", 1e-3)
        t.finish("form, A_per_min, alpha, x0_um")
        return _wrap(t.where, PowerLawRate, A, alpha, x0)
    if form == "austin":
        A = t.quantity("A", "rate", allow_zero=True)
        alpha = t.plain("alpha", kind=float)
        mu = t.quantity("mu", "length")
        Lam = t.plain("Lambda", kind=float)
        x0 = t.quantity("x0", "length", 1e-3)
        xi = t.plain("xi", 0.0, kind=float)
        eta = t.plain("eta", 0.0, kind=float)
        xb = t.quantity("x_b", "length", None)
        xb0 = t.quantity("x_b0", "length", None)
        t.finish("form, A_per_min, alpha, mu_um, Lambda, x0_um, and for ball size: x_b_mm (ball), x_b0_mm "
                 "(reference ball), xi, eta")
        return _wrap(t.where, AustinRate, A, alpha, mu, Lam, xi=xi, x_b=xb, x_b0=xb0, eta=eta, x0=x0)
    raise InputError(f"{t.where}.form = {form!r}: unknown rate form; valid: austin, power")


def _energy_rate(t: _Table) -> EnergySpecificRate:
    """A rate table given per energy (``A_E_t_per_kWh``): S^E of S = S^E P / H (Herbst-Fuerstenau)."""
    A = t.quantity("A_E", "energy_rate", allow_zero=True)
    key = next(k for k in t.data if k.startswith("A_E_"))
    rest = {k: v for k, v in t.data.items() if k != key}
    if any(k.startswith("A_") for k in rest):
        raise InputError(f"{t.where}: {key} and {next(k for k in rest if k.startswith('A_'))} both give A; "
                         "keep one (A_E_<unit> per energy, or A_<unit> per time)")
    rest["A_per_s"] = A  # S^E [kg/J] carried through the same rate form
    inner = _rate(_Table(rest, t.where))
    t.used.update(t.data)
    return EnergySpecificRate(inner, source=f"{t.where}.{key}")


def _per_energy(t: _Table, rate):
    """``per_energy = {lab_power_kW, lab_holdup_kg}``: a time rate measured in a lab mill carried
    per energy, S^E = S_lab H_lab / P_lab."""
    P = t.quantity("lab_power", "power")
    H = t.quantity("lab_holdup", "mass")
    t.finish("lab_power_kW, lab_holdup_kg")
    if rate is None:
        raise InputError(f"{t.where}: the material has no rate to carry per energy")
    if getattr(rate, "basis", "time") == "energy":
        raise InputError(f"{t.where}: the rate is already per energy (A_E_...); remove per_energy")
    return from_lab(rate, P, H)


def _breakage_table(t: _Table, base: Path | None, grid: SizeGrid | None):
    """A user's b_ij or B_ij matrix from a CSV file (N x N numbers, no header, class 1 first)."""
    from millflow.breakage import TabulatedBreakage

    name = t.plain("file", kind=str)
    kind = t.plain("matrix", kind=str)
    t.finish("form, file, matrix (\"b\" or \"B\")")
    if kind not in ("b", "B"):
        raise InputError(f"{t.where}.matrix = {kind!r}: expected \"b\" (fractional, eq. 2) or \"B\" (cumulative)")
    p = _named_file(name, base)
    if not p.is_file():
        raise InputError(f"{t.where}.file: {p} not found")
    M = read_matrix(p, "breakage matrix (CSV)")  # encodings and non-numbers named (millflow.inputs)
    if M.shape[0] != M.shape[1]:
        raise InputError(f"{p}: a {M.shape[0]} x {M.shape[1]} matrix; expected square (N x N)")
    if grid is not None and M.shape[0] != grid.n:
        raise InputError(f"{p}: a {M.shape[0]} x {M.shape[0]} matrix but the grid has {grid.n} classes; give the "
                         "matrix on the flowsheet's grid")
    return _wrap(str(p), TabulatedBreakage, **{kind: M})


def _breakage(t: _Table, base: Path | None = None, grid: SizeGrid | None = None):
    form = t.plain("form", kind=str)
    if form == "table":
        return _breakage_table(t, base, grid)
    if form == "normalized":
        args = [t.plain(k, kind=float) for k in ("phi", "gamma", "beta")]
        t.finish("form, phi, gamma, beta")
        return _wrap(t.where, NormalizedBreakage, *args)
    if form == "non_normalized":
        args = [t.plain(k, kind=float) for k in ("phi0", "gamma", "beta", "theta")]
        xmax = t.quantity("x_max", "length", None)
        t.finish("form, phi0, gamma, beta, theta, x_max_um")
        return _wrap(t.where, NonNormalizedBreakage, *args, xmax)
    raise InputError(f"{t.where}.form = {form!r}: unknown breakage form; valid: non_normalized, normalized, table")


def _fitted_material(m: _Table, base: Path | None) -> dict:
    """A material's rate and breakage from a ``millflow fit --json`` result: the estimate (eqs. 5-7),
    A at the process values the flowsheet states (eq. 10, keys as the fit's process columns)."""
    from millflow.scaleup.fitted import load_fit

    name = m.plain("fit", kind=str)
    process = m.plain("process", {})
    if not isinstance(process, dict):
        raise InputError(f"{m.where}.process = {process!r}: expected a table of the fit's process values")
    m.finish("fit, process, per_energy")
    p = _named_file(name, base, folder_file="fit.json")
    if not p.is_file():
        raise InputError(f"{m.where}.fit: {p} not found")
    fitted = load_fit(p)
    cols = fitted.spec.get("rate_process", [])
    extra = sorted(set(process) - set(cols))
    if extra:
        raise InputError(f"{m.where}.process.{extra[0]}: not a process variable of the fit (its eq. 10 uses "
                         f"{cols or 'none'})")
    for k, v in process.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)):
            raise InputError(f"{m.where}.process.{k} = {v!r}: expected a number")
    proc = fitted.check_process(process, f"{m.where}.process")
    # the fit's own translator decodes its vector (millflow.scaleup.fitted: FittedRate, FittedDistribution)
    return {"rate": fitted.rate_model(process=proc), "breakage": fitted.distribution_model()}


def _materials(mt: _Table | None, base: Path | None, grid: SizeGrid) -> dict:
    """The ``[materials]`` tables: name -> {"rate": ..., "breakage": ...}."""
    materials = {}
    if mt is None:
        return materials
    for mname in mt.data:
        m = mt.sub(mname)
        per_energy = m.sub("per_energy", None)
        if "fit" in m.data:
            materials[mname] = _fitted_material(m, base)
            if per_energy is not None:
                materials[mname]["rate"] = _per_energy(per_energy, materials[mname]["rate"])
            continue
        materials[mname] = {}
        if "rate" in m.data:
            materials[mname]["rate"] = _rate(m.sub("rate"))
        if "breakage" in m.data:
            materials[mname]["breakage"] = _breakage(m.sub("breakage"), base, grid)
        if per_energy is not None:
            materials[mname]["rate"] = _per_energy(per_energy, materials[mname].get("rate"))
        m.finish("rate, breakage, per_energy (or fit = \"fit.json\" with process = {...})")
    return materials
