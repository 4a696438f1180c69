"""Checks shared by the Façade solver's tests."""

from __future__ import annotations

import numpy as np


def assert_jacobian_matches_differences(prob, x: np.ndarray, A) -> np.ndarray:
    """Assert the solver problem's analytic Jacobian at ``x`` equals central
    differences of its residuals; return the analytic one (dense)."""
    J = prob.jacobian(x, A, dense=True)
    Jn = np.zeros_like(J)
    for i in range(len(x)):
        e = np.zeros_like(x)
        e[i] = 1e-6 * max(1.0, abs(x[i]))
        Jn[:, i] = (prob.residuals(x + e, A) - prob.residuals(x - e, A)) / (2 * e[i])
    # central differences: error ~ h² f''' ≪ 1e-5 of the largest entry
    assert np.abs(J - Jn).max() < 1e-5 * np.abs(J).max()
    return J
