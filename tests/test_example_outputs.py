"""Example scripts write outside tracked files: `make_studies.py --quick` (a smoke run)
writes into make_studies-quick/ of the current folder, never over the committed figures
and summaries."""
import hashlib
import subprocess
import sys

from tests import paths

SCRIPT = paths.EXAMPLES / "model_error" / "make_studies.py"
TRACKED = [paths.DOCS / "images" / "micromixing.png", paths.EXAMPLES / "model_error" / "aggregation_summary.json",
           paths.EXAMPLES / "model_error" / "population_summary.json"]


def _digest(p):
    return hashlib.sha256(p.read_bytes()).hexdigest()


def test_quick_study_leaves_tracked_files_alone(tmp_path):
    before = {p: _digest(p) for p in TRACKED}
    r = subprocess.run([sys.executable, str(SCRIPT), "--quick", "micromixing"], cwd=tmp_path,
                       capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr[-2000:]
    assert (tmp_path / "make_studies-quick" / "micromixing.png").stat().st_size > 1000
    assert {p: _digest(p) for p in TRACKED} == before
