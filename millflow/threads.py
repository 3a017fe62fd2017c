"""BLAS threads for small dense problems: one thread inside millflow's solves.

The dense systems of a population balance are small (N = 25..400 classes): an LU
factorisation of a 150 x 150 matrix takes ~0.1 ms on one core, and splitting it over
several BLAS threads adds synchronisation that costs more than the arithmetic. On a
loaded machine it is far worse: threads that wait for a busy core made the non-linear
batch solve at ~150 classes 15x slower. :func:`single_threaded_blas` limits every BLAS
library loaded in the process (OpenBLAS, MKL, BLIS, as numpy and scipy each ship one)
to one thread for the duration of a solve and restores the previous limits after it,
through ``threadpoolctl``'s ``ThreadpoolController.limit`` (the libraries'
``*_set_num_threads`` calls). Without threadpoolctl installed the limits are left as
they are (set ``OPENBLAS_NUM_THREADS=1`` before starting Python for the same effect).

The controller is built once (it scans the loaded shared libraries, ~30 ms) and again
when a BLAS library is loaded later; entering the context then costs ~10 us. Nested
uses cost nothing: only the outermost one sets and restores the limits.
"""
from __future__ import annotations

import contextlib
import functools
import sys
import threading

__all__ = ["single_threaded_blas", "blas_threads", "limit_blas_threads"]

_state = threading.local()
_controller = None
_controller_modules = None  # _loaded_libraries() when the controller was built
_modules_seen = -1  # len(sys.modules) when the libraries were last looked at


#: Parts of the file names of the BLAS libraries threadpoolctl controls (OpenBLAS, MKL,
#: BLIS, FlexiBLAS; the scipy-openblas wheels' libscipy_openblas).
_BLAS_NAMES = (b"blas", b"mkl", b"blis")


def _loaded_libraries():
    """What changes when a BLAS library is loaded: the BLAS shared objects mapped into the
    process (Linux: /proc/self/maps, ~1 ms), else the number of imported modules (a new
    module may have loaded another BLAS)."""
    try:
        with open("/proc/self/maps", "rb") as fh:
            names = {line.rsplit(None, 1)[-1] for line in fh if b".so" in line}
    except OSError:
        return len(sys.modules)
    return frozenset(n for n in names if any(k in n.rsplit(b"/", 1)[-1].lower() for k in _BLAS_NAMES))


def _get_controller():
    """The cached ThreadpoolController, rebuilt when a shared library was loaded since
    (it may be another BLAS); None without threadpoolctl."""
    global _controller, _controller_modules, _modules_seen
    if _controller is not None and len(sys.modules) == _modules_seen:
        return _controller  # nothing imported since: no library can have been loaded (the hot path)
    if _controller is None or _loaded_libraries() != _controller_modules:
        try:
            from threadpoolctl import ThreadpoolController
        except ImportError:
            return None
        import scipy.linalg  # noqa: F401  (loads scipy's own BLAS, so that it is limited too)

        _controller = ThreadpoolController()
        _controller_modules = _loaded_libraries()
    _modules_seen = len(sys.modules)
    return _controller


@contextlib.contextmanager
def single_threaded_blas():
    """Context: every loaded BLAS library runs on one thread inside; previous limits after."""
    if getattr(_state, "depth", 0):
        _state.depth += 1
        try:
            yield
        finally:
            _state.depth -= 1
        return
    controller = _get_controller()
    _state.depth = 1
    try:
        if controller is None:
            yield
        else:
            with controller.limit(limits=1, user_api="blas"):
                yield
    finally:
        _state.depth = 0


def limit_blas_threads(fun):
    """Decorator: ``fun`` runs inside :func:`single_threaded_blas`."""
    @functools.wraps(fun)
    def wrapper(*args, **kwargs):
        with single_threaded_blas():
            return fun(*args, **kwargs)
    return wrapper


def blas_threads() -> int | None:
    """The largest thread count of the loaded BLAS libraries now (None without threadpoolctl)."""
    controller = _get_controller()
    if controller is None:
        return None
    counts = [lib.num_threads for lib in controller.lib_controllers if lib.user_api == "blas"]
    return max(counts) if counts else None
