"""A fit's process columns read as quantities (tau, screen opening, ball size) take their
unit from their names: tau_min is minutes, screen_um micrometres; a name without a unit
is refused in one line naming the column."""
import numpy as np
import pandas as pd
import pytest

from millflow.errors import InputError
from millflow.fitting.models import ForwardModel, ModelSpec
from tests.millflow.fitting.test_fit_mill import GRID, _data

THETA = np.array([[-3.5, 1.0, 0.4, 0.8, 3.0, 0.0, 1.5]])
SECONDS = [60.0, 120.0, 240.0]
MM = [1.0, 2.0, 1.5]


def _model(tau_col, tau_factor, screen_col, screen_factor, cls="screen"):
    proc = pd.DataFrame({"condition": ["c1", "c2", "c3"], tau_col: np.array(SECONDS) / tau_factor,
                         screen_col: np.array(MM) / screen_factor})
    spec = ModelSpec(mode="well_mixed", classification=cls, tau_column=tau_col, screen_column=screen_col)
    return ForwardModel(spec, _data(["c1", "c2", "c3"], ["product"], proc), GRID)


@pytest.mark.parametrize("tau_col, tau_factor", [("tau_min", 60.0), ("tau_h", 3600.0), ("tau_s", 1.0)])
@pytest.mark.parametrize("screen_col, screen_factor", [("screen_um", 1e-3), ("screen_m", 1e3), ("screen_mm", 1.0)])
def test_the_same_conditions_in_any_unit_predict_the_same(tau_col, tau_factor, screen_col, screen_factor):
    # same physical conditions written in other units: the same prediction to rounding
    ref = _model("tau_s", 1.0, "screen_mm", 1.0).predict(THETA)
    got = _model(tau_col, tau_factor, screen_col, screen_factor).predict(THETA)
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_tau_in_minutes_is_not_read_as_seconds():
    # the bug: tau_min = 1, 2, 4 was taken as 1, 2, 4 s
    wrong = _model("tau_s", 60.0, "screen_mm", 1.0).predict(THETA)  # 1, 2, 4 s
    right = _model("tau_min", 60.0, "screen_mm", 1.0).predict(THETA)
    assert np.abs(wrong - right).max() > 1e-2


@pytest.mark.parametrize("tau_col, screen_col, match", [
    ("tau", "screen_mm", r"process column 'tau' \(tau_column\): its unit is not in its name"),
    ("residence_time", "screen_mm", r"'residence_time' \(tau_column\)"),
    ("tau_s", "screen", r"'screen' \(screen_column\)"),
    ("tau_s", "screen_inch", r"'screen_inch' \(screen_column\).*_um, _mm, _m"),
])
def test_a_column_without_a_unit_is_refused(tau_col, screen_col, match):
    with pytest.raises(InputError, match=match):
        _model(tau_col, 1.0, screen_col, 1.0)
