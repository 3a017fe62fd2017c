"""Every benchmark suite runs from an installed package: a copy of the packages alone on the
path, an empty working folder, and nothing read from the repository or the working folder.

The suites' circuits and configurations are package data (``millflow/bench/data``), copies
of the repository's files kept equal here. Each suite runs ``run(quick=True)`` in a child
process under an audit hook (``sys.addaudithook``) that records every file opened and every
folder listed inside the repository or the working folder: a suite that globbed
``flowsheets/`` of the working folder would find nothing there and leave its rows out
silently, so the working folder holds links to a checkout's folders and the listing itself
is what is refused. The quick suites of a few seconds run
by default (one child, about 40 s in all); the four that take 15-60 s are marked slow.
"""
import json
import os
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from millflow.commands.bench import suite_names, load_suite
from tests.paths import EXAMPLES, FLOWSHEETS, REPO

#: Suites whose quick run takes 15 s or more (measured: diagnose 50 s, model_error 22 s,
#: falsify 19 s, startup 13 s of fresh processes).
SLOW = ("diagnose", "falsify", "model_error", "startup")

#: Folders of a checkout linked into the working folder: a suite that looked for them there
#: (``Path("flowsheets").glob(...)`` finds nothing in an empty folder, with no file event to see)
#: opens or lists them, and the hook sees it.
DECOYS = ("flowsheets", "examples", "benchmarks", "docs", "tests")

_CHILD = r"""
import importlib, json, os, shutil, sys
from pathlib import Path

repo, work = Path(sys.argv[1]).resolve(), Path.cwd().resolve()
seen, busy = [], [False]
# the Python environment itself (a virtual environment may live inside the checkout, as
# CI's often does): reading installed packages is not reading the repository
env_roots = {Path(p).resolve() for p in (sys.prefix, sys.exec_prefix, sys.base_prefix)}


def hook(event, args):
    if busy[0] or event not in ("open", "os.listdir", "os.scandir", "glob.glob"):
        return
    path = args[0]
    if isinstance(path, int):
        return
    # shutil.rmtree (a TemporaryDirectory's clean-up) opens the folders it removes by their
    # names relative to their parent's descriptor, os.open(name, dir_fd=fd): the event carries
    # the bare name, which is not relative to the working folder, so it says nothing about it
    caller = sys._getframe(1).f_code
    if caller.co_filename == shutil.__file__ and caller.co_name.startswith("_rmtree"):
        if path is not None and not os.path.isabs(os.fsdecode(path)):
            return
    busy[0] = True
    try:
        p = Path(os.fsdecode(path) if path is not None else ".").resolve()
        if any(p == e or e in p.parents for e in env_roots):
            return
        if p == work or work in p.parents or p == repo or repo in p.parents:
            seen.append(f"{event} {os.fsdecode(path) if path is not None else '.'}")
    finally:
        busy[0] = False


sys.addaudithook(hook)
out = {}
for name in sys.argv[2:]:
    mod = importlib.import_module(f"millflow.bench.{name}")
    rows = mod.run(quick=True)
    out[name] = {"rows": len(rows), "file": mod.__file__, "read": sorted(set(seen))}
    seen.clear()
print(json.dumps(out))
"""


def _installed_copy(tmp_path) -> tuple[Path, Path]:
    """millflow and rtd copied alone into a folder (as an install lays them out, with their
    package data) and an empty working folder beside it."""
    import shutil

    import millflow
    import rtd

    site = tmp_path / "site"
    for pkg in (millflow, rtd):
        src = Path(pkg.__file__).parent
        shutil.copytree(src, site / src.name, ignore=shutil.ignore_patterns("__pycache__", "build", "*.egg-info"))
    work = tmp_path / "work"
    work.mkdir()
    for name in DECOYS:  # the working folder looks like a checkout's root: a read of it is seen
        (work / name).symlink_to(REPO / name, target_is_directory=True)
    return site, work


def _run_suites(tmp_path, names) -> dict:
    # -P: the working folder is not put on sys.path (else the import system itself lists it)
    site, work = _installed_copy(tmp_path)
    env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", MKL_NUM_THREADS="1", PYTHONPATH=str(site),
               MPLBACKEND="Agg")
    for var in ("MILLFLOW_BENCH_DATA", "MILLFLOW_KNIFE_DATA"):
        env.pop(var, None)
    out = subprocess.run([sys.executable, "-P", "-c", _CHILD, str(REPO), *names], capture_output=True, text=True,
                         env=env, timeout=900, cwd=work)
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    assert sorted(p.name for p in work.iterdir()) == sorted(DECOYS), "a suite wrote into the working folder"
    for name in names:
        assert Path(got[name]["file"]).is_relative_to(site), got[name]["file"]  # the copy ran, not the checkout
    return got


def _check(got: dict) -> None:
    for name, r in got.items():
        assert r["rows"] > 0, name
        assert r["read"] == [], f"bench {name} read the repository or the working folder: {r['read']}"


def test_quick_suites_run_from_an_installed_copy(tmp_path):
    _check(_run_suites(tmp_path, [n for n in suite_names() if n not in SLOW]))


@pytest.mark.slow
def test_slow_suites_run_from_an_installed_copy(tmp_path):
    _check(_run_suites(tmp_path, list(SLOW)))


def test_every_module_of_the_bench_is_a_suite():
    # `millflow bench NAME` lists the public modules: each must be a suite (helpers start with _)
    for name in suite_names():
        suite = load_suite(name)
        assert callable(suite.run) and isinstance(suite.DESCRIPTION, str), name
    assert set(SLOW) <= set(suite_names())


def test_package_data_are_the_repositorys_files():
    """The bench's copies equal the repository's files (text), and every file is present."""
    from importlib import resources

    data = resources.files("millflow.bench").joinpath("data")
    shipped = {p.name: p.read_text(encoding="utf-8") for p in FLOWSHEETS.glob("*.toml")}
    copies = {p.name: p.read_text(encoding="utf-8") for p in data.joinpath("flowsheets").iterdir()
              if p.name.endswith(".toml")}
    assert copies == shipped, "millflow/bench/data/flowsheets/ differs from flowsheets/"
    knife = (EXAMPLES / "knife_mill" / "knife_mill.toml").read_text(encoding="utf-8")
    assert data.joinpath("knife_mill.toml").read_text(encoding="utf-8") == knife


def test_package_data_are_declared_for_the_build():
    """Every data file of the bench matches a package-data pattern of pyproject.toml, so a
    wheel (not only a checkout or the copy above) carries it."""
    from fnmatch import fnmatch

    pats = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))["tool"]["setuptools"][
        "package-data"]["millflow.bench"]
    base = REPO / "millflow" / "bench"
    files = [p.relative_to(base).as_posix() for p in (base / "data").rglob("*") if p.is_file()
             and "__pycache__" not in p.parts]
    assert files and all(any(fnmatch(f, pat) for pat in pats) for f in files), files
