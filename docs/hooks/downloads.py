"""MkDocs hook: the gallery's input files as downloads, straight from where they live.

Every file named in :data:`FILES` (repository paths) is added to the site under
``downloads/`` at build time, so the gallery links the very files the examples run
and nothing is copied into docs/.
"""
from __future__ import annotations

from pathlib import Path

from mkdocs.structure.files import File

REPO = Path(__file__).resolve().parents[2]
FILES = sorted([*(f"flowsheets/{p.name}" for p in (REPO / "flowsheets").glob("*.toml")),
                "docs/examples/tracer_tis.csv", "docs/gallery/inputs/tracer_mill.toml",
                "examples/scaleup/lab_fit.toml", "examples/scaleup/lab_psd.csv", "examples/scaleup/lab_process.csv",
                "examples/scaleup/plant.toml", "examples/survey/survey.toml", "examples/survey/circuit.toml"])


def on_files(files, config):
    for rel in FILES:
        src = REPO / rel
        if src.is_file():
            files.append(File.generated(config, f"downloads/{Path(rel).name}", abs_src_path=str(src)))
    return files
