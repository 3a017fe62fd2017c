"""The finite-difference Jacobian of the fit where a forward solve fails."""
import numpy as np


def test_jacobian_steps_to_the_solved_side_where_a_solve_fails():
    """A non-linear forward solve that fails on one side of a central difference (NaN there)
    gives that column by the first-order difference on the solved side: exact here, for a
    residual linear in theta (to rounding of h ~ 6e-6 steps: 1e-9 relative)."""
    from millflow.fitting.statistics import jacobian

    A = np.array([[1.0, 2.0], [3.0, -1.0], [0.5, 4.0]])

    def resid_pop(T):
        R = T @ A.T
        R[T[:, 0] > 1.0] = np.nan  # the model cannot be solved above theta_0 = 1
        return R

    J = jacobian(resid_pop, np.array([1.0, 0.3]), [-5.0, -5.0], [5.0, 5.0])
    np.testing.assert_allclose(J, A, rtol=1e-9)
    both = jacobian(lambda T: np.full((T.shape[0], 3), np.nan), np.array([1.0, 0.3]), [-5.0, -5.0], [5.0, 5.0])
    assert not np.isfinite(both).any()  # nothing solved: the caller sees it
