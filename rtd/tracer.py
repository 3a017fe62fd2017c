"""Tracer data: reading, checking, baseline, moments with a tail, convolution with an inlet.

A tracer curve is the outlet concentration c(t) after a pulse (E-curve data) or a step
(F-curve data) at the inlet. ``read_tracer_csv`` reads a CSV with a time column whose
name carries the unit (``time_s``, ``time_min``, ``time_h``) and a ``concentration``
column (or ``F`` for a step response), optionally an ``inlet`` column with the measured
inlet concentration when the injection was not an ideal pulse. ``check_tracer`` refuses
data that no fit can use (NaN, non-increasing times, all zeros, strongly negative
values) and says which row. Moments are trapezoid integrals; when the curve is cut off
before it returns to baseline an exponential tail c = c_T exp(-(t - T)/lambda) fitted to
the last descending points is added analytically, and the result says so.
"""
from __future__ import annotations

import io
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from rtd.models import RTDError

TIME_COLUMN = re.compile(r"^time_([A-Za-z]+)$")
TIME_UNITS = {"s": "s", "sec": "s", "min": "min", "h": "h", "hr": "h", "d": "d", "ms": "ms"}


class TracerError(RTDError):
    """Tracer data cannot be used; ``column`` names the offending column if known."""

    def __init__(self, message: str, column: str | None = None):
        super().__init__(message)
        self.column = column


@dataclass(frozen=True, eq=False)
class TracerCurve:
    """Checked tracer data.

    Attributes
    ----------
    t : array
        Times [time_unit], strictly increasing.
    c : array
        Outlet concentration [any unit] (pulse) or F-curve values (step).
    kind : {"pulse", "step"}
    time_unit : str
        Unit of ``t`` as read from the column name ("s", "min", "h", ...).
    inlet : array or None
        Measured inlet concentration on the same times (non-ideal pulse).
    source : str
        File it came from, if any.
    notes : tuple of str
        Corrections applied (baseline, tail, ...), in order.
    """

    t: np.ndarray
    c: np.ndarray
    kind: str = "pulse"
    time_unit: str = ""
    inlet: np.ndarray | None = None
    source: str = ""
    notes: tuple = field(default_factory=tuple)

    def with_notes(self, *notes: str, **changes) -> "TracerCurve":
        """A copy with ``notes`` appended and the fields in ``changes`` replaced."""
        from dataclasses import replace
        return replace(self, notes=self.notes + tuple(notes), **changes)


def noise_level(c: np.ndarray) -> float:
    """Robust noise standard deviation from second differences (MAD / sqrt(6))."""
    if c.size < 5:
        return 0.0
    d2 = np.diff(c, 2)
    return float(1.4826 * np.median(np.abs(d2 - np.median(d2))) / math.sqrt(6))


def check_tracer(t, c, kind: str = "pulse", column: str = "concentration",
                 time_column: str = "time", inlet=None) -> tuple[np.ndarray, np.ndarray]:
    """Return t, c as float arrays or raise TracerError naming the row and column.

    Refused: NaN or infinite values, fewer than 3 points, times not strictly increasing
    (a negative or zero time step, e.g. unsorted rows), a curve that is all zero, and
    negative concentrations below -(5 sigma + 1 % of the peak), sigma the noise level
    estimated from second differences. Smaller negative values are noise and are kept
    (removing them would bias the fit and the moments upwards).
    """
    t = np.asarray(t, dtype=float).ravel()
    c = np.asarray(c, dtype=float).ravel()
    if t.shape != c.shape:
        raise TracerError(f"{time_column} has {t.size} values but {column} has {c.size}", column)
    for name, arr in ((time_column, t), (column, c)) + ((("inlet", np.asarray(inlet, float)),)
                                                        if inlet is not None else ()):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            raise TracerError(f"column {name!r}: value {arr[bad[0]]} at data row {bad[0] + 1}; "
                              "expected finite numbers (remove or fill the row)", name)
    if t.size < 3:
        raise TracerError(f"only {t.size} data rows; expected at least 3", column)
    steps = np.diff(t)
    bad = np.flatnonzero(steps <= 0)
    if bad.size:
        i = int(bad[0])
        what = "repeated" if steps[i] == 0 else "decreasing (negative time step; unsorted rows?)"
        raise TracerError(f"column {time_column!r}: time {t[i + 1]:g} at data row {i + 2} is "
                          f"{what} after {t[i]:g}; expected strictly increasing times", time_column)
    if t[0] < 0:
        raise TracerError(f"column {time_column!r}: time {t[0]:g} at data row 1 is before the injection; "
                          "expected times >= 0 measured from the injection (shift the clock)", time_column)
    peak = float(np.max(np.abs(c)))
    if peak == 0.0:
        raise TracerError(f"column {column!r}: all values are zero; expected a tracer response",
                          column)
    if not 1e-100 <= peak <= 1e100:
        raise TracerError(f"column {column!r}: peak {peak:.3g}; expected a peak between 1e-100 and 1e100 "
                          "(rescale the column: the fit does not depend on the concentration unit)", column)
    if float(np.max(c) - np.min(c)) <= 1e-12 * peak:
        raise TracerError(f"column {column!r}: all values are equal ({c[0]:.6g}); expected a tracer "
                          "response that changes with time", column)
    if kind == "pulse":
        limit = 5 * noise_level(c) + 0.01 * float(np.max(c))
        bad = np.flatnonzero(c < -limit)
        if bad.size or np.max(c) <= 0:
            i = int(bad[0]) if bad.size else int(np.argmin(c))
            raise TracerError(f"column {column!r}: value {c[i]:.6g} at data row {i + 1} is negative "
                              f"beyond the noise (limit -{limit:.3g}); expected concentrations "
                              ">= 0 (subtract the right baseline?)", column)
    return t, c


def _utf8_text(path: Path) -> str:
    """The file's text as UTF-8.

    The file's text as UTF-8 (a byte-order mark is dropped); otherwise a TracerError
    naming the file and the byte offset of the first byte that is not UTF-8.
    """
    try:
        raw = path.read_bytes()
    except FileNotFoundError:
        raise TracerError(f"{path}: no such file") from None
    except OSError as err:
        raise TracerError(f"{path}: cannot read the file ({err.strerror or err})") from None
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise TracerError(f"{path}: the file is UTF-16 encoded; save it as UTF-8")
    try:
        return raw.decode("utf-8-sig")
    except UnicodeDecodeError as err:
        line = raw.count(b"\n", 0, err.start) + 1
        raise TracerError(f"{path}: byte {err.start} (line {line}) is not UTF-8 "
                          f"(0x{raw[err.start]:02x}); save the file as UTF-8") from None


def read_tracer_csv(path, kind: str | None = None) -> TracerCurve:
    """Read a tracer CSV: ``time_<unit>``, ``concentration`` (or ``F``), optional ``inlet``.

    Parameters
    ----------
    path : str or Path
    kind : {"pulse", "step"}, optional
        Default: "step" if the file has an ``F`` column, else "pulse".
    """
    import pandas as pd

    path = Path(path)
    text = _utf8_text(path)
    try:
        df = pd.read_csv(io.StringIO(text), comment="#")
    except (OSError, ValueError) as err:
        msg = " ".join(str(err).split())
        raise TracerError(f"{path}: cannot read as CSV ({msg})") from None
    df.columns = [str(col).strip() for col in df.columns]
    _check_unique_header(path, text)
    times = [col for col in df.columns if TIME_COLUMN.match(col)]
    if len(times) != 1:
        raise TracerError(f"{path}: columns {list(df.columns)}; expected exactly one time column "
                          "named time_<unit> (time_s, time_min, time_h)", "time")
    tcol = times[0]
    unit = TIME_COLUMN.match(tcol).group(1)
    if unit not in TIME_UNITS:
        raise TracerError(f"{path}: time unit {unit!r} in {tcol!r}; expected one of "
                          f"{sorted(TIME_UNITS)}", tcol)
    known = {tcol, "concentration", "F", "inlet"}
    unknown = [col for col in df.columns if col not in known]
    hint = {u: k for u in unknown for k in ("concentration", "F", "inlet") if u.lower() == k.lower()}
    said = "; ".join(f"{u!r} is not {k!r} (names are case-sensitive)" for u, k in hint.items())
    ccol = "F" if "F" in df.columns and kind in (None, "step") else "concentration"
    if ccol not in df.columns:
        raise TracerError(f"{path}: no column 'concentration' (or 'F' for a step response) in "
                          f"{list(df.columns)}{' (' + said + ')' if said else ''}", "concentration")
    if unknown:
        raise TracerError(f"{path}: unknown column{'s' if len(unknown) > 1 else ''} {unknown}"
                          f"{' (' + said + ')' if said else ''}; expected {tcol}, concentration (a pulse) or F (a "
                          "step response), and optionally inlet", unknown[0])
    if "F" in df.columns and "concentration" in df.columns:
        raise TracerError(f"{path}: both 'concentration' and 'F' columns; expected one: concentration for a pulse "
                          "response, F for a step response (F(t), the fraction of the tracer that has left)", "F")
    kind = kind or ("step" if ccol == "F" else "pulse")
    if kind not in ("pulse", "step"):
        raise TracerError(f"kind = {kind!r}; expected 'pulse' or 'step'")
    cols = {}
    for col in [tcol, ccol] + (["inlet"] if "inlet" in df.columns else []):
        values = pd.to_numeric(df[col], errors="coerce")
        bad = np.flatnonzero(values.isna() & df[col].notna())
        if bad.size:
            raise TracerError(f"{path}: column {col!r}: {df[col].iloc[bad[0]]!r} at data row "
                              f"{bad[0] + 1} is not a number", col)
        cols[col] = values.to_numpy(dtype=float)
    try:
        t, c = check_tracer(cols[tcol], cols[ccol], kind, ccol, tcol, cols.get("inlet"))
    except TracerError as err:
        raise TracerError(f"{path}: {err}", err.column) from None
    return TracerCurve(t, c, kind, TIME_UNITS[unit], cols.get("inlet"), str(path))


def _check_unique_header(path, text: str) -> None:
    """Refuse a column named twice.

    pandas would rename the second 'name.1' and one of them would be fitted without a word.
    """
    import csv

    line = next((ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")), "")
    names = [n.strip() for n in next(csv.reader([line]), [])]
    seen = set()
    for name in names:
        if name in seen:
            raise TracerError(f"{path}: column {name!r} appears twice in the header; expected each column once",
                              name)
        seen.add(name)


def subtract_baseline(curve: TracerCurve, baseline="head", points: int = 5) -> TracerCurve:
    """Subtract a constant baseline: a number, or the median of the first/last points.

    ``"head"`` suits curves whose first samples precede the tracer's arrival, ``"tail"``
    curves that return to baseline. The subtracted value is recorded in ``notes``.
    """
    if isinstance(baseline, str):
        if baseline not in ("head", "tail"):
            raise TracerError(f"baseline = {baseline!r}; expected 'head', 'tail' or a number")
        part = curve.c[:points] if baseline == "head" else curve.c[-points:]
        value = float(np.median(part))
        how = f"median of the {'first' if baseline == 'head' else 'last'} {len(part)} points"
    else:
        value, how = float(baseline), "given"
    return curve.with_notes(f"baseline {value:.6g} ({how}) subtracted", c=curve.c - value)


@dataclass(frozen=True)
class Moments:
    """Area, mean [time] and variance [time^2] of a pulse curve; tail share of the area."""

    area: float
    mean: float
    variance: float
    tail_fraction: float = 0.0
    note: str = ""


def _tail_fit(t, c) -> tuple[float, float] | None:
    """(c_T, lambda) of an exponential through the last descending points, or None."""
    ipk = int(np.argmax(c))
    idx = np.flatnonzero((np.arange(c.size) > ipk) & (c > 0) & (c <= 0.5 * c[ipk]))
    if idx.size < 3:
        return None
    idx = idx[-max(3, idx.size // 2):]
    slope, icpt = np.polyfit(t[idx], np.log(c[idx]), 1)
    if slope >= 0:
        return None
    return float(math.exp(icpt + slope * t[-1])), float(-1.0 / slope)


def moments(t, c, tail="auto") -> Moments:
    """Zeroth, first and second central moment of a pulse response by trapezoids.

    Parameters
    ----------
    t, c : arrays
        Times [time] and concentrations (baseline already removed).
    tail : "auto", bool
        Add an exponential tail beyond the last point: ``"auto"`` when the last value is
        above 1 % of the peak (the curve was cut off). Tail integrals from T = t[-1]:
        int c_T e^{-(t-T)/lam} t^k dt = c_T lam, c_T (lam T + lam^2),
        c_T (lam T^2 + 2 lam^2 T + 2 lam^3) for k = 0, 1, 2.
    """
    t = np.asarray(t, float)
    c = np.asarray(c, float)
    m0 = np.trapezoid(c, t)
    m1 = np.trapezoid(t * c, t)
    m2 = np.trapezoid(t * t * c, t)
    note, frac = "", 0.0
    want = (c[-1] > 0.01 * np.max(c)) if tail == "auto" else bool(tail)
    fit = _tail_fit(t, c) if want else None
    if fit is not None:
        ct, lam = fit
        big_t = t[-1]
        add = (ct * lam, ct * (lam * big_t + lam**2),
               ct * (lam * big_t**2 + 2 * lam**2 * big_t + 2 * lam**3))
        m0, m1, m2 = m0 + add[0], m1 + add[1], m2 + add[2]
        frac = add[0] / m0
        note = (f"exponential tail (time constant {lam:.4g}) added beyond t = {big_t:.4g}: "
                f"{100 * frac:.2f} % of the area")
    elif want:
        note = "curve cut off but no decaying tail to extrapolate; moments truncated"
    if m0 <= 0:
        raise TracerError(f"curve area {m0!r}; expected a positive area")
    mean = m1 / m0
    return Moments(float(m0), float(mean), float(max(m2 / m0 - mean**2, 0.0)), float(frac), note)


def step_moments(t, f) -> Moments:
    """Mean and variance of a step (F-curve) response normalised by its final plateau.

    mean = int (1 - F) dt, E[t^2] = 2 int t (1 - F) dt, F = f / median(last 5 points).
    """
    t = np.asarray(t, float)
    f = np.asarray(f, float)
    plateau = float(np.median(f[-5:]))
    if plateau <= 0:
        raise TracerError(f"step response ends at {plateau!r}; expected a positive plateau", "F")
    g = 1.0 - f / plateau
    mean = t[0] + np.trapezoid(g, t)
    second = t[0]**2 + 2 * np.trapezoid(t * g, t)
    return Moments(plateau, float(mean), float(max(second - mean**2, 1e-12 * mean**2)), 0.0,
                   f"F normalised by the plateau {plateau:.6g}")


def normalise(curve: TracerCurve, tail="auto") -> TracerCurve:
    """E-curve: concentrations divided by the area (with tail, see :func:`moments`)."""
    mom = moments(curve.t, curve.c, tail)
    notes = [f"normalised by the area {mom.area:.6g}"] + ([mom.note] if mom.note else [])
    return curve.with_notes(*notes, c=curve.c / mom.area)


def convolve_inlet(cdf, t, inlet) -> np.ndarray:
    """Outlet response to a measured inlet curve, normalised to unit area.

    The inlet is taken piecewise constant between samples (mean of the two ends), so
    c_out(t_i) = sum_j cbar_j [F(t_i - t_j) - F(t_i - t_{j+1})] / int c_in dt exactly,
    with F the model's cdf: exact for plug flow and bypass too, where E has atoms.
    """
    t = np.asarray(t, float)
    cin = np.asarray(inlet, float)
    cbar = 0.5 * (cin[:-1] + cin[1:])
    area = float(np.sum(cbar * np.diff(t)))
    if area <= 0:
        raise TracerError("inlet curve has no positive area", "inlet")
    lags = t[:, None] - t[None, :]
    # uniform sampling repeats the lags: evaluate F once per distinct value
    uniq, inv = np.unique(lags, return_inverse=True)
    big_f = np.asarray(cdf(uniq)).reshape(-1)[inv].reshape(lags.shape)
    return ((big_f[:, :-1] - big_f[:, 1:]) @ cbar) / area
