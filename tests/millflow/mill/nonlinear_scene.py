"""The breakage scene the non-linear mill tests share: 2^(1/4) classes from 1 cm, power-law
rates (30 / TAU at the top, alpha = 1) with a sink, normalized breakage, a feed in the
three coarsest classes."""
import numpy as np

from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.grid import SizeGrid

TAU = 600.0


def breakage_scene(n: int):
    """(grid, S [1/s], b, feed) on ``n`` classes."""
    grid = SizeGrid.geometric(1e-2, 2 ** 0.25, n)
    S = power_law_rates(grid.x, 30.0 / TAU, 1.0, grid.x[0])
    S[-1] = 0.0
    b = b_from_B(normalized_B(grid.x, 0.4, 0.8, 3.0))
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return grid, S, b, feed
