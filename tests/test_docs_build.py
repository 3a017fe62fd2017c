"""The documentation site builds with warnings as errors (`mkdocs build --strict`, as
.ci/run does), its math is rendered by a MathJax served from the site itself, and no
page loads anything from the network."""
import importlib.util
import os
import subprocess
import sys

import pytest

from tests import paths

pytestmark = pytest.mark.skipif(any(importlib.util.find_spec(m) is None
                                    for m in ("mkdocs", "mkdocstrings", "pymdownx", "mathjax")),
                                reason="the docs extra is not installed (pip install -e '.[docs]')")


@pytest.fixture(scope="module")
def site(tmp_path_factory):
    out = tmp_path_factory.mktemp("site")
    env = dict(os.environ, NO_MKDOCS_2_WARNING="1", PYTHONPATH=str(paths.REPO))
    proc = subprocess.run([sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
                          cwd=paths.REPO, capture_output=True, text=True, timeout=600, env=env)
    return proc, out


def test_strict_build_has_no_warnings(site):
    proc, _ = site
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "WARNING" not in proc.stderr, proc.stderr[-3000:]


def test_nothing_is_loaded_from_the_network(site):
    import re

    _, out = site
    assert (out / "assets" / "mathjax" / "tex-svg.js").stat().st_size > 1_000_000  # MathJax served locally
    loaded = re.compile(r'(?:<script[^>]*\bsrc|<link[^>]*rel="stylesheet"[^>]*\bhref|<img[^>]*\bsrc)="(https?:)?//')
    for page in out.rglob("*.html"):
        assert not loaded.search(page.read_text(encoding="utf-8")), page


def test_equations_render_in_headless_chromium(site):
    import shutil

    browser = next((shutil.which(b) for b in ("chromium", "chromium-browser", "google-chrome") if shutil.which(b)),
                   None)
    if browser is None:
        pytest.skip("no Chromium or Chrome on this machine (.ci/run installs chromium with apt-get)")
    _, out = site
    page = out / "equations" / "index.html"
    proc = subprocess.run([browser, "--headless", "--no-sandbox", "--disable-gpu", "--enable-logging=stderr", "--v=0",
                           "--virtual-time-budget=10000", "--dump-dom", page.as_uri()],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0
    assert not [line for line in proc.stderr.splitlines() if ":CONSOLE" in line and "rror" in line]
    # every display equation (eqs. 1-10) and the inline ones typeset by MathJax
    assert proc.stdout.count("<mjx-container") >= 30
