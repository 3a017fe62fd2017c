"""The cases of a sweep: what is varied, over which values."""
from __future__ import annotations

import math
import re
from dataclasses import dataclass

import numpy as np

from millflow.errors import InputError

__all__ = ["Axis", "parse_vary", "grid_cases", "latin_hypercube_cases", "set_key"]

_VARY = re.compile(r"^\s*([A-Za-z_][\w.]*)\s*=\s*([^:]+):([^:]+):([^:]+)\s*$")


@dataclass(frozen=True)
class Axis:
    """A varied key of the flowsheet and its range.

    A varied key (dotted path into the flowsheet's tables) from ``start`` to ``stop``
    in ``n`` values (grid), or uniformly between them (Latin hypercube).
    """

    key: str
    start: float
    stop: float
    n: int

    @property
    def values(self) -> np.ndarray:
        """The grid's values of this key."""
        return np.linspace(self.start, self.stop, self.n)


def parse_vary(text: str) -> Axis:
    """The :class:`Axis` of a ``--vary KEY=START:STOP:N`` argument.

    Parameters
    ----------
    text : str
        ``KEY=START:STOP:N``: a dotted key of the flowsheet (its unit is the key's own,
        ``tau_min`` in minutes), two finite numbers and a whole number >= 1.

    Returns
    -------
    Axis

    Raises
    ------
    InputError
        Anything else, in one line naming the argument.

    Examples
    --------
    >>> ax = parse_vary("units.ball_mill.tau_min=2:6:5")
    >>> ax.key, ax.values.tolist()
    ('units.ball_mill.tau_min', [2.0, 3.0, 4.0, 5.0, 6.0])
    """
    m = _VARY.match(text)
    if not m:
        raise InputError(f"--vary {text!r}: expected KEY=START:STOP:N, e.g. units.ball_mill.tau_min=2:6:5")
    key, a, b, n = m.groups()
    try:
        start, stop = float(a), float(b)
    except ValueError:
        raise InputError(f"--vary {text!r}: START and STOP must be numbers") from None
    if not (math.isfinite(start) and math.isfinite(stop)):
        raise InputError(f"--vary {text!r}: START and STOP must be finite")
    if not re.fullmatch(r"\d+", n.strip()) or int(n) < 1:
        raise InputError(f"--vary {text!r}: N = {n.strip()!r}; expected a whole number >= 1")
    return Axis(key, start, stop, int(n))


def set_key(data: dict, key: str, value: float) -> None:
    """Set a numeric key of a flowsheet document by its dotted path.

    Set ``data[a][b][c] = value`` for key "a.b.c"; the path must exist (a misspelt key
    is refused, not added as a new setting).
    """
    parts = key.split(".")
    node = data
    for k, part in enumerate(parts[:-1]):
        if not isinstance(node, dict) or part not in node:
            raise InputError(f"--vary {key}: no table {'.'.join(parts[:k + 1])!r} in the flowsheet")
        node = node[part]
    if not isinstance(node, dict) or parts[-1] not in node:
        raise InputError(f"--vary {key}: the flowsheet has no key {key!r} to vary (write it in the file first)")
    old = node[parts[-1]]
    if isinstance(old, bool) or not isinstance(old, (int, float)):
        raise InputError(f"--vary {key}: its value {old!r} is not a number")
    node[parts[-1]] = float(value)


def grid_cases(axes: list[Axis]) -> list[dict]:
    """Every combination of the axes' values (the first key varies slowest).

    Examples
    --------
    >>> grid_cases([Axis("a", 1, 2, 2), Axis("b", 0, 10, 2)])
    [{'a': 1.0, 'b': 0.0}, {'a': 1.0, 'b': 10.0}, {'a': 2.0, 'b': 0.0}, {'a': 2.0, 'b': 10.0}]
    """
    grids = np.meshgrid(*[a.values for a in axes], indexing="ij")
    flat = [g.ravel() for g in grids]
    return [{a.key: float(f[i]) for a, f in zip(axes, flat)} for i in range(flat[0].size)]


def latin_hypercube_cases(axes: list[Axis], samples: int, seed: int = 0) -> list[dict]:
    """``samples`` cases, each key uniform on [start, stop], stratified (scipy's LHS).

    Each key's range is cut into ``samples`` equal strata and every stratum holds one case
    (McKay, Beckman and Conover, Technometrics 21 (1979) 239-245).

    Examples
    --------
    >>> cases = latin_hypercube_cases([Axis("a", 0, 1, 1)], samples=4, seed=0)
    >>> sorted(int(c["a"] * 4) for c in cases)  # one case in each quarter
    [0, 1, 2, 3]
    """
    from scipy.stats import qmc

    if samples < 1:
        raise InputError(f"--samples {samples}: expected a whole number >= 1")
    u = qmc.LatinHypercube(d=len(axes), seed=seed).random(samples)
    lo = np.array([a.start for a in axes])
    hi = np.array([a.stop for a in axes])
    x = lo + u * (hi - lo)
    return [{a.key: float(x[i, k]) for k, a in enumerate(axes)} for i in range(samples)]
