"""steady_population: the products of many mills at once equal steady_mill's, member by
member, for every transport: cell chains (compiled kernel and numpy), cell networks,
segregated flow through the eigenbasis, and the per-member paths."""
import numpy as np
import pytest
import rtd

from millflow.breakage import b_from_B, normalized_B, power_law_rates
from millflow.errors import InputError
from millflow.grid import SizeGrid
from millflow.mill import steady_mill
from millflow.mill.population import steady_population, tanks_in_series_population


def _members(p=6, n=40, seed=0):
    g = SizeGrid.geometric(1e-2, 2 ** 0.5, n)
    b = b_from_B(normalized_B(g.x, 0.4, 0.8, 3.0))
    rng = np.random.default_rng(seed)
    S = np.array([power_law_rates(g.x, a, al, g.x[0]) for a, al in zip(rng.uniform(0.005, 0.2, p),
                                                                     rng.uniform(0.5, 1.5, p))])
    S[:, -1] = 0.0
    feed = np.zeros(n)
    feed[:3] = [0.2, 0.5, 0.3]
    return S, b, feed


# Both sides are triangular solves of the same systems in a different order of
# operations: rounding only (products are O(1)).
ATOL = 1e-13


@pytest.mark.parametrize("transport", [rtd.PerfectMixing(60.0), rtd.TanksInSeries(60.0, 1),
                                       rtd.TanksInSeries(60.0, 4), rtd.TanksInSeries(90.0, 10),
                                       rtd.PlugFlow(30.0)])
def test_equals_steady_mill_member_by_member(transport):
    S, b, feed = _members()
    out = steady_population(S, b, feed, transport)
    for k in range(S.shape[0]):
        ref = steady_mill(S[k], b, feed, transport)["product"].values
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=ATOL)
    np.testing.assert_allclose(out.sum(axis=1), feed.sum(), rtol=0, atol=1e-13)  # mass balance


def test_classified_perfect_mixing_and_per_member_feeds():
    S, b, feed = _members(p=4)
    d = np.linspace(1.0, 3.0, S.shape[1])
    feeds = np.abs(np.random.default_rng(1).random(S.shape)) + feed
    out = steady_population(S, b, feeds, rtd.PerfectMixing(45.0), d)
    for k in range(4):
        ref = steady_mill(S[k], b, feeds[k], rtd.PerfectMixing(45.0), d)["product"].values
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=1e-12)


def test_many_tanks_approach_plug_flow():
    # n -> infinity: tanks in series tend to plug flow, error O(1/n)
    S, b, feed = _members(p=2)
    plug = steady_population(S, b, feed, rtd.PlugFlow(40.0))
    errs = [np.abs(tanks_in_series_population(S, b, feed, 40.0, n) - plug).max() for n in (50, 100, 200)]
    assert errs[0] > errs[1] > errs[2]
    assert errs[1] / errs[2] == pytest.approx(2.0, rel=0.1)  # first order in 1/n


def test_bad_shapes_one_line_errors():
    S, b, feed = _members(p=3)
    with pytest.raises(InputError, match="S has shape"):
        steady_population(S[0], b, feed, rtd.PerfectMixing(1.0))
    with pytest.raises(InputError, match="feed has shape"):
        steady_population(S, b, feed[:-1], rtd.PerfectMixing(1.0))
    with pytest.raises(InputError, match="rates >= 0"):
        steady_population(-S, b, feed, rtd.PerfectMixing(1.0))


@pytest.mark.parametrize("transport,classified,where", [
    (rtd.PerfectMixing(60.0), True, "cells"),
    (rtd.TanksInSeries(60.0, 3), True, None),  # a network with classification at the discharge
    (rtd.TanksInSeries(60.0, 3), True, "cells"),
    (rtd.TanksInSeries(60.0, 2.5), False, None),  # segregated flow
    (rtd.RecirculatingCells(60.0, 4, 1.0), False, None),
    (rtd.RecirculatingCells(60.0, 4, 1.0), True, "cells"),
    (rtd.PlugFlow(60.0), True, None),  # classification along the axis: rates S/d*
    (rtd.AxialDispersion(60.0, 8.0), False, None),
    (rtd.AxialDispersion(60.0, 8.0, bc="open"), False, None),
    (rtd.AxialDispersion(60.0, 8.0), True, None),  # finite volumes: member by member
    (rtd.Series(rtd.PerfectMixing(20.0), rtd.PlugFlow(40.0)), False, None),
    (rtd.Parallel(rtd.PerfectMixing(20.0), rtd.PlugFlow(40.0), weights=[0.3, 0.7]), False, None),
], ids=lambda v: repr(v)[:40] if not isinstance(v, (bool, str, type(None))) else str(v))
@pytest.mark.parametrize("kernel", ["compiled", "numpy"])
def test_every_transport_equals_steady_mill(transport, classified, where, kernel):
    from millflow import compiled

    if kernel == "compiled" and (compiled.kernel("cells") is None or compiled.kernel("eigenbasis") is None):
        pytest.skip("compiled kernels not built")
    S, b, feed = _members(p=5)
    g = SizeGrid.geometric(1e-2, 2 ** 0.5, S.shape[1])
    d = np.where(g.x > 2e-3, 0.4, 1.0) if classified else None
    out = steady_population(S, b, feed, transport, d, where=where, kernel=kernel)
    for k in range(S.shape[0]):
        ref = steady_mill(S[k], b, feed, transport, d, where=where)["product"].values
        # substitutions: rounding (~1e-15); the eigenbasis of segregated flow: its
        # cancellation estimate, below 1e-13 of the feed for every member it serves
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=1e-12)


def test_members_with_equal_rates_take_the_clustered_path():
    # two members with a pair of equal rates: the plain eigenbasis would divide by zero;
    # steady_mill's clustered eigenbasis solves them (exact), the others stay vectorised
    S, b, feed = _members(p=4)
    S[1, 5] = S[1, 6]
    S[3, 2:6] = S[3, 2]
    out = steady_population(S, b, feed, rtd.PlugFlow(50.0))
    for k in range(4):
        ref = steady_mill(S[k], b, feed, rtd.PlugFlow(50.0))["product"].values
        np.testing.assert_allclose(out[k], ref, rtol=0, atol=1e-12)
    assert np.all(np.isfinite(out))


def test_kernel_blocks_of_eight_and_a_remainder():
    # 1, 8, 9 and 19 members: full blocks and a padded last block give steady_mill's products
    for p in (1, 8, 9, 19):
        S, b, feed = _members(p=p, n=25, seed=p)
        out = tanks_in_series_population(S, b, feed, 90.0, 3)
        for k in range(p):
            ref = steady_mill(S[k], b, feed, rtd.TanksInSeries(90.0, 3))["product"].values
            np.testing.assert_allclose(out[k], ref, rtol=0, atol=ATOL)


def test_top_level_export():
    import millflow
    from millflow.mill import steady_population as from_mill

    assert millflow.steady_population is from_mill is steady_population
