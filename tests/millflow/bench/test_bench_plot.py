"""Issue 16: `millflow bench core|mill --plot FILE.png` draws error against run time."""
import numpy as np

from millflow.cli import main
from millflow.commands.bench import ERROR_FLOOR, plot_work_precision


def test_bench_mill_plot_is_written_and_never_over_a_file(tmp_path, capsys):
    png = tmp_path / "wp.png"
    assert main(["bench", "mill", "--quick", "--quiet", "--plot", str(png)]) == 0
    data = png.read_bytes()
    assert data[:8] == b"\x89PNG\r\n\x1a\n" and len(data) > 10_000
    assert main(["bench", "mill", "--quick", "--quiet", "--plot", str(png)]) == 2  # exists: refused
    assert "exists" in capsys.readouterr().err and png.read_bytes() == data


def test_plot_draws_every_row_with_an_error_and_a_time(tmp_path):
    rows = [{"method": "a", "max_abs_error": 1e-3, "runtime_s": 1e-3},
            {"method": "a", "max_abs_error": 0.0, "runtime_s": 2e-3},  # exact: drawn at the floor
            {"method": "b", "max_abs_error": float("nan"), "runtime_s": 1e-3},  # no error: not drawn
            {"method": "c", "runtime_s": 1e-3}]
    assert plot_work_precision(rows, tmp_path / "p.png", "test") == 2
    assert ERROR_FLOOR > 0 and np.isfinite(ERROR_FLOOR)
