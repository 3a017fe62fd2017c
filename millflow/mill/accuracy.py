"""One check of every mill solve against its requested tolerance.

A solve reports its mass-balance error and its error estimate, both relative to the
total feed (mills are linear: the relative error does not depend on the feed's scale).
Above ``tol`` either raises :class:`~millflow.errors.SolverError` naming the method and
the numbers (``on_inaccuracy="raise"``, the default) or warns with a named
:class:`~millflow.errors.AccuracyWarning` (``"warn"``). Nothing above the tolerance is
returned silently.
"""
from __future__ import annotations

import math
import warnings

from millflow.errors import AccuracyWarning, InputError, SolverError

__all__ = ["ON_INACCURACY", "check_accuracy"]

ON_INACCURACY = ("raise", "warn")


def check_accuracy(where: str, method: str, mass_balance_rel: float, estimate_rel: float, tol: float,
                   on_inaccuracy: str = "raise", advice: str | None = None) -> None:
    """Raise (or warn) if a relative mass-balance error or error estimate exceeds ``tol``."""
    if on_inaccuracy not in ON_INACCURACY:
        raise InputError(f"on_inaccuracy = {on_inaccuracy!r}: expected 'raise' or 'warn'")
    problems = []
    if not (math.isfinite(mass_balance_rel) and mass_balance_rel <= tol):
        problems.append(f"mass balance error {mass_balance_rel:.2g} of the feed")
    if not (math.isfinite(estimate_rel) and estimate_rel <= tol) and not math.isnan(estimate_rel):
        problems.append(f"error estimate {estimate_rel:.2g} of the feed")
    if not problems:
        return
    msg = (f"{where}: {method}: {' and '.join(problems)} above the tolerance {tol:.2g}; "
           + (f"{advice}; " if advice else "")
           + "or loosen tol, or pass on_inaccuracy='warn' to accept it")
    if on_inaccuracy == "raise":
        raise SolverError(msg)
    warnings.warn(msg, AccuracyWarning, stacklevel=3)
