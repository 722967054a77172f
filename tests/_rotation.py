"""R_b^E from 3-2-1 Euler angles, built in NumPy as the three turns of docs/model.md (yaw, then pitch, then
roll): an independent reference for the model's CasADi rotation."""

from __future__ import annotations

import numpy as np


def body_to_earth(phi: float, theta: float, psi: float) -> np.ndarray:
    """R_b^E = Rz(psi) Ry(theta) Rx(phi) (3 x 3): a body vector in the NED earth frame."""
    def rx(a):
        return np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])

    def ry(a):
        return np.array([[np.cos(a), 0, np.sin(a)], [0, 1, 0], [-np.sin(a), 0, np.cos(a)]])

    def rz(a):
        return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])

    return rz(psi) @ ry(theta) @ rx(phi)
