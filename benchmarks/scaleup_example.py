"""Benchmark: the README / docs scale-up example (``millflow scaleup fit.json --to plant.toml
--target-p80-um 150``) against the previous defaults, in the same process.

Before: 1,000 Monte Carlo draws on the 2^(1/4) prediction grid, no model-form terms. Now:
400 draws on the 2^(1/8) grid plus the model-form contributions (three power families, the
other scaling rule, the halved grid). Interleaved repeats, medians of wall and CPU time; on a
shared machine the CPU time is the fairer measure (the wall time includes waiting for a core).

    cd examples/scaleup && python make_lab_data.py && python -m millflow fit lab_fit.toml --json --quiet > fit.json
    cd ../.. && python benchmarks/scaleup_example.py examples/scaleup/fit.json
"""
from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # small dense algebra: one BLAS thread per process

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "scaleup"


def _old_plant(folder: Path) -> Path:
    text = (EXAMPLE / "plant.toml").read_text()
    text = text.replace("# power_model: the plant's", 'power_model = "hogg_fuerstenau"\n#')
    text = text.replace("ratio = 1.0905077326652577", "ratio = 1.189207115002721")
    p = folder / "plant_before.toml"
    p.write_text(text)
    return p


def _before(fit_path, plant):
    from millflow.scaleup.api import predict_plant
    from millflow.scaleup.fitted import load_fit
    from millflow.scaleup.plantfile import load_plant

    su, _ = load_plant(plant, load_fit(fit_path))
    predict_plant(su, 150e-6, n_draws=1000)


def _now(fit_path, out):
    from millflow.cli import main

    assert main(["scaleup", str(fit_path), "--to", str(EXAMPLE / "plant.toml"), "--target-p80-um", "150",
                 "--quiet", "--no-plots", "--overwrite", "--out", str(out)]) == 0


def main(fit_path: str, repeats: int = 3) -> dict:
    times = {"before": [], "now": []}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        old = _old_plant(tmp)
        for _ in range(repeats):
            for name, run in (("before", lambda: _before(fit_path, old)), ("now", lambda: _now(fit_path, tmp / "o"))):
                w, c = time.perf_counter(), time.process_time()
                run()
                times[name].append((time.perf_counter() - w, time.process_time() - c))
    med = {k: (statistics.median(t[0] for t in v), statistics.median(t[1] for t in v)) for k, v in times.items()}
    out = {"before_wall_s": med["before"][0], "before_cpu_s": med["before"][1], "now_wall_s": med["now"][0],
           "now_cpu_s": med["now"][1], "cpu_ratio_now_over_before": med["now"][1] / med["before"][1],
           "load_average_1min": os.getloadavg()[0]}
    for k, v in out.items():
        print(f"{k}: {v:.3g}")
    return out


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else str(EXAMPLE / "fit.json"))
