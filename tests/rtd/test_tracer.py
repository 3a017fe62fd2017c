"""Tracer data: CSV reading, refusal of bad data, baseline, moments with a tail, inlet."""
import math

import numpy as np
import pytest

import rtd


def write(tmp_path, text, name="tracer.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_read_csv_with_unit_in_time_column(tmp_path):
    path = write(tmp_path, "# comment line\ntime_min,concentration\n0,0\n1,2.5\n2,1.0\n3,0.2\n")
    curve = rtd.read_tracer_csv(path)
    assert curve.time_unit == "min" and curve.kind == "pulse" and curve.inlet is None
    np.testing.assert_array_equal(curve.t, [0, 1, 2, 3])
    np.testing.assert_array_equal(curve.c, [0, 2.5, 1.0, 0.2])


def test_read_step_response_and_inlet(tmp_path):
    step = rtd.read_tracer_csv(write(tmp_path, "time_s,F\n0,0\n1,0.5\n2,0.9\n3,1\n"))
    assert step.kind == "step" and step.time_unit == "s"
    pulse = rtd.read_tracer_csv(write(tmp_path, "time_h,concentration,inlet\n0,0,1\n1,1,0\n2,0.5,0\n",
                                      "b.csv"))
    np.testing.assert_array_equal(pulse.inlet, [1, 0, 0])


@pytest.mark.parametrize("text, match", [
    ("time_s,concentration\n0,1\n1,nan\n2,0.5\n3,0\n", r"concentration.*row 2"),
    ("time_s,concentration\n0,1\n2,2\n1,0.5\n3,0\n", r"time_s.*row 3.*decreasing"),
    ("time_s,concentration\n0,1\n1,2\n1,0.5\n3,0\n", r"row 3 is repeated"),
    ("time_s,concentration\n0,0\n1,0\n2,0\n3,0\n", r"all values are zero"),
    ("time_s,concentration\n0,0\n1,5\n2,-3\n3,0\n", r"row 3 is negative beyond the noise"),
    ("time_s,concentration\n0,1\n1,2\n", r"only 2 data rows"),
    ("t,concentration\n0,1\n1,2\n2,3\n", r"time_<unit>"),
    ("time_fortnights,concentration\n0,1\n1,2\n2,3\n", r"time unit"),
    ("time_s,conc\n0,1\n1,2\n2,3\n", r"no column 'concentration'"),
    ("time_s,concentration\n0,1\n1,abc\n2,3\n", r"'abc' at data row 2 is not a number"),
])
def test_bad_data_gives_clear_errors(tmp_path, text, match):
    path = write(tmp_path, text)
    with pytest.raises(rtd.TracerError, match=match) as err:
        rtd.read_tracer_csv(path)
    assert str(path) in str(err.value) and err.value.column is not None


def test_small_negative_values_within_noise_are_kept():
    t = np.linspace(0, 10, 101)
    c = np.exp(-t) + 0.01 * np.random.default_rng(0).standard_normal(t.size)
    t2, c2 = rtd.check_tracer(t, c)
    assert np.any(c2 < 0) and np.array_equal(c2, c)


def test_baseline_subtraction_is_stated():
    t = np.linspace(0, 10, 50)
    curve = rtd.TracerCurve(t, np.exp(-(t - 5) ** 2) + 0.3)
    out = rtd.subtract_baseline(curve, "head")
    assert out.c[0] == pytest.approx(0.0, abs=1e-6)
    assert "baseline 0.3" in out.notes[0] and "first 5 points" in out.notes[0]
    assert rtd.subtract_baseline(curve, 0.1).c[0] == pytest.approx(0.2, abs=1e-6)


def test_moments_of_complete_curve_match_model():
    m = rtd.TanksInSeries(2.0, 4)
    t = np.linspace(0, 20, 2001)
    mom = rtd.moments(t, 3.0 * m.pdf(t))
    assert mom.area == pytest.approx(3.0, rel=1e-6) and mom.tail_fraction == 0.0
    assert mom.mean == pytest.approx(2.0, rel=1e-5) and mom.variance == pytest.approx(1.0, rel=1e-4)


def test_exponential_tail_restores_moments_of_cut_curve():
    m = rtd.PerfectMixing(2.0)
    t = np.linspace(0, 5, 2001)  # cut at 2.5 tau: 8 % of the tracer is missing
    cut = rtd.moments(t, m.pdf(t), tail=False)
    full = rtd.moments(t, m.pdf(t))
    assert cut.area == pytest.approx(1 - math.exp(-2.5), rel=1e-5)
    assert full.area == pytest.approx(1.0, rel=1e-6) and full.mean == pytest.approx(2.0, rel=1e-5)
    assert full.variance == pytest.approx(4.0, rel=1e-4)
    assert full.tail_fraction == pytest.approx(math.exp(-2.5), rel=1e-4)
    assert "exponential tail" in full.note and "8.21 %" in full.note


def test_step_moments():
    m = rtd.TanksInSeries(3.0, 2)
    t = np.linspace(0, 40, 4001)
    mom = rtd.step_moments(t, 2.0 * m.cdf(t))
    assert mom.mean == pytest.approx(3.0, rel=1e-5) and mom.variance == pytest.approx(4.5, rel=1e-4)


def test_normalise_gives_unit_area():
    t = np.linspace(0, 30, 301)
    e = rtd.normalise(rtd.TracerCurve(t, 7.0 * rtd.PerfectMixing(3.0).pdf(t)))
    assert np.trapezoid(e.c, t) == pytest.approx(1.0, rel=1e-3) and "normalised" in e.notes[0]


def test_convolution_with_inlet():
    t = np.linspace(0, 20, 401)
    inlet = rtd.TanksInSeries(0.5, 2).pdf(t)  # a smeared injection
    model = rtd.PerfectMixing(3.0)
    out = rtd.convolve_inlet(model.cdf, t, inlet)
    ref = rtd.Series(rtd.TanksInSeries(0.5, 2), model).pdf(t)
    # piecewise-constant inlet: error O(h^2 c_in''), here < 0.5 % of the peak
    np.testing.assert_allclose(out, ref, atol=5e-3 * ref.max())
    fine = np.linspace(0, 20, 1601)
    err_fine = np.max(np.abs(rtd.convolve_inlet(model.cdf, fine, rtd.TanksInSeries(0.5, 2).pdf(fine))
                             - rtd.Series(rtd.TanksInSeries(0.5, 2), model).pdf(fine)))
    assert err_fine < np.max(np.abs(out - ref)) / 10  # second order: 4x finer, 16x smaller
    shifted = rtd.convolve_inlet(rtd.PlugFlow(2.0).cdf, t, inlet)  # plug flow: a delay
    np.testing.assert_allclose(shifted[t >= 4], np.interp(t[t >= 4] - 2.0, t, inlet),
                               atol=2e-2 * inlet.max())
