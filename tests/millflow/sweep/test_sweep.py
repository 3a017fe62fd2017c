"""Issue 14 §3: sweeps of a flowsheet, serial and on a Dask LocalCluster."""
import numpy as np
import pytest

from millflow.cli import main
from millflow.errors import InputError
from millflow.sweep import parse_vary, run_sweep
from tests import paths
import tempfile
from pathlib import Path

from tests.closed_circuit import per_time_file

# the example in its per-time form (tau_min = 3.5 fixed), the linear circuit these sweeps vary
CLOSED = per_time_file(Path(tempfile.mkdtemp()))
VARY = ["units.ball_mill.tau_min=0:6:4", "units.fresh_feed.solids_tph=150:300:3"]


def test_grid_sweep_has_a_dimension_per_key_and_keeps_failed_cases():
    ds = run_sweep(CLOSED, [parse_vary(v) for v in VARY], scheduler="serial", progress=False)
    assert ds["p80_um"].sizes == {"product": 1, "units.ball_mill.tau_min": 4, "units.fresh_feed.solids_tph": 3}
    bad = ds["reason"].sel({"units.ball_mill.tau_min": 0.0}).values
    assert all("tau_min = 0.0" in r for r in bad)  # tau = 0 is invalid: NaN with its reason, not dropped
    assert np.isnan(ds["p80_um"].sel({"units.ball_mill.tau_min": 0.0})).all()
    p80 = ds["p80_um"].sel(product="overflow", **{"units.fresh_feed.solids_tph": 225.0}).values[1:]
    assert np.all(np.diff(p80) < 0)  # longer residence: a finer product
    # a linear circuit with tau given is linear in the feed rate: the product PSD does not change
    by_feed = ds["p80_um"].sel(product="overflow", **{"units.ball_mill.tau_min": 4.0}).values
    np.testing.assert_allclose(by_feed, by_feed[0], rtol=1e-9)
    assert ds.attrs["n_cases"] == 12 and ds.attrs["n_failed"] == 3
    assert float(ds["mass_balance_error"].max()) < 1e-12


def test_local_cluster_gives_the_serial_result():
    """Two Dask workers solve the same chunks: the same Dataset to rounding."""
    axes = [parse_vary(v) for v in VARY]
    serial = run_sweep(CLOSED, axes, scheduler="serial", progress=False)
    dask = run_sweep(CLOSED, axes, scheduler="local", workers=2, chunk=2, progress=False)
    for var in ("p80_um", "p50_um", "circulating_load", "specific_energy_kWh_per_t"):
        np.testing.assert_allclose(dask[var].values, serial[var].values, rtol=1e-12, equal_nan=True)
    assert (dask["reason"].values == serial["reason"].values).all()


def test_latin_hypercube_cases_stay_in_range():
    ds = run_sweep(CLOSED, [parse_vary("units.ball_mill.tau_min=2:6:1")], samples=8, seed=3,
                   scheduler="serial", progress=False)
    tau = ds["units.ball_mill.tau_min"].values
    assert ds.sizes["case"] == 8 and tau.min() >= 2 and tau.max() <= 6 and np.unique(tau).size == 8


@pytest.mark.parametrize("vary, match", [("tau=1:2", "expected KEY=START:STOP:N"),
                                         ("units.ball_mill.tau_min=a:2:3", "must be numbers"),
                                         ("units.ball_mill.tau_hours=1:2:3", "no key 'units.ball_mill.tau_hours'"),
                                         ("units.nomill.tau_min=1:2:3", "no table 'units.nomill'")])
def test_bad_vary_is_named(vary, match, tmp_path, capsys):
    with pytest.raises(InputError, match=match):
        run_sweep(CLOSED, [parse_vary(vary)], scheduler="serial", progress=False)
    assert main(["sweep", str(CLOSED), "--vary", vary, "--scheduler", "serial", "--quiet",
                 "--out", str(tmp_path / "o")]) == 2
    assert capsys.readouterr().err.count("\n") == 1 and not (tmp_path / "o").exists()


def test_cli_writes_dataset_csv_and_plot(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["sweep", str(CLOSED), "--vary", VARY[0], "--scheduler", "serial", "--quiet", "--out", str(out)]) == 0
    assert {"sweep.nc", "sweep.csv", "sweep.png", "summary.json", ".millflow-manifest.json"} <= \
        {p.name for p in out.iterdir()}


def test_compare_two_flowsheets(tmp_path, capsys):
    """Issue 14 §3: one table and one plot of the streams both flowsheets share."""
    import json
    a, b = paths.FLOWSHEETS / "open_circuit_ball_mill.toml", CLOSED
    assert main(["compare", str(a), str(b), "--json", "--out", str(tmp_path / "c")]) == 0
    res = json.loads(capsys.readouterr().out)
    assert [r["stream"] for r in res["streams"]] == ["mill_feed", "mill_discharge"]
    r = res["streams"][0]
    assert r["d_p80_um"] == pytest.approx(r["p80_um_b"] - r["p80_um_a"])
    assert {"compare.csv", "compare.json", "compare.png"} <= {p.name for p in (tmp_path / "c").iterdir()}
    assert main(["compare", str(a), str(paths.FLOWSHEETS / "hammer_mill_screen.toml"), "--quiet",
                 "--out", str(tmp_path / "d")]) in (0, 2)  # no shared stream: exit 2 with a line


def test_a_killed_worker_is_replaced_and_the_dataset_is_complete():
    """A worker process killed mid-sweep (SIGKILL, as a crash or the OOM killer would) loses
    its chunk; the scheduler runs it again on another worker (the nanny restarts the dead
    one): every case is solved and none is dropped. The test holds no Client of its own:
    it watches the in-process scheduler and kills the worker's process by its pid."""
    import os
    import signal
    import threading
    import time

    from dask.distributed import LocalCluster

    axes = [parse_vary("units.ball_mill.tau_min=2:6:12"), parse_vary("units.cyclones.d50c_um=100:200:6")]
    killed = []
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None) as cluster:
        def kill_one_worker():
            deadline = time.monotonic() + 60
            while time.monotonic() < deadline:
                if any(ts.state == "processing" for ts in list(cluster.scheduler.tasks.values())):
                    break
                time.sleep(0.01)
            nanny = next(iter(cluster.workers.values()))
            pid = nanny.process.process.pid
            os.kill(pid, signal.SIGKILL)
            killed.append(pid)

        t = threading.Thread(target=kill_one_worker, daemon=True)
        t.start()
        ds = run_sweep(CLOSED, axes, scheduler=cluster.scheduler_address, chunk=3, progress=False)
        t.join(timeout=60)
    assert killed, "no worker was killed: the test did not exercise the retry"
    assert ds.attrs["n_cases"] == 72 and ds.attrs["n_failed"] == 0
    assert np.isfinite(ds["p80_um"].values).all()
    serial = run_sweep(CLOSED, axes, scheduler="serial", progress=False)
    np.testing.assert_allclose(ds["p80_um"].values, serial["p80_um"].values, rtol=1e-12)
