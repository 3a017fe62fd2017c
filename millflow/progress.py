"""Progress of long commands on stderr, hidden by ``--quiet`` (its one meaning).

One rule for every command: progress is shown only when it is wanted (no ``--quiet``)
and stderr is a terminal, as tqdm does with ``disable=None``; logs, pipes and captured
output get the results and nothing else. One display per command: :func:`progress`
opens it with the command's stages (solve, grid check, write ...) or a count of items
(cases, replicates); the command moves it on with ``stage(name)`` or ``update(n)``, and
library code deep inside a stage says what it is doing with :func:`note` (a fit's start,
a benchmark's case), shown after the bar and silently dropped when no display is open.
The elapsed time ticks every second, so a long stage never looks frozen.

With tqdm (extras ``sweep`` and ``test``) the display is one bar rewritten in place;
without it, one plain line per stage and at most one note every 2 s.
"""
from __future__ import annotations

import contextlib
import os
import sys
import threading
import time

__all__ = ["shown", "progress", "stages", "note", "Progress"]

#: Seconds between refreshes of the elapsed time, and between plain note lines.
TICK, PLAIN_EVERY = 1.0, 2.0

_OPEN: list = []  # the displays open now (the innermost last)


def shown(enabled: bool = True) -> bool:
    """True when progress is wanted (not ``--quiet``) and stderr is a terminal."""
    try:
        return bool(enabled) and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def _columns() -> int | None:
    """The width for tqdm: None unless the terminal reports none.

    None (tqdm reads the terminal's width) unless the terminal says it has no width (a
    fresh pseudo-terminal): then $COLUMNS, else 100.
    """
    try:
        if os.get_terminal_size(sys.stderr.fileno()).columns > 0:
            return None
    except (OSError, ValueError, AttributeError):
        pass
    try:
        return max(int(os.environ.get("COLUMNS", "100")), 20)
    except ValueError:
        return 100


def note(message: str) -> None:
    """What the work inside the current stage is doing.

    What the work inside the current stage is doing (shown after the bar; nothing when
    no display is open or progress is hidden). Library code may call it freely.
    """
    if _OPEN:
        _OPEN[-1].note(message)


class Progress:
    """The one progress display of a command (see the module docstring)."""

    def __init__(self, command: str, names=(), *, total: int | None = None, unit: str = "stage",
                 enabled: bool = True):
        self.command, self.names, self.k = command, list(names), 0
        self.total = total if total is not None else (len(self.names) or None)
        self.unit, self.bar, self._note, self._last = unit, None, "", 0.0
        self.on = shown(enabled)
        self._stop = threading.Event()
        self._thread = None
        if not self.on:
            return
        try:
            from tqdm import tqdm
        except ImportError:
            return
        # a count when there is more than one thing to count; the stage and note after the time
        count = "{n_fmt}/{total_fmt} " + unit + "s |{bar}| " if (self.total or 0) > 1 else ""
        self.bar = tqdm(total=self.total, desc=command, unit=unit, leave=False, file=sys.stderr,
                        bar_format="{desc}: " + count + "{elapsed}{postfix}", mininterval=0.2,
                        ncols=_columns())
        self._thread = threading.Thread(target=self._tick, daemon=True)
        self._thread.start()

    def _tick(self) -> None:
        while not self._stop.wait(TICK):
            with contextlib.suppress(Exception):  # a display refresh never fails the command
                self.bar.refresh()

    def _postfix(self) -> None:
        stage = self.names[self.k - 1] if 0 < self.k <= len(self.names) else ""
        text = "; ".join(t for t in (stage, self._note) if t)
        self.bar.set_postfix_str(text[:100], refresh=True)

    def stage(self, name: str) -> None:
        """Start stage ``name`` (the previous one is done)."""
        if not self.on:
            return
        if name not in self.names:
            self.names.insert(self.k, name)
            if self.bar is not None and self.bar.total is not None and self.bar.total < len(self.names):
                self.bar.total = len(self.names)
        self._note = ""
        if self.bar is not None:
            if self.k:
                self.bar.update(1)
            self.k += 1
            self._postfix()
        else:
            self.k += 1
            print(f"{self.command}: {name} ...", file=sys.stderr, flush=True)

    __call__ = stage

    def update(self, n: int = 1) -> None:
        """``n`` more items done (a display opened with ``total``)."""
        if self.on and self.bar is not None:
            self.bar.update(n)

    def note(self, message: str) -> None:
        """What the current stage is doing now."""
        if not self.on:
            return
        self._note = str(message)
        if self.bar is not None:
            self._postfix()
        elif time.monotonic() - self._last >= PLAIN_EVERY:
            self._last = time.monotonic()
            print(f"{self.command}: {self._note}", file=sys.stderr, flush=True)

    def close(self) -> None:
        """Stop the display and leave the terminal clean."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        if self.bar is not None:
            if self.bar.total:
                self.bar.update(self.bar.total - self.bar.n)
            self.bar.close()


@contextlib.contextmanager
def progress(command: str, names=(), *, total: int | None = None, unit: str = "stage", enabled: bool = True):
    """Open the command's display of stages or items.

    Open the command's display: ``names`` its stages (or ``total`` items of ``unit``);
    yields the :class:`Progress` (call it, or its ``stage``, as each stage starts).
    """
    p = Progress(command, names, total=total, unit=unit, enabled=enabled)
    _OPEN.append(p)
    try:
        yield p
    finally:
        _OPEN.remove(p)
        p.close()


def stages(command: str, names: list, enabled: bool = True):
    """:func:`progress` over named stages (yields ``stage(name)``, called as each starts)."""
    return progress(command, names, enabled=enabled)
