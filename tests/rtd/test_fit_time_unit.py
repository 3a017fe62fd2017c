"""A fitted RTD keeps its time unit (issue 14 §2): a fit of minutes data says so and gives
its model in seconds for millflow; millflow refuses the fit result itself."""
import numpy as np
import pytest

import rtd
from rtd.tracer import read_tracer_csv


def _curve(tmp_path, unit):
    t = np.linspace(0, 40, 81)
    c = rtd.TanksInSeries(6.0, 3.0).pdf(t)
    p = tmp_path / "tracer.csv"
    p.write_text(f"time_{unit},concentration\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, c)))
    return read_tracer_csv(p)


def test_fit_of_minutes_data_converts_to_seconds(tmp_path):
    res = rtd.fit("tis", _curve(tmp_path, "min"))
    assert res.time_unit == "min" and res.to_dict()["time_unit"] == "min"
    m = res.model_in_seconds()
    assert m.tau == pytest.approx(res.model.tau * 60, rel=1e-15) and m.n == res.model.n
    assert res.model.tau == pytest.approx(6.0, rel=1e-6)  # noise-free data: the fit is exact to its tolerance


def test_fit_of_bare_arrays_has_no_unit():
    t = np.linspace(0, 40, 81)
    res = rtd.fit("tis", t, rtd.TanksInSeries(6.0, 3.0).pdf(t))
    with pytest.raises(rtd.RTDError, match="no unit"):
        res.model_in_seconds()
