"""The documentation site builds with warnings as errors (`mkdocs build --strict`, as
.ci/run does), its math is rendered by a MathJax served from the site itself, and no
page loads anything from the network."""
import importlib.util
import os
import subprocess
import sys

import pytest

from tests import paths

pytestmark = pytest.mark.skipif(importlib.util.find_spec("mkdocs") is None
                                or importlib.util.find_spec("mkdocstrings") is None,
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
