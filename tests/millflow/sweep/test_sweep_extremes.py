"""Sweeps at the edges: open circuits, every case failing, bad seeds, schedulers and sizes."""
import re

import pandas as pd
import pytest
import xarray as xr

from millflow.cli import main
from millflow.errors import InputError
from millflow.sweep import parse_vary, run_sweep
from millflow.sweep.run import MAX_CASES
import tempfile
from pathlib import Path

from tests import paths
from tests.closed_circuit import per_time_file

# the closed-circuit example in its per-time form (tau_min fixed), the key these sweeps vary
CLOSED = per_time_file(Path(tempfile.mkdtemp()))
OPEN = paths.FLOWSHEETS / "open_circuit_ball_mill.toml"


def test_open_circuit_sweep_writes_a_readable_dataset_and_a_full_table(tmp_path, capsys):
    # no recycle stream: the zero-length dimension made sweep.nc unreadable and the CSV empty
    out = tmp_path / "s"
    assert main(["sweep", str(OPEN), "--vary", "units.ball_mill.holdup_t=12:24:3", "--scheduler", "serial",
                 "--quiet", "--no-plots", "--out", str(out)]) == 0
    with xr.open_dataset(out / "sweep.nc") as ds:
        assert ds.sizes["units.ball_mill.holdup_t"] == 3
        assert "circulating_load" not in ds and "no_recycle_stream" in ds.attrs
        assert float(ds["p80_um"].min()) > 0
    table = pd.read_csv(out / "sweep.csv")
    assert len(table) == 3 * 2  # three cases x two product streams


def test_every_case_failing_is_exit_1_with_readable_files(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", str(CLOSED), "--vary", "units.ball_mill.tau_min=-2:-1:2", "--scheduler", "serial",
                 "--quiet", "--no-plots", "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "every case failed" in err and "Traceback" not in err
    with xr.open_dataset(out / "sweep.nc") as ds:
        assert all("tau_min" in r for r in ds["reason"].values)
    assert len(pd.read_csv(out / "sweep.csv")) == 2


@pytest.mark.parametrize("args, match", [
    (["--samples", "3", "--seed", "-1"], "--seed -1"),
    (["--samples", "3", "--seed", str(2**70)], "--seed"),
    (["--scheduler", "foo"], "--scheduler 'foo'"),
    (["--vary", "units.fresh_feed.solids_tph=100:200:100000", "--vary", "units.ball_mill.power_kW=1:2:100000"],
     "2e\\+10 cases; at most"),
    (["--samples", str(10**12)], "1e\\+12 cases"),
])
def test_bad_sweep_designs_are_one_line_errors(args, match, tmp_path, capsys):
    argv = ["sweep", str(CLOSED), "--vary", "units.ball_mill.tau_min=2:3:2", *args, "--quiet",
            "--out", str(tmp_path / "s")]
    if "--scheduler" not in args:
        argv += ["--scheduler", "serial"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1
    assert re.search(match, err), err
    assert not (tmp_path / "s").exists()


def test_the_case_limit_is_checked_before_any_case_is_built():
    axes = [parse_vary(f"units.ball_mill.tau_min=1:2:{MAX_CASES + 1}")]
    with pytest.raises(InputError, match="at most 1,000,000"):
        run_sweep(CLOSED, axes, scheduler="serial", progress=False)
