"""``millflow bench SUITE [--json] [--quick] [--make-references]``: run a benchmark suite.

Suites are the modules of :mod:`millflow.bench` (found by listing the package, so a
new suite is a new module); each exposes ``DESCRIPTION`` and
``run(quick=False) -> list[dict]`` and optionally ``format_table(rows)`` and
``make_references()`` (docs/CONTRACTS.md, "Benchmarks"; docs/benchmarks.md).

Timings are single-threaded BLAS. The thread count of OpenBLAS/MKL/OpenMP is read from
the environment once, when numpy is first imported, and ``millflow`` imports numpy
before any sub-command runs; setting the variables here would change nothing. So when
``OPENBLAS_NUM_THREADS``, ``OMP_NUM_THREADS`` and ``MKL_NUM_THREADS`` are not all 1,
``millflow bench`` started from the command line re-runs itself once in a child
process (``python -m millflow bench ...``) with them set to 1 and returns the child's
exit code. Called in-process (``millflow.cli.main([...])``, e.g. from a test) it
cannot do that: it runs anyway, says so on stderr and marks every row
``"blas_threads": "default"``. Set the variables before starting Python to avoid both.
"""
from __future__ import annotations

import importlib
import json
import math
import os
import pkgutil
import subprocess
import sys

from millflow.errors import InputError
from millflow.compiled import status as kernel_status

THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
_NO_REEXEC = "MILLFLOW_BENCH_REEXEC"


def suite_names() -> list[str]:
    """Names of the benchmark suites: the modules of millflow.bench."""
    import millflow.bench as bench

    return sorted(m.name for m in pkgutil.iter_modules(bench.__path__) if not m.name.startswith("_"))


def load_suite(name: str):
    """Import suite ``name``; an unknown name raises InputError listing the valid ones.
    A hyphen stands for the module's underscore (``model-error`` is ``model_error``)."""
    names = suite_names()
    name = name.replace("-", "_")
    if name not in names:
        raise InputError(f"benchmark suite {name!r} is unknown; expected one of: {', '.join(names)}")
    return importlib.import_module(f"millflow.bench.{name}")


def add_parser(subparsers) -> None:
    p = subparsers.add_parser(
        "bench",
        help="run a benchmark suite (work-precision tables, timings)",
        description="Run a benchmark suite of millflow.bench and print its table "
                    f"(suites: {', '.join(suite_names())}). Timings use single-threaded BLAS.",
    )
    p.add_argument("suite", help="suite name, e.g. core")
    p.add_argument("--json", action="store_true", help="print the rows as a JSON array instead of a table")
    from millflow.commands.output import QUIET_HELP

    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.add_argument("--plot", default=None, metavar="FILE.png",
                   help="also draw error against run time for every method on one log-log axis")
    p.add_argument("--quick", action="store_true", help="fewer sizes and repeats (a few seconds)")
    p.add_argument("--make-references", action="store_true",
                   help="(re)make the suite's cached high-precision references first (slow)")
    p.set_defaults(func=run_command)


def _single_threaded() -> bool:
    return all(os.environ.get(v) == "1" for v in THREAD_VARS)


def _rerun_single_threaded() -> int | None:
    """Re-run this command line in a child with single-threaded BLAS; None if not possible."""
    if os.environ.get(_NO_REEXEC) == "0" or sys.argv[1:2] != ["bench"]:
        return None  # not our own command line (in-process call), or already the child
    env = dict(os.environ, **{v: "1" for v in THREAD_VARS}, **{_NO_REEXEC: "0"})
    sys.stdout.flush()
    return subprocess.run([sys.executable, "-m", "millflow", *sys.argv[1:]], env=env).returncode


def _jsonable(value):
    """Plain JSON values: numpy scalars and arrays unwrapped, non-finite floats as null."""
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if hasattr(value, "tolist"):  # numpy scalar or array
        return _jsonable(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _generic_table(rows: list[dict]) -> str:
    keys = ["case", "method", "runtime_s", "max_abs_error", "mass_balance_error", "ratio_vs_baseline"]
    out = ["  ".join(f"{k:>18}" for k in keys)]
    for r in rows:
        cells = [r.get(k) for k in keys]
        out.append("  ".join(f"{c:>18.6g}" if isinstance(c, float) else f"{str(c):>18}" for c in cells))
    return "\n".join(out)


def run_command(args) -> int:
    suite = load_suite(args.suite)
    threads = "1"
    if not _single_threaded():
        code = _rerun_single_threaded()
        if code is not None:
            return code
        threads = "default"
        # a warning on the timings, not progress: --quiet does not hide it
        print("millflow bench: BLAS threads not limited (set OPENBLAS_NUM_THREADS=1 OMP_NUM_THREADS=1 "
              "MKL_NUM_THREADS=1 before starting Python); timings may differ", file=sys.stderr)
    if args.make_references:
        maker = getattr(suite, "make_references", None)
        if maker is None:
            raise InputError(f"benchmark suite {args.suite!r} has no references to make")
        maker()
    if args.plot and os.path.exists(args.plot):  # checked before the run, not after it
        raise InputError(f"--plot {args.plot}: exists; give a new file name (or remove it)")
    from millflow.progress import progress

    label = f"suite {args.suite}" + (" (quick)" if args.quick else "")
    # one stage; the suite says which case it runs with millflow.progress.note, and the
    # elapsed time ticks meanwhile
    with progress("millflow bench", [label], enabled=not getattr(args, "quiet", False)) as stage:
        stage(label)
        rows = suite.run(quick=args.quick)
    kernels = kernel_status()
    for row in rows:
        row.setdefault("suite", args.suite)
        row["blas_threads"] = threads
        row["kernels"] = kernels
    if args.plot:
        plot_work_precision(rows, args.plot, f"millflow bench {args.suite}" + (" --quick" if args.quick else ""))
    if args.json:
        print(json.dumps(_jsonable(rows), indent=1, allow_nan=False))
    else:
        fmt = getattr(suite, "format_table", _generic_table)
        print(f"millflow bench {args.suite}: {suite.DESCRIPTION}" + (" (quick)" if args.quick else "")
              + f"; kernels: {kernels}")
        print(fmt(rows))
    return 0


#: Errors below this are drawn at it (an exact 0 has no place on a log axis).
ERROR_FLOOR = 1e-17


def plot_work_precision(rows: list[dict], path, title: str) -> int:
    """Error (max abs error against the reference) against run time [s] for every row that
    has both, one marker series per method, on one log-log axis; written to ``path``
    (PNG, whole or not at all: drawn into a temporary file beside it, then renamed).
    Returns the number of points drawn; a suite without error columns is refused."""
    import os
    import tempfile

    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    pts = {}
    for r in rows:
        err, t = r.get("max_abs_error"), r.get("runtime_s")
        if isinstance(err, (int, float)) and isinstance(t, (int, float)) and math.isfinite(err) \
                and math.isfinite(t) and t > 0:
            pts.setdefault(str(r.get("method", "?")), []).append((t, max(float(err), ERROR_FLOOR)))
    if not pts:
        raise InputError(f"--plot {path}: this suite reports no errors to draw (no max_abs_error with runtime_s)")
    fig = Figure(figsize=(7.5, 5.0))
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    markers = "osD^v<>pPhX*"
    for k, (method, xy) in enumerate(sorted(pts.items())):
        t, e = zip(*sorted(xy))
        ax.loglog(t, e, markers[k % len(markers)], ms=5, alpha=0.8, label=method)
    ax.set_xlabel("run time [s]")
    ax.set_ylabel(f"max abs error (floor {ERROR_FLOOR:g})")
    ax.set_title(f"work-precision: {title}", fontsize=9)
    ax.grid(True, which="major", alpha=0.3)
    ax.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    path = os.fspath(path)
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        raise InputError(f"--plot {path}: the folder {folder} does not exist")
    if os.path.exists(path):  # never over a file the user has: name a new one
        raise InputError(f"--plot {path}: exists; give a new file name (or remove it)")
    fd, tmp = tempfile.mkstemp(prefix=".plot-", suffix=".png", dir=folder)
    os.close(fd)
    try:
        fig.savefig(tmp, dpi=110)
        mask = os.umask(0)
        os.umask(mask)
        os.chmod(tmp, 0o666 & ~mask)  # as an ordinary new file (mkstemp makes it private)
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return sum(len(v) for v in pts.values())
