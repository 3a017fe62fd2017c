"""B from the t10 family: exact at the tabulated points, valid B, clear errors, config."""
import numpy as np
import pandas as pd
import pytest

from millflow.breakage import b_from_B, validate_b
from millflow.breakage.t10 import T10Breakage, T10Table, read_t10_table, t10_B
from millflow.errors import BreakageError, InputError
from millflow.grid import SizeGrid

NS = np.array([2.0, 4.0, 25.0, 50.0, 75.0])


def power_family(gammas):
    """Phi(r) = r^gamma: t_n = n^-gamma, t10 = 10^-gamma (an exact family to test against)."""
    g = np.asarray(gammas, dtype=float)
    return T10Table(10.0 ** -g, NS, NS[np.newaxis, :] ** -g[:, np.newaxis])


def test_exact_at_tabulated_points_and_power_law_tail():
    table = power_family([1.1, 0.9, 0.7, 0.5])  # t10 increasing
    grid = SizeGrid.geometric(1e-2, 2.0, 12)  # x_{i-1}/x_j = 2^-k: hits r = 1/2 and 1/4 exactly
    gamma = 0.7
    B = t10_B(grid, 10.0 ** -gamma, table)
    for j in range(3):
        np.testing.assert_allclose(B[j + 2, j], 0.5 ** gamma, rtol=1e-12)  # r = 1/2
        np.testing.assert_allclose(B[j + 3, j], 0.25 ** gamma, rtol=1e-12)  # r = 1/4
        # below r = 1/75 the power-law extension of a power law is exact
        np.testing.assert_allclose(B[j + 8, j], (2.0 ** -7) ** gamma, rtol=1e-12)
    # in between, PCHIP in ln r of a power law is close
    r = grid.x[0:11] / grid.x[0]
    np.testing.assert_allclose(B[1:, 0], r ** gamma, rtol=2e-2)


def test_b_is_a_valid_distribution_and_model_plugs_in():
    grid = SizeGrid.geometric(8e-3, 2 ** 0.25, 40)
    model = T10Breakage(0.25, power_family([1.2, 0.3]))
    b = model(grid.x)
    validate_b(b)
    np.testing.assert_allclose(b.sum(axis=0)[:-1], 1.0, atol=1e-12)
    np.testing.assert_allclose(b, b_from_B(model.B(grid.x)), atol=0)


def test_errors_name_what_is_wrong(tmp_path):
    table = power_family([1.0, 0.6])
    with pytest.raises(InputError, match="outside the table's range"):
        t10_B(SizeGrid.geometric(1e-2, 2.0, 6), 0.5, table)
    with pytest.raises(InputError, match="fraction"):
        T10Table([0.1, 0.2], NS, np.full((2, 5), 50.0))  # percent instead of fractions
    with pytest.raises(BreakageError, match="rise with n"):
        T10Table([0.1, 0.2], NS, np.array([[0.5, 0.3, 0.05, 0.2, 0.01]] * 2)).points(0.15)
    with pytest.raises(InputError, match="file not found"):
        read_t10_table(tmp_path / "missing.csv")
    pd.DataFrame({"t2": [0.5]}).to_csv(tmp_path / "no_t10.csv", index=False)
    with pytest.raises(InputError, match="no column 't10'"):
        read_t10_table(tmp_path / "no_t10.csv")


def test_read_table_and_fit_config(tmp_path):
    """A hybrid fit config with B from the t10 family builds b on the numerical grid."""
    from millflow.fitting.config import load_config

    table = power_family([1.0, 0.8, 0.6])
    df = pd.DataFrame({"t10": table.t10, **{f"t{int(n)}": table.tn[:, k] for k, n in enumerate(table.n)}})
    df.to_csv(tmp_path / "tn_t10.csv", index=False)
    read = read_t10_table(tmp_path / "tn_t10.csv")
    np.testing.assert_allclose(read.tn, table.tn)
    grid = SizeGrid.geometric(4e-3, 2 ** 0.5, 16)
    psd = pd.DataFrame({"condition": ["*", "*", "c1", "c1"], "location": ["feed", "feed", "product", "product"],
                        "size_m": [grid.x[0], grid.x[1], grid.x[0], grid.x[1]], "passing": [1.0, 0.0, 1.0, 0.5]})
    psd.to_csv(tmp_path / "psd.csv", index=False)
    pd.DataFrame({"condition": ["c1"], "tau_s": [60.0]}).to_csv(tmp_path / "process.csv", index=False)
    (tmp_path / "fit.toml").write_text(f"""
[data]
psd = "psd.csv"
process = "process.csv"
[grid]
ratio = {2 ** 0.5!r}
top_mm = 4.0
bottom_mm = {float(grid.x[-1]) * 1e3!r}
[model]
mode = "well_mixed"
tau_column = "tau_s"
t10_table_csv = "tn_t10.csv"
t10 = 0.125
""")
    cfg = load_config(tmp_path / "fit.toml")
    assert cfg.spec.breakage == "fixed" and cfg.spec.param_names == ("ln_A0", "alpha")
    np.testing.assert_allclose(cfg.spec.b_matrix, T10Breakage(0.125, table).b(grid.x), atol=1e-15)
