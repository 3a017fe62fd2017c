"""Build the gallery's figures: each example flowsheet solved and drawn.

    python docs/gallery/build.py

Writes docs/gallery/img/<example>-psd.png and <example>-flowsheet.png, and the plots of
the lab fit of examples/scaleup (lab_fit-fit_psd.png, lab_fit-parity.png): small PNGs,
committed so the site builds without running the solver.
"""
import shutil
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
REPO = HERE.parents[1]


def main() -> int:
    sys.path.insert(0, str(REPO))
    from millflow.flowsheet import load, save, solve

    out = HERE / "img"
    out.mkdir(exist_ok=True)
    for toml in sorted((REPO / "flowsheets").glob("*.toml")):
        with tempfile.TemporaryDirectory() as tmp:
            files = save(solve(load(toml)), Path(tmp) / "r", plots=True)
            for kind in ("psd", "flowsheet"):
                png = Path(tmp) / "r" / f"{kind}.png"
                if png.exists():
                    shutil.copyfile(png, out / f"{toml.stem}-{kind}.png")
        print(toml.stem, ", ".join(sorted(Path(f).name for f in files.values())))
    # a fit with its plots: the scale-up example's lab batch data (synthetic, stated so)
    from millflow.cli import main as cli
    with tempfile.TemporaryDirectory() as tmp:
        cfg = REPO / "examples" / "scaleup" / "lab_fit.toml"
        if cli(["fit", str(cfg), "--quiet", "--out", str(Path(tmp) / "fit")]) != 0:
            return 1
        for name in ("fit_psd.png", "parity.png"):
            shutil.copyfile(Path(tmp) / "fit" / name, out / f"lab_fit-{name}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
