"""The compiled class-by-class circuit solve (millflow/_cells.c) against its numpy loop."""
import tomllib

import numpy as np
import pytest

from millflow import compiled
from millflow.synthetic import CLOSED_CIRCUIT_TOML, closed_circuit_case
from millflow.flowsheet import from_dict
from millflow.flowsheet.structured import cell_circuit, structured_solve

needs_kernel = pytest.mark.skipif(compiled.kernel("cells") is None, reason="compiled cells kernel not built")


def _two_mills(n_classes=40):
    data = tomllib.loads(CLOSED_CIRCUIT_TOML)
    data["grid"] = {"top_um": 8000, "bottom_um": 2, "n": n_classes}
    data["units"]["ball_mill"]["transport"] = {"model": "tanks_in_series", "n": 4}
    data["units"]["regrind"] = {"type": "mill", "material": "ore", "tau_min": 1.5,
                                "transport": {"model": "perfect_mixing"}}
    data["streams"]["overflow"] = {"from": "cyclones.overflow", "to": "regrind"}
    data["streams"]["final"] = {"from": "regrind", "to": "overflow_product"}
    return from_dict(data)


@needs_kernel
@pytest.mark.parametrize("make", [lambda: closed_circuit_case(100, 10), lambda: closed_circuit_case(7, 1), _two_mills])
def test_compiled_equals_numpy(make):
    fs = make()
    circuit = cell_circuit(fs)[0]
    x_c, res_c, amp_c = circuit.solve(kernel="compiled")
    x_n, res_n, amp_n = circuit.solve(kernel="numpy")
    # the same recurrence summed in another order: rounding of flows up to ~100 kg/s
    np.testing.assert_allclose(x_c, x_n, rtol=0, atol=1e-13 * x_n.max())
    assert amp_c == pytest.approx(amp_n, rel=1e-12)  # 1 / the same smallest pivot
    assert res_c < 1e-13 and res_n < 1e-13
    # the column-sum error estimate: numpy's trtrs and the kernel differ by rounding only
    from millflow.flowsheet.structured import _column_sum_error

    for _, M, n, *_ in circuit.chains:
        assert abs(_column_sum_error(M, n, compiled.kernel("cells")) - _column_sum_error(M, n, None)) < 1e-14


@needs_kernel
def test_loop_amplification_is_one_over_one_minus_the_loop_gain():
    # one recycle loop: the smallest LU pivot of I - G_k is 1 - (loop gain of class k)
    fs = closed_circuit_case(30, 3)
    circuit = cell_circuit(fs)[0]
    names = fs.stream_names
    G = circuit.G
    o_mill, o_cyc = names.index("mill_discharge"), names.index("underflow")
    gain = G[:, names.index("mill_feed"), o_cyc] * G[:, o_mill, names.index("mill_feed")] * G[:, o_cyc, o_mill]
    _, _, amp = circuit.solve(kernel="compiled")
    assert amp == pytest.approx(1.0 / (1.0 - gain.max()), rel=1e-12)


@needs_kernel
@pytest.mark.parametrize("kernel", ["compiled", "numpy"])
def test_trapped_size_returns_none_for_the_sparse_path(kernel):
    # a cyclone that returns everything coarse to the mill while the mill does not break
    # the top class: that class circulates for ever (loop gain 1), both solvers decline
    fs = closed_circuit_case(20, 2)
    circuit = cell_circuit(fs)[0]
    names = fs.stream_names
    circuit.G[0, names.index("mill_feed"), names.index("underflow")] = 1.0
    circuit.G[0, names.index("mill_discharge"), names.index("mill_feed")] = 1.0
    circuit.G[0, names.index("underflow"), names.index("mill_discharge")] = 1.0
    trapped = type(circuit)(circuit.N, circuit.G, circuit.Gd, circuit.src, circuit.chains)
    assert trapped.solve(kernel=kernel) is None


def test_structured_solve_reports_the_mills_error_estimate_and_residual():
    fs = closed_circuit_case(50, 5)
    x, info, blocks, infos = structured_solve(fs)
    assert info["relative_residual"] < 1e-13
    assert 0 <= infos["ball_mill"]["error_estimate"] < 1e-12
    # the estimate is the dense transfer matrix's column-sum defect, to rounding
    P = blocks["ball_mill"]["out"]
    assert abs(infos["ball_mill"]["error_estimate"] - np.max(np.abs(P.sum(axis=0) - 1))) < 1e-13
