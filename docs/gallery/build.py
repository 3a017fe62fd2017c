"""Build the gallery: each daily job run as a script, each example flowsheet solved and drawn.

    python docs/gallery/build.py

Runs every job of :data:`JOBS` (the commands a user types, in a temporary folder, from
the repository root's files), and solves every flowsheet of ``flowsheets/``; writes
docs/gallery/img/<example>-flowsheet.svg (the report's drawing, two layers of units to a
row so its text reads at the width the site shows it) and -psd.png, docs/gallery/reports/<example>.html
(the run's report.html), docs/gallery/out/<job>.txt (what the job printed) and
docs/gallery.md itself, whose captions carry the numbers of these runs. The files are
committed, so the site builds without running the solver; the inputs are downloads
(docs/hooks/downloads.py).
"""
import contextlib
import io
import json
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]

#: (name, title, what it shows, [command lines], inputs to download). ``{tmp}`` is the job's folder.
JOBS = [
    ("run", "Run a wet closed circuit",
     "A ball mill with six hydrocyclones predicted by Plitt's model, water tracked through every stream. "
     "The run writes `report.html` ([this run's report](gallery/reports/closed_circuit_wet_cyclones.html)), "
     "`results.xlsx`, CSV tables and `results.nc`.",
     [["run", "flowsheets/closed_circuit_wet_cyclones.toml", "--out", "{tmp}/wet"]],
     ["closed_circuit_wet_cyclones.toml"]),
    ("tracer", "Fit a tracer curve, then use it in a mill",
     "Moments and three RTD models compared on a tracer curve; the fit's folder is then the transport of "
     "the open-circuit mill (`transport = {rtd_fit = \"tracer_tis-rtd\"}`).",
     [["fit-rtd", "docs/examples/tracer_tis.csv", "--model", "tis", "--model", "cells", "--model", "cstr",
       "--out", "{tmp}/tracer_tis-rtd"],
      ["run", "{tmp}/tracer_mill.toml", "--no-grid-check", "--out", "{tmp}/tracer_mill"]],
     ["tracer_tis.csv", "tracer_mill.toml"]),
    ("fit", "Fit breakage parameters to batch tests",
     "Eq. 5 rates and eq. 6 breakage fitted to synthetic lab batch tests (stated so), with standard errors "
     "([the fit's report](gallery/reports/lab_fit.html)).",
     [["fit", "examples/scaleup/lab_fit.toml", "--out", "{tmp}/fit"]],
     ["lab_fit.toml", "lab_psd.csv", "lab_process.csv"]),
    ("scaleup", "Carry the lab fit to a plant circuit",
     "The fit above drives a closed ball-mill circuit at plant scale; the throughput that meets a P80 "
     "target, with delta-method bands and the model-form contributions "
     "([the scale-up's report](gallery/reports/plant_scaleup.html): the plant circuit drawn, its streams and units).",
     [["fit", "examples/scaleup/lab_fit.toml", "--json", "--quiet", "--out", "{tmp}/fit2", ">", "{tmp}/fit.json"],
      ["scaleup", "{tmp}/fit.json", "--to", "examples/scaleup/plant.toml", "--target-p80-um", "150",
       "--band-method", "delta", "--out", "{tmp}/plant"]],
     ["lab_fit.toml", "plant.toml"]),
    ("sweep", "Sweep a circuit over mill power and feed rate",
     "20 cases of the closed ball-mill circuit (serial here; a Dask cluster with `--scheduler`); "
     "[the sweep's report](gallery/reports/sweep.html) plots P80, circulating load and kWh/t against both keys.",
     [["sweep", "flowsheets/closed_circuit_ball_mill.toml", "--vary", "units.ball_mill.power_kW=3000:4600:5",
       "--vary", "units.fresh_feed.solids_tph=150:300:4", "--scheduler", "serial", "--out", "{tmp}/sweep"]],
     ["closed_circuit_ball_mill.toml"]),
    ("survey", "Mass-balance a plant survey, then fit the circuit to it",
     "A synthetic survey of a wet closed ball-mill circuit (solids, % solids and sieve analyses of six "
     "streams, stated so; one % solids planted 8 points off) reconciled with the node balances held exactly: "
     "the chi-square test, the gross-error candidates, the circulating load with its SD, then six circuit "
     "parameters fitted to the reconciled streams. The balance writes `report.html` "
     "([this balance's report](gallery/reports/survey_balance.html)), `results.xlsx`, CSV tables and "
     "`results.nc`.",
     [["balance", "examples/survey/survey.toml", "--no-plots", "--out", "{tmp}/survey"]],
     ["survey.toml", "circuit.toml"]),
]

#: job name -> (report.html under the job's folder, published name in docs/gallery/reports/)
JOB_REPORTS = {"survey": ("survey/report.html", "survey_balance.html"), "fit": ("fit/report.html", "lab_fit.html"),
               "scaleup": ("plant/report.html", "plant_scaleup.html"), "sweep": ("sweep/report.html", "sweep.html")}

#: Width [px] at which the site shows a gallery image (the content column of the theme),
#: and the layers of units per row of the gallery's drawings: two keep a drawing narrow
#: enough that its 12 px text is at least 9 px high at that width.
SHOWN_PX, GALLERY_LAYERS = 688, 2


def _shown(cmd, tmp) -> str:
    return "millflow " + " ".join(a.replace(str(tmp) + "/", "").replace(str(tmp), ".") for a in cmd)


def run_jobs(tmp: Path) -> dict:
    from millflow.cli import main as cli

    shutil.copyfile(HERE / "inputs" / "tracer_mill.toml", tmp / "tracer_mill.toml")
    printed = {}
    (HERE / "out").mkdir(exist_ok=True)
    for name, _, _, commands, _ in JOBS:
        text = []
        for cmd in commands:
            cmd = [a.replace("{tmp}", str(tmp)) for a in cmd]
            target = None
            if ">" in cmd:
                target = Path(cmd[cmd.index(">") + 1])
                cmd = cmd[:cmd.index(">")]
            buf = io.StringIO()
            with contextlib.redirect_stdout(buf):
                code = cli(cmd)
            if code != 0:
                raise SystemExit(f"gallery job {name}: {' '.join(cmd)} exited {code}")
            if target is not None:
                target.write_text(buf.getvalue())
                text.append(f"$ {_shown(cmd, tmp)} > {target.name}")
            else:
                text.append(f"$ {_shown(cmd, tmp)}\n{buf.getvalue().replace(str(tmp) + '/', '')}")
        printed[name] = "\n".join(text).rstrip() + "\n"
        if name in JOB_REPORTS:
            src, dst = JOB_REPORTS[name]
            (HERE / "reports").mkdir(exist_ok=True)
            # published without this machine's temporary folder (the sweep's summary names its output)
            text = (tmp / src).read_text(encoding="utf-8").replace(str(tmp) + "/", "")
            (HERE / "reports" / dst).write_text(text, encoding="utf-8")
        (HERE / "out" / f"{name}.txt").write_text(printed[name])
    return printed


def solve_examples(tmp: Path) -> list:
    from millflow.commands.output import write_extras
    from millflow.flowsheet import load, save, solve, summary
    from millflow.flowsheet.gridcheck import grid_check
    from millflow.flowsheet.results import stream_properties
    from millflow.report.flowsheet import drawing

    img = HERE / "img"
    reports = HERE / "reports"
    img.mkdir(exist_ok=True)
    reports.mkdir(exist_ok=True)
    rows = []
    for toml in sorted((REPO / "flowsheets").glob("*.toml")):
        out = tmp / toml.stem
        sol = solve(load(toml))
        props = stream_properties(sol)
        check = grid_check(sol, props)  # as millflow run: the grid error is part of what the page says
        s = summary(sol, props, grid_check=check)
        s["source_file"] = f"flowsheets/{toml.name}"  # not this machine's path in the published page
        save(sol, out, plots=True, props=props, grid_check=check)
        write_extras(sol, s, out, input_path=toml)
        shutil.copyfile(out / "psd.png", img / f"{toml.stem}-psd.png")
        # the drawing of report.html, narrow enough to read at the width the site shows it
        (img / f"{toml.stem}-flowsheet.svg").write_text(
            drawing(s, layers_per_row=GALLERY_LAYERS, standalone=True), encoding="utf-8")
        shutil.copyfile(out / "report.html", reports / f"{toml.stem}.html")
        rows.append((toml, s))
        print(toml.stem, file=sys.stderr)
    return rows


def _caption(s: dict) -> str:
    fs_products = [n for n, st in s["streams"].items() if s["units"].get(st["to"], {}).get("type") == "product"]
    parts = []
    for n in fs_products:
        st = s["streams"][n]
        parts.append(f"{n} {st['solids_tph']:.4g} t/h at P80 {st['p80_um']:.4g} um")
    for n, v in (s["circulating_load"] or {}).items():
        parts.append(f"circulating load of {n} {100 * v:.1f} %")
    if s.get("specific_energy_kWh_per_t") is not None:
        parts.append(f"{s['specific_energy_kWh_per_t']:.3g} kWh/t of product")
    parts.append(f"mass balance error {s['mass_balance_error']:.1e}")
    gc = s.get("grid_check") or {}
    if gc.get("worst") is not None:  # the run's grid error: against the extrapolated (converged) value
        parts.append(f"grid error of P80, P50 and circulating loads at most {100 * gc['worst']:.2g} % "
                     f"({gc['worst_at']}; threshold {100 * gc['threshold']:.2g} %: {gc['status']})")
    return "; ".join(parts)


def write_page(printed: dict, rows: list) -> None:
    lines = ["# Gallery", "",
             "<!-- written by docs/gallery/build.py: edit that script, not this page -->", "",
             "The daily jobs as a user runs them (inputs to download, then the command and what it "
             "printed), and every example flowsheet solved and drawn. Everything here is made by "
             "`python docs/gallery/build.py` from the files linked.", "", "## Daily jobs", ""]
    for name, title, text, _, inputs in JOBS:
        links = ", ".join(f"[{f}](downloads/{f})" for f in inputs)
        lines += [f"### {title}", "", text, "", f"Inputs: {links}.", "", "```text", printed[name].rstrip(), "```", ""]
    lines += ["## Example flowsheets", "",
              "Each runs from the repository root with `millflow run flowsheets/<name>.toml`; the numbers "
              "below are from these runs. Each report is the run's `report.html`.", ""]
    for toml, s in rows:
        stem = toml.stem
        title = s["title"] or stem.replace("_", " ")
        lines += [f"### {title}", "",
                  f"[{toml.name}](downloads/{toml.name}) ([report](gallery/reports/{stem}.html)): {_caption(s)}.", "",
                  f"![{title}: circuit, each stream with its solids (and water) t/h and P80]"
                  f"(gallery/img/{stem}-flowsheet.svg)", "",
                  f"![{title}: cumulative passing of every stream](gallery/img/{stem}-psd.png)", ""]
    lines += ["## Model error: falsification studies", "",
              "Bias and coverage of a linear, perfectly mixed fit against truths with model error "
              "(see [model-error.md](model-error.md)).", ""]
    for n in ("falsify_aggregation", "falsify_population", "falsify_slowing", "falsify_tanks", "micromixing"):
        lines += [f"![{n.replace('_', ' ')}](images/{n}.png)", ""]
    lines += ["## Work-precision", "", "![core](img/work_precision_core.png)", "",
              "![mill](img/work_precision_mill.png)", ""]
    (REPO / "docs" / "gallery.md").write_text("\n".join(lines), encoding="utf-8")


def main() -> int:
    sys.path.insert(0, str(REPO))
    import os

    os.chdir(REPO)
    with tempfile.TemporaryDirectory() as tmp:
        printed = run_jobs(Path(tmp))
        rows = solve_examples(Path(tmp) / "examples")
    write_page(printed, rows)
    print(json.dumps({"jobs": list(printed), "examples": [t.stem for t, _ in rows]}))
    return 0


if __name__ == "__main__":
    sys.exit(main())
