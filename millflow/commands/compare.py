"""``millflow compare A.toml B.toml [--out DIR] [--json] [--no-plots]``: two flowsheets
side by side.

Solves both and prints one table of the streams they share (by name): t/h, P80 and P50
in A and in B, and the differences; the circulating loads and specific energies of
both. Writes ``compare.csv`` (solids and water t/h, % solids, P80 and P50 of the shared
streams in A and B), ``compare.json`` (the same, and both flowsheets' summaries),
``report.html`` (its numbers those of compare.json) and ``compare.png`` (cumulative
passing of every shared stream, A solid, B dashed) into ``--out`` (default
``<A>-vs-<B>/``).
"""
from __future__ import annotations

import json
import math
from pathlib import Path

from millflow.commands.output import add_output_flags


def add_parser(subparsers) -> None:
    p = subparsers.add_parser("compare", help="solve two flowsheets and compare the streams they share",
                              description=__doc__.split("\n\n")[0],
                              epilog="example: millflow compare flowsheets/open_circuit_ball_mill.toml "
                                     "flowsheets/closed_circuit_ball_mill.toml")
    p.add_argument("a", help="first flowsheet file (TOML)")
    p.add_argument("b", help="second flowsheet file (TOML)")
    add_output_flags(p, out="output folder (default: <A stem>-vs-<B stem>)",
                     json="print one JSON object instead of the table",
                     plots="do not write compare.png")
    p.set_defaults(func=run)


def _d(a, b):
    return None if a is None or b is None or not (math.isfinite(a) and math.isfinite(b)) else b - a


def run(args) -> int:
    from millflow.commands.output import check_target, staged_folder
    from millflow.errors import InputError
    from millflow.flowsheet import load, solve, summary

    pa, pb = Path(args.a), Path(args.b)
    out = Path(args.out) if args.out else Path.cwd() / f"{pa.stem}-vs-{pb.stem}"
    check_target(out, overwrite=args.overwrite, input_path=pa)
    from millflow.progress import stages

    with stages("millflow compare", ["solve A", "solve B"], enabled=not args.quiet) as stage:
        stage("solve A")
        sa = summary(solve(load(pa)))
        stage("solve B")
        sb = summary(solve(load(pb)))
    shared = [n for n in sa["streams"] if n in sb["streams"]]
    if not shared:
        raise InputError(f"{pa} and {pb} share no stream name; compare needs streams of the same name")
    rows = []
    for n in shared:
        a, b = sa["streams"][n], sb["streams"][n]
        row = {"stream": n}
        for key in ("solids_tph", "water_tph", "solids_content_pct", "p80_um", "p50_um"):
            row[f"{key}_a"], row[f"{key}_b"] = a.get(key), b.get(key)
            if key in ("p80_um", "p50_um"):
                row[f"d_{key}"] = _d(a[key], b[key])
        rows.append(row)
    result = {"a": str(pa), "b": str(pb), "streams": rows,
              "circulating_load": {"a": sa["circulating_load"], "b": sb["circulating_load"]},
              "specific_energy_kWh_per_t": {"a": sa["specific_energy_kWh_per_t"],
                                            "b": sb["specific_energy_kWh_per_t"]},
              "summaries": {"a": sa, "b": sb}}
    from millflow.report.html import finite

    result = finite(result)  # strict JSON: a number that is not finite is null
    with staged_folder(out, overwrite=args.overwrite, input_path=pa, command="compare") as tmp:
        import pandas as pd

        pd.DataFrame(rows).dropna(axis=1, how="all").to_csv(tmp / "compare.csv", index=False, float_format="%.6g")
        (tmp / "compare.json").write_text(json.dumps(result, indent=1, allow_nan=False) + "\n", encoding="utf-8")
        from millflow.report.studies import compare_report, write_page

        write_page(tmp / "report.html", compare_report(result, inputs=(pa, pb)))
        if not args.no_plots:
            _plot(sa, sb, shared, pa.stem, pb.stem, tmp / "compare.png")
    if args.json:
        print(json.dumps(result))
    else:  # --quiet hides progress only
        def f(v, fmt="{:.4g}"):
            return "-" if v is None or not math.isfinite(v) else fmt.format(v)


        head = f"{'stream':<20}{'t/h A':>9}{'t/h B':>9}{'P80 A':>9}{'P80 B':>9}{'dP80':>9}{'P50 A':>9}{'P50 B':>9}"
        print(f"A = {pa}\nB = {pb}\n{head}\n{'-' * len(head)}")
        for r in rows:
            print(f"{r['stream']:<20}{f(r['solids_tph_a'], '{:.1f}'):>9}{f(r['solids_tph_b'], '{:.1f}'):>9}"
                  f"{f(r['p80_um_a'], '{:.0f}'):>9}{f(r['p80_um_b'], '{:.0f}'):>9}{f(r['d_p80_um'], '{:+.0f}'):>9}"
                  f"{f(r['p50_um_a'], '{:.0f}'):>9}{f(r['p50_um_b'], '{:.0f}'):>9}")
        def loads(cl):
            return ", ".join(f"{n} {f(100 * v, '{:.1f}')} %" for n, v in cl.items()) or "none (no recycle)"
        print(f"circulating load (recycle / new feed): A {loads(sa['circulating_load'])}; "
              f"B {loads(sb['circulating_load'])}")
        print(f"specific energy [kWh/t]: A {f(sa['specific_energy_kWh_per_t'] or math.nan)}, "
              f"B {f(sb['specific_energy_kWh_per_t'] or math.nan)}")
        print(f"written to {out}/")
    return 0


def _plot(sa, sb, shared, la, lb, path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(7, 4.5))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    for k, n in enumerate(shared):
        for s, style, lab in ((sa, "-", la), (sb, "--", lb)):
            st = s["streams"][n]
            ax.semilogx(st["size_um"], st["cum_passing"], style, color=f"C{k % 10}", lw=1.2, label=f"{n} ({lab})")
    ax.set_xlabel("size [um]")
    ax.set_ylabel("cumulative passing [-]")
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
