"""The model's exact Jacobians held to central differences of its right-hand side (shared by the
model tests, diagonal and full inertia)."""

from __future__ import annotations

import numpy as np

from quadctl.physics.model import build_model, evaluate

FD_STEP = 1e-6
"""Central differences: truncation ~ h^2 |f'''| ~ 1e-12, round-off ~ eps |f| / h ~ 1e-10 (scaled)."""
FD_RTOL = 1e-6


def assert_jacobians_match_central_differences(x, u, vehicle) -> tuple[np.ndarray, np.ndarray]:
    """Assert ``A = df/dx`` and ``B = df/du`` at ``(x, u)`` equal central differences of ``f`` to
    :data:`FD_RTOL` (relative to the larger of 1 and the matrix's largest entry); return ``(A, B)``."""
    a, b = (np.asarray(m) for m in build_model().jacobians(x, u, vehicle.vector()))
    a_fd = np.column_stack([(evaluate(x + FD_STEP * e, u, vehicle) - evaluate(x - FD_STEP * e, u, vehicle))
                            / (2 * FD_STEP) for e in np.eye(len(x))])
    b_fd = np.column_stack([(evaluate(x, u + FD_STEP * e, vehicle) - evaluate(x, u - FD_STEP * e, vehicle))
                            / (2 * FD_STEP) for e in np.eye(len(u))])
    for exact, approx, name in ((a, a_fd, "A"), (b, b_fd, "B")):
        err = np.abs(exact - approx).max() / max(1.0, np.abs(exact).max())
        assert err < FD_RTOL, f"{name}: max diff {err:.4E}"
    return a, b
