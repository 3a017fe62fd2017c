"""Results of a reconciled survey: xarray Dataset, tables, summary.json and plots.

Tables and the summary use t/h, um and %; the Dataset keeps SI with ``units`` attributes.
``measurements.csv`` has one row per measured value (measured, SD, adjusted, its SD,
the adjustment in SDs, the normalised adjustment, redundant or not), ``streams.csv``
the solids, water and % solids of every stream (adjusted, SD, measured or derived,
observable), ``passing.csv`` cumulative passing at every sieve of the common series.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

__all__ = ["measurement_table", "stream_table", "passing_table", "to_dataset", "summary", "save"]

TPH = 3.6  # kg/s -> t/h
CSV_FLOAT_FORMAT = "%.8g"


def _scale(row) -> float:
    return 100.0 if row["kind"] in ("fraction", "solids_content") else TPH


def measurement_table(bal):
    import pandas as pd

    st = bal.structure
    norm = bal.normalised
    red, power, kd = bal.redundancy, bal.detection_power(10.0), bal.detectable_sd(0.9)
    recs = []
    for i, row in enumerate(st.rows):
        k = _scale(row)
        unit = "%" if k == 100.0 else "t/h"
        recs.append({"key": row["key"], "quantity": row["kind"], "class": row.get("label", ""), "unit": unit,
                     "measured": st.y[i] * k, "sd": st.sd[i] * k, "adjusted": bal.adjusted[i] * k,
                     "adjusted_sd": bal.adjusted_sd[i] * k, "adjustment": bal.adjustment[i] * k,
                     "adjustment_in_sd": bal.adjustment[i] / st.sd[i], "normalised_adjustment": norm[i],
                     "redundant": bool(bal.redundant[i]), "redundancy": red[i],
                     "power_10sd": power[i], "detectable_sd_90": kd[i] if np.isfinite(kd[i]) else math.nan})
    for key, v in st.exact:
        recs.append({"key": key, "quantity": "exact", "class": "", "unit": "t/h", "measured": v * TPH, "sd": 0.0,
                     "adjusted": v * TPH, "adjusted_sd": 0.0, "adjustment": 0.0, "adjustment_in_sd": math.nan,
                     "normalised_adjustment": math.nan, "redundant": False, "redundancy": 0.0,
                     "power_10sd": 0.0, "detectable_sd_90": math.nan})
    return pd.DataFrame.from_records(recs)


def _stream_values(bal) -> dict:
    st = bal.structure
    out = {}
    for n in st.streams:
        m = bal.survey.streams.get(n)
        M, Msd, Mok = bal.solids(n)
        d = {"solids_tph": M * TPH, "solids_sd_tph": Msd * TPH, "solids_observable": Mok,
             "solids_measured_tph": None if m is None or m.solids is None else m.solids * TPH}
        if st.wet:
            W, Wsd, Wok = bal.water(n)
            d.update(water_tph=W * TPH, water_sd_tph=Wsd * TPH, water_observable=Wok,
                     water_measured_tph=None if m is None or m.water is None else m.water * TPH,
                     solids_content_pct=100 * M / (M + W) if Mok and Wok and M + W > 0 else math.nan,
                     solids_content_measured_pct=None if m is None or m.solids_content is None
                     else 100 * m.solids_content)
        out[n] = d
    return out


def stream_table(bal):
    import pandas as pd

    return pd.DataFrame.from_dict(_stream_values(bal), orient="index").rename_axis("stream")


def _passing(bal):
    st = bal.structure
    meas, adj, sd = [], [], []
    for n in st.streams:
        v, s, ok = bal.passing(n)
        adj.append(np.where(ok, v, np.nan))
        sd.append(np.where(ok, s, np.nan))
        row = np.full(st.sieves.size, np.nan)
        m = bal.survey.streams.get(n)
        if m is not None and m.psd is not None:
            for x, p in zip(m.psd.sizes, m.psd.passing):
                row[int(np.argmin(np.abs(st.sieves - x)))] = p
        meas.append(row)
    return np.array(meas), np.array(adj), np.array(sd)


def passing_table(bal):
    import pandas as pd

    st = bal.structure
    meas, adj, sd = _passing(bal)
    recs = []
    for i, n in enumerate(st.streams):
        for j, x in enumerate(st.sieves):
            recs.append({"stream": n, "size_um": x * 1e6, "measured_pct": 100 * meas[i, j],
                         "adjusted_pct": 100 * adj[i, j], "sd_pct": 100 * sd[i, j]})
    return pd.DataFrame.from_records(recs)


def to_dataset(bal):
    """Measured, adjusted and SD of cumulative passing (stream x size) and of the stream flows (SI)."""
    import xarray as xr

    st = bal.structure
    meas, adj, sd = _passing(bal)
    sv = _stream_values(bal)
    names = st.streams

    def var(dims, data, units, long_name):
        return (dims, np.asarray(data, dtype=float), {"units": units, "long_name": long_name})

    def col(key, scale=1 / TPH):
        return [np.nan if sv[n].get(key) is None else sv[n][key] * scale for n in names]

    ds = xr.Dataset(coords={"stream": ("stream", names, {"long_name": "stream name"}),
                            "size": ("size", st.sieves, {"units": "m", "long_name": "sieve size"})})
    ds["passing_measured"] = var(("stream", "size"), meas, "1", "measured cumulative fraction passing the sieve")
    ds["passing_adjusted"] = var(("stream", "size"), adj, "1", "reconciled cumulative fraction passing the sieve")
    ds["passing_sd"] = var(("stream", "size"), sd, "1", "SD of the reconciled cumulative fraction passing")
    ds["solids_measured"] = var("stream", col("solids_measured_tph"), "kg/s", "measured solids flow")
    ds["solids_adjusted"] = var("stream", col("solids_tph"), "kg/s", "reconciled solids flow")
    ds["solids_sd"] = var("stream", col("solids_sd_tph"), "kg/s", "SD of the reconciled solids flow")
    if st.wet:
        ds["water_measured"] = var("stream", col("water_measured_tph"), "kg/s", "measured water flow")
        ds["water_adjusted"] = var("stream", col("water_tph"), "kg/s", "reconciled water flow")
        ds["water_sd"] = var("stream", col("water_sd_tph"), "kg/s", "SD of the reconciled water flow")
        ds["solids_content_measured"] = var("stream", col("solids_content_measured_pct", 0.01), "1",
                                            "measured solids mass fraction")
        ds["solids_content_adjusted"] = var("stream", col("solids_content_pct", 0.01), "1",
                                            "reconciled solids mass fraction")
    ds.attrs.update({"title": bal.survey.title, "source_file": bal.survey.source,
                     "method": "weighted least squares, node balances exact (null-space elimination), "
                               "Gauss-Newton on the bilinear terms",
                     "chi_square": json.dumps(_clean(bal.chi_square)),
                     "balance_error": bal.balance_error})
    return ds


def _clean(v):
    if isinstance(v, dict):
        return {k: _clean(x) for k, x in v.items()}
    if isinstance(v, (list, tuple, np.ndarray)):
        return [_clean(x) for x in v]
    if isinstance(v, (float, np.floating)):
        return float(v) if math.isfinite(v) else None
    if isinstance(v, (np.integer,)):
        return int(v)
    if isinstance(v, np.bool_):
        return bool(v)
    return v


def detectability(bal, k: float = 10.0, power: float = 0.9, count: int = 5) -> dict:
    """How well the survey can catch a gross error in each measurement: the power of the
    measurement test for an error of ``k`` SD, the redundancies, and the least detectable ones."""
    p, r, kd = bal.detection_power(k), bal.redundancy, bal.detectable_sd(power)
    red = np.flatnonzero(bal.redundant)
    worst = red[np.argsort(p[red], kind="stable")][:count]

    def one(i):
        d = bal._describe(int(i))
        return {"measurement": d["measurement"], "redundancy": float(r[i]), "power": float(p[i]),
                "detectable_sd": float(kd[i])}

    return {"k_sd": k, "power_level": power,
            "rule": (f"a gross error of k SD in one measurement shifts its normalised adjustment by k sqrt(r), "
                     f"r = 1 - H_ii its redundancy; power = P(|N(k sqrt(r), 1)| > threshold); an error of "
                     f"(threshold + z_{power:g}) / sqrt(r) SD is detected with probability {power:g}"),
            "n_redundant": int(red.size), "n_not_redundant": int(p.size - red.size),
            "n_detected_at_power": int(np.sum(p[red] >= power)),
            "least_detectable": [one(i) for i in worst]}


def summary(bal) -> dict:
    """What a metallurgist reads first: the test, the candidates, the flows, the loads, what is unknown."""
    chi = dict(bal.chi_square)
    cl = {n: {"value_pct": 100 * v, "sd_pct": 100 * s, "observable": ok}
          for n, (v, s, ok) in bal.circulating_loads().items()}
    d = {
        "title": bal.survey.title, "source_file": bal.survey.source,
        "method": ("weighted least squares; node balances (solids per size class, total solids across mills, "
                   "water) held exactly by null-space elimination; bilinear flow x fraction terms by "
                   "Gauss-Newton with step halving; error-model SDs re-evaluated at the "
                   f"reconciled values ({bal.meta.get('reweight_passes', 0)} passes); linearised covariances"),
        "chi_square": chi,
        "chi_square_verdict": (None if chi["dof"] <= 0 else
                               f"SSR {chi['ssr']:.4g} on {chi['dof']} degrees of freedom: "
                               + ("consistent with the stated errors at 5 %" if chi["passed"] else
                                  "larger than the stated errors allow at 5 % (gross errors, or SDs too small)")),
        "gross_error_threshold": bal.threshold,
        "gross_error_rule": ("|normalised adjustment| > z(1 - 0.05 / (2 n_redundant)): a two-sided test at 5 % "
                             "family-wise (Bonferroni) over the redundant measurements; not_separable_from lists "
                             "the measurements whose normalised adjustments correlate with a candidate's by "
                             "|rho| >= 0.9: an error in any of them looks alike to the test"),
        "gross_error_candidates": bal.gross_errors,
        "largest_normalised_adjustments": bal.ranked(5),
        "gross_error_detectability": detectability(bal),
        "streams": _stream_values(bal),
        "circulating_load": cl,
        "observability": bal.observability(),
        "sieves_um": [x * 1e6 for x in bal.structure.sieves],
        "n_measured": chi["n_measured"],
        "exact": [k for k, _ in bal.structure.exact],
        "balance_error": bal.balance_error,
        "iterations": bal.nfev, "runtime_s": bal.runtime_s,
        "starts_tried": bal.meta.get("starts_tried", 1), "start": bal.meta.get("start"),
        "outside_physical_range": _outside(bal),
        "physical_range_violations": list(bal.meta.get("unphysical", [])),
    }
    extra = _report_fields(bal)
    for n, v in extra.pop("stream_topology").items():
        d["streams"][n].update(v)
    d.update(extra)
    return _clean(d)


def _outside(bal) -> list:
    """Reconciled values below 0 within their errors (a size class, a water flow), as they are:
    the reconciliation does not impose positivity and nothing is clipped."""
    from millflow.survey.reconcile import negatives

    return negatives(bal)


def _p80_p50(sieves, passing) -> tuple[float, float]:
    """P80 and P50 [m] read from cumulative passing at the sieves (coarse -> fine), linear
    in log size between the two observable sieves that bracket it; NaN where the percentile
    lies above the top sieve or below the finest, or the analysis is unobservable."""
    x = np.asarray(sieves, float)
    P = np.asarray(passing, float)
    keep = np.isfinite(P)  # sieves the survey does not determine for this stream are left out
    x, P = x[keep], P[keep]
    out = []
    for q in (0.8, 0.5):
        val = math.nan
        if P.size:
            for k in range(P.size - 1):
                if P[k] >= q > P[k + 1]:
                    f = (P[k] - q) / (P[k] - P[k + 1])
                    val = math.exp(math.log(x[k]) + f * (math.log(x[k + 1]) - math.log(x[k])))
                    break
        out.append(val)
    return out[0], out[1]


def _report_fields(bal) -> dict:
    """What ``report.html`` and ``results.xlsx`` show beyond the balance itself: the
    drawing's topology (``units``, each stream's ``from``/``to``), each stream's adjusted
    passing at the sieves with SDs and its measured passing, P80/P50 of the adjusted
    analysis, solids t/h per size class (``class_tph``, classes as in ``classes``), every
    measurement with its adjustment (``measurements``), the input's SHA-256 and the version."""
    import hashlib

    from millflow import __version__

    st = bal.structure
    fs = bal.survey.flowsheet
    meas, adj, sd = _passing(bal)
    n_cls = st.sieves.size + 1
    um = [x * 1e6 for x in st.sieves]
    classes = [f"+{um[0]:.6g} um"] + [f"-{um[k - 1]:.6g} +{um[k]:.6g} um" for k in range(1, st.sieves.size)] \
        + [f"-{um[-1]:.6g} um"]
    streams = {}
    for i, n in enumerate(st.streams):
        s = fs.streams[n]
        p80, p50 = _p80_p50(st.sieves, adj[i])
        m = np.zeros(n_cls)
        m[st.live] = bal.z[st.m_index(i)]
        Mok = bal.solids(n)[2]
        streams[n] = {"from": f"{s.source}.{s.port}", "to": s.target, "p80_um": p80 * 1e6, "p50_um": p50 * 1e6,
                      "passing_adjusted_pct": list(100 * adj[i]), "passing_sd_pct": list(100 * sd[i]),
                      "passing_measured_pct": list(100 * meas[i]),
                      "class_tph": list(m * TPH) if Mok else [math.nan] * n_cls}
    sha = None
    try:
        sha = hashlib.sha256(Path(bal.survey.source).read_bytes()).hexdigest()
    except (OSError, TypeError, ValueError):
        pass
    cols = ["key", "quantity", "class", "unit", "measured", "sd", "adjusted", "adjusted_sd", "adjustment",
            "adjustment_in_sd", "normalised_adjustment", "redundant"]
    recs = measurement_table(bal)[cols].to_dict(orient="records")
    return {"units": {u: {"type": fs.units[u].type} for u in fs.units}, "stream_topology": streams,
            "classes": classes, "measurements": recs, "input_sha256": sha, "millflow_version": __version__}


def save(bal, out_dir, *, plots: bool = True) -> dict:
    """Write results.nc, measurements.csv, streams.csv, passing.csv, summary.json and one plot per stream."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    files = {"netcdf": out / "results.nc"}
    to_dataset(bal).to_netcdf(files["netcdf"], engine="scipy")
    files["measurements"] = out / "measurements.csv"
    measurement_table(bal).to_csv(files["measurements"], index=False, float_format=CSV_FLOAT_FORMAT)
    files["streams"] = out / "streams.csv"
    stream_table(bal).to_csv(files["streams"], float_format=CSV_FLOAT_FORMAT)
    files["passing"] = out / "passing.csv"
    passing_table(bal).to_csv(files["passing"], index=False, float_format=CSV_FLOAT_FORMAT)
    files["summary"] = out / "summary.json"
    files["summary"].write_text(json.dumps(summary(bal), indent=2), encoding="utf-8")
    if plots:
        files.update(_plots(bal, out))
    return files


def _plots(bal, out: Path) -> dict:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    st = bal.structure
    meas, adj, sd = _passing(bal)
    files = {}
    x = st.sieves * 1e6
    for i, n in enumerate(st.streams):
        fig, ax = plt.subplots(figsize=(5.5, 4))
        ax.fill_between(x, 100 * (adj[i] - 2 * sd[i]), 100 * (adj[i] + 2 * sd[i]), color="C0", alpha=0.25,
                        label="adjusted +- 2 SD")
        ax.plot(x, 100 * adj[i], "-", color="C0", label="adjusted")
        ok = np.isfinite(meas[i])
        if ok.any():
            ax.plot(x[ok], 100 * meas[i][ok], "o", color="C3", ms=4, label="measured")
        ax.set_xscale("log")
        ax.set_xlabel("sieve size [um]")
        ax.set_ylabel("cumulative passing [%]")
        M, Msd, Mok = bal.solids(n)
        flow = f"{M * TPH:.1f} +- {Msd * TPH:.1f} t/h" if Mok else "flow unobservable"
        ax.set_title(f"{n}: {flow}", fontsize=10)
        ax.legend(fontsize=8)
        fig.tight_layout()
        path = out / f"stream_{n}.png"
        fig.savefig(path, dpi=90)
        plt.close(fig)
        files[f"plot_{n}"] = path
    return files
