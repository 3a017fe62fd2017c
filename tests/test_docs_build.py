"""The documentation site builds with warnings as errors (`mkdocs build --strict`, as
.ci/run does; a link to a missing anchor is one), its math is rendered by a MathJax
served from the site itself, and no page loads anything from the network (nor asks
api.github.com for repository facts)."""
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


def test_no_page_fetches_repository_facts(site):
    """Material's repository widget (repo_url) fetches star and fork counts from
    api.github.com on every page load: the site does not set it."""
    _, out = site
    for page in out.rglob("*.html"):
        assert 'data-md-component="source"' not in page.read_text(encoding="utf-8"), page


def test_strict_build_fails_on_a_missing_anchor():
    import yaml

    cfg = yaml.safe_load((paths.REPO / "mkdocs.yml").read_text())
    assert cfg["strict"] is True and "repo_url" not in cfg
    assert cfg["validation"]["links"]["anchors"] == "warn"  # with strict: an error


def test_new_modules_have_api_pages_linked_from_getting_started():
    text = (paths.DOCS / "getting-started.md").read_text()
    for page, module in (("sweep", "millflow.sweep"), ("falsify", "millflow.falsify")):
        assert f"::: {module}" in (paths.DOCS / "api" / f"{page}.md").read_text()
        assert f"(api/{page}.md)" in text
    assert text.count("](api/") >= 8


@pytest.mark.parametrize("page", ["rtd.md", "mill.md", "equations.md"])
def test_guides_write_their_math_in_latex(page):
    """The formulas of these pages are LaTeX between $...$ (rendered by MathJax), not ASCII."""
    import re

    text = (paths.DOCS / page).read_text()
    prose = re.sub(r"```.*?```|`[^`\n]*`|\$\$.*?\$\$|\$[^$]+\$", "", text, flags=re.S)
    for ascii_math in ("E_hat", "sum c_k", "tau^2", "sqrt(", "exp(", "b_ij = B_ij", "S_i = S_i^E", "d_i*", "theta)"):
        assert ascii_math not in prose, f"{page}: {ascii_math!r} outside math"
    assert text.count("$") >= 40


#: Guides converted later; the number is a floor on their "$" signs (sweeps.md has few formulas).
LATEX_GUIDES = {"core.md": 100, "sweeps.md": 10, "survey.md": 40, "flowsheets.md": 80, "scaleup.md": 100,
                "benchmarks.md": 100, "model-error.md": 300,
                "fitting.md": 200}


@pytest.mark.parametrize("page", sorted(LATEX_GUIDES))
def test_other_guides_write_their_math_in_latex(page):
    """These guides' formulas are LaTeX too: no ASCII exponents, Greek names or chi-square in prose."""
    import re

    text = (paths.DOCS / page).read_text()
    prose = re.sub(r"```.*?```|`[^`\n]*`|\$\$.*?\$\$|\$[^$]+\$|^(?: {4}|\t)[^\n]*$", "", text, flags=re.S | re.M)
    for ascii_math in ("E_hat", "tau^2", "sqrt(", "exp(", "S_i = S_i^E", "d_i*", "d_i\\*", "theta)", "2^(1/",
                       "chi-square", "tau = ", "S^E", " >= ", " <= ", "lambda", "kappa"):
        assert ascii_math not in prose, f"{page}: {ascii_math!r} outside math"
    assert text.count("$") >= LATEX_GUIDES[page]


def test_gallery_drawings_are_legible_at_the_width_shown():
    """Each gallery flowsheet is the report's SVG drawing; at the 688 px the site shows it
    its 12 px text is at least 9 px high."""
    import re

    gallery = (paths.DOCS / "gallery.md").read_text()
    drawings = re.findall(r"\(gallery/img/([^)]+-flowsheet\.[a-z]+)\)", gallery)
    assert drawings and all(d.endswith(".svg") for d in drawings)
    for name in drawings:
        svg = (paths.DOCS / "gallery" / "img" / name).read_text()
        width = float(re.search(r'<svg[^>]*\bwidth="([\d.]+)"', svg).group(1))
        font = float(re.search(r"font-size:([\d.]+)px", svg).group(1))
        assert font * min(1.0, 688 / width) >= 9.0, (name, width)
