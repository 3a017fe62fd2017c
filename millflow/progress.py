"""Progress of long commands on stderr, hidden by ``--quiet`` (its one meaning).

:func:`stages` shows which stage of a command runs (solve, grid check, write ...), with a
tqdm bar when tqdm is installed (extras ``sweep`` and ``test``) and one plain line per
stage otherwise. Progress is shown only when stderr is a terminal, as tqdm does with
``disable=None``: logs, pipes and captured output get the results and nothing else.
"""
from __future__ import annotations

import contextlib
import sys

__all__ = ["stages", "shown"]


def shown(enabled: bool = True) -> bool:
    """True when progress is wanted (not ``--quiet``) and stderr is a terminal."""
    try:
        return bool(enabled) and sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


class _Stages:
    def __init__(self, command: str, names: list, enabled: bool):
        self.command, self.names, self.k = command, list(names), 0
        self.bar = None
        self.on = shown(enabled)
        if self.on:
            try:
                from tqdm import tqdm
            except ImportError:
                return
            self.bar = tqdm(total=len(self.names), desc=command, unit="stage", leave=False,
                            bar_format="{desc}: {n_fmt}/{total_fmt} stages |{bar}| {elapsed} {postfix}")

    def __call__(self, name: str) -> None:
        """Start stage ``name`` (the previous one is done)."""
        if not self.on:
            return
        if self.bar is not None:
            if self.k:
                self.bar.update(1)
            self.bar.set_postfix_str(name)
        else:
            print(f"{self.command}: {name} ...", file=sys.stderr, flush=True)
        self.k += 1

    def close(self) -> None:
        if self.bar is not None:
            self.bar.update(self.bar.total - self.bar.n)
            self.bar.close()


@contextlib.contextmanager
def stages(command: str, names: list, enabled: bool = True):
    """Context yielding ``stage(name)``, called as each stage starts."""
    s = _Stages(command, names, enabled)
    try:
        yield s
    finally:
        s.close()
