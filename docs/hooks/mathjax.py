"""MkDocs hook: serve MathJax from the site itself (no CDN).

The equations are written in LaTeX between ``$...$`` / ``$$...$$`` (pymdownx.arithmatex,
generic mode) and typeset in the browser by MathJax 3's single-file ``tex-svg.js`` bundle
(glyphs as SVG paths: no font files). That file comes from the ``django-static-mathjax``
wheel of the docs extra (MathJax 3.2.2, Apache-2.0) and is added to the site as
``assets/mathjax/tex-svg.js`` at build time, so nothing is fetched from the network and
nothing is vendored into the repository.
"""
from __future__ import annotations

import importlib.util
from pathlib import Path

from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File

TARGET = "assets/mathjax/tex-svg.js"


def bundle() -> Path:
    spec = importlib.util.find_spec("mathjax")
    if spec is None or not spec.submodule_search_locations:
        raise PluginError("MathJax not found: pip install -e '.[docs]' (django-static-mathjax)")
    path = Path(next(iter(spec.submodule_search_locations))) / "static" / "mathjax" / "es5" / "tex-svg.js"
    if not path.is_file():
        raise PluginError(f"MathJax bundle missing at {path}: pip install -e '.[docs]' (django-static-mathjax)")
    return path


def on_files(files, config):
    files.append(File.generated(config, TARGET, abs_src_path=str(bundle())))
    return files
