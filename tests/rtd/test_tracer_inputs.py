"""Issue 10 §4-5: tracer files in other encodings, extreme scales, constant curves and
times before the injection get one named error or the same answer as a plain file."""
import codecs

import numpy as np
import pytest

import rtd

T = np.linspace(0.0, 60.0, 61)
C = T * np.exp(-T / 10.0)  # TanksInSeries(tau = 20, n = 2) up to its area, exact values


def _csv(path, c, t=T, prefix=b""):
    text = "time_min,concentration\n" + "".join(f"{float(a)!r},{float(b)!r}\n" for a, b in zip(t, c))
    path.write_bytes(prefix + text.encode("utf-8"))
    return path


@pytest.mark.parametrize("scale", [1e-90, 1e-8, 1.0, 1e8, 1e90])
def test_fit_is_scale_free(tmp_path, scale):
    res = rtd.fit("tis", rtd.read_tracer_csv(_csv(tmp_path / "c.csv", scale * C)))
    # exact data: tau and n to the optimiser's tolerance (xtol 1e-10), whatever the unit
    assert res.params["tau"][0] == pytest.approx(20.0, rel=1e-8)
    assert res.params["n"][0] == pytest.approx(2.0, rel=1e-8)
    # E(t) of TanksInSeries(20, 2) is 0.01 t e^(-t/10), so C = 100 E: the area A is 100 x scale
    assert res.scale == pytest.approx(scale * 100.0, rel=1e-8)
    assert np.allclose(res.fitted, scale * C, rtol=0, atol=1e-8 * scale * C.max())


def test_byte_order_mark_is_read_as_utf8(tmp_path):
    a = rtd.read_tracer_csv(_csv(tmp_path / "a.csv", C))
    b = rtd.read_tracer_csv(_csv(tmp_path / "b.csv", C, prefix=codecs.BOM_UTF8))
    assert np.array_equal(a.c, b.c) and np.array_equal(a.t, b.t)


@pytest.mark.parametrize("raw, match", [
    ("time_min,concentration\n0,0\n".encode("utf-16"), "UTF-16"),
    (b"time_min,concentration\n# caf\xe9\n0,0\n1,1\n2,0\n", r"byte 28 \(line 2\) is not UTF-8"),
])
def test_other_encodings_are_named(tmp_path, raw, match):
    p = tmp_path / "t.csv"
    p.write_bytes(raw)
    with pytest.raises(rtd.TracerError, match=match):
        rtd.read_tracer_csv(p)


@pytest.mark.parametrize("c, t, match", [
    (np.ones_like(T), T, "all values are equal"),
    (C, T - 10.0, "before the injection"),
    (1e300 * C / C.max(), T, "expected a peak between"),
])
def test_curves_no_model_can_fit_are_refused(tmp_path, c, t, match):
    with pytest.raises(rtd.TracerError, match=match):
        rtd.read_tracer_csv(_csv(tmp_path / "t.csv", c, t))


def test_a_curve_no_model_fits_is_flagged(tmp_path):
    """Issue 10 §5: a bimodal curve fitted by one tanks-in-series model (R^2 ~0.6) was a
    normal result; now the fit carries a lack-of-fit flag with its reasons."""
    t = np.linspace(0.0, 80.0, 81)
    c = rtd.TanksInSeries(10.0, 4).pdf(t) + 0.8 * rtd.TanksInSeries(45.0, 12).pdf(t)
    res = rtd.fit("tis", t, c)
    lof = res.lack_of_fit
    assert lof["flag"] and any("runs test" in r for r in lof["reasons"])
    assert res.to_dict()["lack_of_fit"]["flag"] is True and "lack of fit" in res.summary()
    good = rtd.fit("tis", rtd.read_tracer_csv(_csv(tmp_path / "c.csv", C)))
    assert not good.lack_of_fit["flag"]


def test_rtd_arrays_beyond_the_memory_budget_are_refused():
    """RecirculatingCells(1, 1000, 1).pdf at 20001 times asked for 149 GiB; a chain is now
    inverted from its transform (tests/rtd/test_chain_inversion.py) and needs megabytes.
    A network that is not a chain and whose eigenvectors are ill-conditioned still takes
    one expm per time: refused before allocating, with the size it would need."""
    t = np.linspace(0.0, 5.0, 20001)
    e = rtd.RecirculatingCells(1.0, 1000, 1.0).pdf(t)
    assert np.all(np.isfinite(e)) and abs(e.sum() * (t[1] - t[0]) - 1.0) < 1e-6  # trapezoid on a smooth E
    from rtd.compartments import CompartmentNetwork

    n = 1000
    flows = np.zeros((n, n))
    flows[np.arange(1, n), np.arange(n - 1)] = 1.0  # a plug-like chain ...
    flows[2, 0] += 0.01  # ... with an exchange between cells 1 and 3: not tridiagonal
    flows[0, 2] += 0.01
    inlet, outlet = np.eye(n)[0], np.eye(n)[-1]
    net = CompartmentNetwork(np.full(n, 1.0 / n), flows, inlet, outlet)
    with pytest.raises(rtd.ParameterError, match=r"1000 cells at 20001 times .* 149 GiB"):
        net.pdf(t)
    with pytest.raises(rtd.ParameterError, match="RTD_MEMORY_BUDGET_GB"):
        rtd.TanksInSeries(600.0, 1e9).network()


@pytest.mark.parametrize("header, match", [
    ("time_min,concentration,F", "both 'concentration' and 'F'"),
    ("time_min,Concentration", r"no column 'concentration'.*\('Concentration' is not 'concentration'"),
    ("time_min,concentration,Inlet", r"unknown column \['Inlet'\] \('Inlet' is not 'inlet'"),
    ("time_min,concentration,temperature", r"unknown column \['temperature'\]"),
    ("time_min,f", r"'f' is not 'F'"),
])
def test_ambiguous_and_unknown_columns_are_named(tmp_path, header, match):
    # both columns: F was used silently (then "tau = -4.9e6"); 'Concentration' was ignored
    n = header.count(",") + 1
    rows = "".join(",".join([repr(float(t))] + [repr(float(c))] * (n - 1)) + "\n" for t, c in zip(T, C))
    path = tmp_path / "c.csv"
    path.write_text(header + "\n" + rows)
    with pytest.raises(rtd.TracerError, match=match):
        rtd.read_tracer_csv(path)

