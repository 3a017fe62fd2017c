"""The one table of transport names (rtd.names): canonical names, aliases, errors."""
import pytest

import rtd
from rtd.names import ALIASES, TRANSPORTS


def test_every_alias_names_a_canonical_model():
    assert set(ALIASES.values()) <= set(TRANSPORTS)
    for alias, name in ALIASES.items():
        assert rtd.canonical_name(alias) == name
        assert rtd.MODELS[alias] == rtd.MODELS[name]  # rtd.fit takes both


@pytest.mark.parametrize("name, params, expected", [
    ("perfect_mixing", {}, rtd.PerfectMixing(5.0)),
    ("tis", {"n": 3}, rtd.TanksInSeries(5.0, 3)),
    ("RecirculatingCells", {"n": 4, "r": 1.5}, rtd.RecirculatingCells(5.0, 4, 1.5)),
    ("axial_dispersion", {"pe": 8.0}, rtd.AxialDispersion(5.0, 8.0)),
    ("ad-open", {"pe": 8.0}, rtd.AxialDispersion(5.0, 8.0, bc="open")),
    ("plug", {}, rtd.PlugFlow(5.0)),
])
def test_build_by_any_spelling(name, params, expected):
    assert rtd.build_transport(name, 5.0, **params) == expected


def test_unknown_name_and_parameters_are_named():
    with pytest.raises(rtd.RTDError, match="'gamma' unknown; expected one of perfect_mixing"):
        rtd.canonical_name("gamma")
    with pytest.raises(rtd.RTDError, match="missing n"):
        rtd.build_transport("tanks_in_series", 5.0)
    with pytest.raises(rtd.RTDError, match="unknown pe"):
        rtd.build_transport("tanks_in_series", 5.0, n=3, pe=2.0)
