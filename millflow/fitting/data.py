"""Measured PSD tables for fitting: reading, unit conversion and validation.

A PSD data set is a *long table* (one row per measured value) with columns

- ``condition``: the name of an operating condition (a batch test, a steady state);
- ``location``: ``feed``, ``product``, ``holdup`` (mill content) or any sample point;
- ``time_<unit>`` (optional, batch tests): sampling time, unit ``s``, ``min`` or ``h``;
- ``size_<unit>``: sieve size, unit ``m``, ``mm``, ``um`` (or ``in``, ``ft``);
- ``passing`` (cumulative mass fraction passing the size) or ``retained`` (mass
  fraction retained on that sieve, i.e. between this size and the next coarser one);
- ``weight`` (optional): a weight per value, e.g. 1/variance of the measurement.

Feed rows with condition ``*`` apply to every condition that has no feed of its own.
A second table gives the process parameters: column ``condition`` and one numeric
column per parameter (``speed_m_s``, ``moisture``, ``screen_mm``...; any positive
number). Everything is converted to SI on reading (sizes in m, times in s) by the units
of :data:`millflow.inputs.UNITS` (:func:`millflow.inputs.unit_column`): a ``size`` or
``time`` column without its unit, or with an unknown one, is refused. Every error names
the file, the column and the row.
"""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field

import numpy as np
import pandas as pd

from millflow.errors import InputError
from millflow.inputs import read_csv, unit_column

__all__ = ["PSDData", "read_psd_table", "read_process_table", "read_sprite_folder", "psd_data_from_frames"]

#: A size unit this table took before it read columns through millflow.inputs (size_micron).
_LEGACY_SIZE = {"micron": 1e-6}
_TOL = 1e-6  # cumulative passing may rise by rounding this much between sieves


@dataclass
class PSDData:
    """A validated PSD data set in SI units.

    Attributes
    ----------
    table : pandas.DataFrame
        Columns ``condition``, ``location``, ``time_s``, ``size_m``, ``passing`` and
        ``weight``; sorted by condition, location, time and decreasing size.
    process : pandas.DataFrame
        Index ``condition``, one numeric column per process parameter (may be empty).
    source : str
        Where the data came from (for messages).
    """

    table: pd.DataFrame
    process: pd.DataFrame = field(default_factory=pd.DataFrame)
    source: str = "<memory>"

    @property
    def conditions(self) -> list[str]:
        """Conditions with at least one non-feed measurement, in table order."""
        t = self.table[self.table.location != "feed"]
        return list(dict.fromkeys(t.condition))

    def feed(self, condition: str) -> tuple[np.ndarray, np.ndarray]:
        """(size_m decreasing, cumulative passing) of the feed of a condition."""
        t = self.table
        rows = t[(t.location == "feed") & (t.condition == condition)]
        if rows.empty:
            rows = t[(t.location == "feed") & (t.condition == "*")]
        if rows.empty:
            first = t[(t.condition == condition) & (t.time_s == 0)]
            if first.empty:
                raise InputError(
                    f"{self.source}: condition {condition!r} has no feed rows (location 'feed', or condition '*' "
                    "for a common feed, or a sample at time 0)"
                )
            rows = first
        rows = rows.sort_values("size_m", ascending=False)
        return rows.size_m.to_numpy(), rows.passing.to_numpy()

    def samples(self, conditions=None) -> pd.DataFrame:
        """The measurements to fit (feed rows excluded), for the given conditions."""
        t = self.table[self.table.location != "feed"]
        if conditions is not None:
            t = t[t.condition.isin(list(conditions))]
        return t

    def subset(self, conditions) -> "PSDData":
        keep = set(conditions) | {"*"}
        t = self.table[self.table.condition.isin(keep)].reset_index(drop=True)
        p = self.process.loc[[c for c in self.process.index if c in keep]] if len(self.process) else self.process
        return PSDData(t, p, self.source)


#: Rounding allowed above 1 in a sample's sum of retained fractions (six-digit tables).
RETAINED_TOL = 1e-6

def _numeric(df: pd.DataFrame, col: str, source: str) -> np.ndarray:
    vals = pd.to_numeric(df[col], errors="coerce").to_numpy(dtype=float)
    bad = np.flatnonzero(~np.isfinite(vals))
    if bad.size:
        k = bad[0]
        raise InputError(f"{source}: column {col!r}, row {k + 2}: {df[col].iloc[k]!r} is not a finite number")
    return vals


def psd_data_from_frames(psd: pd.DataFrame, process: pd.DataFrame | None = None, source: str = "<memory>",
                         process_source: str = "<memory>", *, strict: bool = True) -> PSDData:
    """Validate a long PSD table (and a process table) given as DataFrames; see module doc.

    ``strict=False`` skips the range [0, 1] and monotonicity checks of the values: for
    synthetic data with added noise only (measured data must pass them)."""
    df = psd.copy()
    df.columns = [str(c).strip() for c in df.columns]
    for col in ("condition", "location"):
        if col not in df.columns:
            raise InputError(f"{source}: missing column {col!r}; columns are {list(df.columns)}")
    if df.empty:
        raise InputError(f"{source}: the PSD table has no rows")
    scol, sfac = unit_column(df.columns, "size", "length", source, extra=_LEGACY_SIZE)
    tcol, tfac = unit_column(df.columns, "time", "time", source, required=False)
    size = _numeric(df, scol, source) * sfac
    if np.any(size < 0):
        k = int(np.flatnonzero(size < 0)[0])
        raise InputError(f"{source}: column {scol!r}, row {k + 2}: size {size[k]!r} < 0")
    time = _numeric(df, tcol, source) * tfac if tcol else np.zeros(len(df))
    has_p, has_r = "passing" in df.columns, "retained" in df.columns
    if has_p == has_r:
        raise InputError(f"{source}: expected exactly one of the columns 'passing' or 'retained'")
    vcol = "passing" if has_p else "retained"
    val = _numeric(df, vcol, source)
    if strict and (np.any(val > 1 + 1e-9) or np.any(val < -1e-9)):
        k = int(np.flatnonzero((val > 1 + 1e-9) | (val < -1e-9))[0])
        hint = " (give fractions, not percent)" if val[k] > 1 else ""
        raise InputError(f"{source}: column {vcol!r}, row {k + 2}: {val[k]!r} outside [0, 1]{hint}")
    weight = _numeric(df, "weight", source) if "weight" in df.columns else np.ones(len(df))
    if np.any(weight < 0):
        raise InputError(f"{source}: column 'weight' has negative values; expected weights >= 0")
    out = pd.DataFrame({
        "condition": df.condition.astype(str).str.strip(), "location": df.location.astype(str).str.strip(),
        "time_s": time, "size_m": size, "value": val, "weight": weight,
    })
    out = out.sort_values(["condition", "location", "time_s", "size_m"], ascending=[True, True, True, False],
                          kind="stable").reset_index(drop=True)
    parts = []
    for key, grp in out.groupby(["condition", "location", "time_s"], sort=False):
        if grp.size_m.duplicated().any():
            raise InputError(f"{source}: {key}: a sieve size appears twice in one sample")
        if vcol == "retained":
            # retained on sieve i = mass between size i and the next coarser size; a sample's
            # fractions sum to at most 1 (the pan holds the rest): beyond rounding, refused
            total = float(grp.value.sum())
            if total > 1 + RETAINED_TOL:
                raise InputError(f"{source}: sample {key}: retained fractions sum to {total:.6g}; expected at "
                                 f"most 1 (within {RETAINED_TOL:g}): fractions, not percent, of one sample")
            grp = grp.assign(passing=np.clip(1.0 - np.cumsum(grp.value.to_numpy()), 0.0, 1.0))
        else:
            grp = grp.assign(passing=grp.value)
        rise = np.diff(grp.passing.to_numpy())
        if strict and np.any(rise > _TOL):
            k = int(np.flatnonzero(rise > _TOL)[0]) + 1
            raise InputError(
                f"{source}: sample {key}: cumulative passing rises from coarse to fine at size "
                f"{grp.size_m.iloc[k]:.6g} m; expected non-increasing"
            )
        parts.append(grp)
    out = pd.concat(parts, ignore_index=True).drop(columns="value")
    samples = out[out.location != "feed"]
    if samples.empty:
        raise InputError(f"{source}: no measurements besides feed rows")
    if np.all(samples.passing.to_numpy() == 0):
        raise InputError(f"{source}: every measured value is zero; there is nothing to fit")
    proc = pd.DataFrame()
    if process is not None:
        p = process.copy()
        p.columns = [str(c).strip() for c in p.columns]
        if "condition" not in p.columns:
            raise InputError(f"{process_source}: missing column 'condition'; columns are {list(p.columns)}")
        p["condition"] = p.condition.astype(str).str.strip()
        if p.condition.duplicated().any():
            raise InputError(f"{process_source}: condition {p.condition[p.condition.duplicated()].iloc[0]!r} twice")
        for col in p.columns:
            if col != "condition":
                p[col] = _numeric(p, col, process_source)
        proc = p.set_index("condition")
        missing = [c for c in dict.fromkeys(samples.condition) if c not in proc.index]
        if missing:
            raise InputError(f"{process_source}: no process parameters for conditions {missing}")
    return PSDData(out, proc, source)


def _read(p):
    if not os.path.isfile(p):
        raise InputError(f"{p}: file not found")
    try:
        return read_csv(p)
    except InputError:
        raise
    except Exception as exc:  # pandas raises many types for malformed CSV
        raise InputError(f"{p}: cannot read as CSV ({exc})") from exc


def read_process_table(path) -> pd.DataFrame:
    """Read a process table (CSV): column ``condition`` and numeric columns; index condition."""
    p = _read(path)
    p.columns = [str(c).strip() for c in p.columns]
    if "condition" not in p.columns:
        raise InputError(f"{path}: missing column 'condition'; columns are {list(p.columns)}")
    p["condition"] = p.condition.astype(str).str.strip()
    for col in p.columns:
        if col != "condition":
            p[col] = _numeric(p, col, str(path))
    return p.set_index("condition")


def read_psd_table(path, process_path=None) -> PSDData:
    """Read a long PSD table (CSV) and optionally a process table (CSV); see module doc."""
    psd = _read(path)
    proc = _read(process_path) if process_path else None
    return psd_data_from_frames(psd, proc, source=str(path), process_source=str(process_path))


_SPRITE_NAME = re.compile(r"^JRS_(\d+(?:\.\d+)?)Hz_(\d+(?:\.\d+)?)p_(\d+(?:\.\d+)?)_output$")
#: Rotor radius of the JRS knife mill used by SPRITE for tip speed 2 pi r f [m].
SPRITE_ROTOR_RADIUS_M = 0.026


def read_sprite_folder(path) -> PSDData:
    """Build the long tables of the SPRITE knife-mill data (Lu et al. 2024) in memory.

    ``JRS_input.csv`` (``FSieves`` mm, ``Feedmass`` cumulative passing) becomes the
    common feed (condition ``*``); each ``JRS_<f>Hz_<m>p_<s>_output.csv``
    (``ExpSieves`` mm, ``Expmass``) becomes condition ``<file stem>``, location
    ``product``. Process table: ``speed_m_s`` = 2 pi 0.026 f, ``moisture`` = m/100
    (mass fraction), ``screen_mm`` = s * 25.4 (the file names give the screen in inches).
    Nothing is written to disk.
    """
    path = os.fspath(path)
    if not os.path.isdir(path):
        raise InputError(f"{path}: SPRITE data folder not found")
    feed_file = os.path.join(path, "JRS_input.csv")
    if not os.path.isfile(feed_file):
        raise InputError(f"{feed_file}: feed file not found")
    feed = read_csv(feed_file)
    for col in ("FSieves", "Feedmass"):
        if col not in feed.columns:
            raise InputError(f"{feed_file}: missing column {col!r}")
    rows = [pd.DataFrame({"condition": "*", "location": "feed", "size_mm": feed.FSieves, "passing": feed.Feedmass})]
    proc = []
    for name in sorted(os.listdir(path)):
        m = _SPRITE_NAME.match(os.path.splitext(name)[0])
        if not m or not name.endswith(".csv"):
            continue
        stem = os.path.splitext(name)[0]
        d = read_csv(os.path.join(path, name))
        for col in ("ExpSieves", "Expmass"):
            if col not in d.columns:
                raise InputError(f"{os.path.join(path, name)}: missing column {col!r}")
        rows.append(pd.DataFrame({"condition": stem, "location": "product", "size_mm": d.ExpSieves,
                                  "passing": d.Expmass}))
        f, moist, screen_in = (float(g) for g in m.groups())
        proc.append({"condition": stem, "frequency_hz": f, "speed_m_s": 2 * np.pi * SPRITE_ROTOR_RADIUS_M * f,
                     "moisture": moist / 100.0, "screen_mm": screen_in * 25.4})
    if not proc:
        raise InputError(f"{path}: no JRS_<f>Hz_<m>p_<s>_output.csv files")
    table = pd.concat(rows, ignore_index=True)
    # the feed file's own rounding makes passing rise by < 1e-9 in places; clip
    table["passing"] = table.passing.clip(0.0, 1.0)
    return psd_data_from_frames(table, pd.DataFrame(proc), source=path, process_source=path)
