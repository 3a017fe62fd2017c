"""Progress of long fits: one line per stage on stderr, only once a run is slow.

``fit``, ``leave_out``, ``nested_leave_out`` and ``compare_models`` take ``progress`` (a
callable taking a message) and ``quiet``. By default (``progress=None, quiet=False``) a
:class:`StageReporter` prints each stage's message to stderr once the run has taken
longer than two seconds, so quick fits stay silent and a minute-long fit says what it
is doing. ``quiet=True`` silences it; a given ``progress`` callable receives every
message instead.
"""
from __future__ import annotations

import sys
import time

__all__ = ["StageReporter", "reporter", "AFTER_S"]

#: A run reports its stages once it has taken longer than this [s].
AFTER_S = 2.0


class StageReporter:
    """Callable: prints ``[millflow <what> <elapsed> s] message`` to ``stream`` (stderr)
    for messages that come after ``after_s`` seconds of the run."""

    def __init__(self, what: str, after_s: float = AFTER_S, stream=None):
        self.what, self.after_s, self.stream = what, after_s, stream
        self.t0 = time.perf_counter()

    def __call__(self, msg: str) -> None:
        elapsed = time.perf_counter() - self.t0
        if elapsed >= self.after_s:
            print(f"[millflow {self.what} {elapsed:.0f} s] {msg}", file=self.stream or sys.stderr, flush=True)


def reporter(progress, quiet: bool, what: str):
    """The message sink of a run: nothing when quiet, the given callable, or a
    :class:`StageReporter`."""
    if quiet:
        return lambda msg: None
    return progress if progress is not None else StageReporter(what)
