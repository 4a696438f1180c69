"""Checks and the shared scene of the Façade solver's tests."""

from __future__ import annotations

from pathlib import Path

import numpy as np

FIXTURE_BLOCKS = Path(__file__).resolve().parents[1] / "fixtures" / "facade" / "blocks.json"


def fixture_model():
    """The committed ``fixtures/facade/blocks.json`` model."""
    from lumigraph.stereo.debevec1996.model import load_blocks

    return load_blocks(FIXTURE_BLOCKS)


def fixture_cameras():
    """Six cameras on a ring 30 m out around the fixture model (700 px focal,
    5 % jitter, seeded): the solver tests' rig."""
    from lumigraph.capture.scenes.facade_edges import ring_cameras

    return ring_cameras(6, target=[1.5, 0, 4], radius=30, height=4, focal_px=700,
                        rng=np.random.default_rng(1), jitter=0.05)


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
