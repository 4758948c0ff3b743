"""Closed-form kinematics of the shipped planar five-bar, written independently of
linkopt.

Geometry is read from the file's rest anchors; branches are those of the rest pose
(tip to the left of the elbow-to-elbow vector, each elbow on the rest side of its
base-to-tip line).
"""

import numpy as np

B_L, B_R = np.array([-20.0, 0.0]), np.array([20.0, 0.0])
E_L0, E_R0 = np.array([-37.0, 36.0]), np.array([37.0, 36.0])
T0 = np.array([0.0, 70.0])
L1 = float(np.linalg.norm(E_R0 - B_R))  # crank
L2 = float(np.linalg.norm(T0 - E_R0))  # distal link
PHI_L0 = float(np.arctan2(*(E_L0 - B_L)[::-1]))
PHI_R0 = float(np.arctan2(*(E_R0 - B_R)[::-1]))


def cross(u, v):
    return u[..., 0] * v[..., 1] - u[..., 1] * v[..., 0]


def circles(c0, r0, c1, r1, side):
    """Intersection of two circles; ``side=+1`` is left of the vector c0 -> c1."""
    d = c1 - c0
    dist = np.linalg.norm(d, axis=-1, keepdims=True)
    a = (r0**2 - r1**2 + dist**2) / (2 * dist)
    h = np.sqrt(np.maximum(r0**2 - a**2, 0.0))
    perp = np.stack([-d[..., 1], d[..., 0]], axis=-1) / dist
    return c0 + a * d / dist + side * h * perp


def elbows(motors):
    motors = np.atleast_2d(motors)
    e_l = B_L + L1 * np.stack(
        [np.cos(PHI_L0 + motors[:, 0]), np.sin(PHI_L0 + motors[:, 0])], -1
    )
    e_r = B_R + L1 * np.stack(
        [np.cos(PHI_R0 + motors[:, 1]), np.sin(PHI_R0 + motors[:, 1])], -1
    )
    return e_l, e_r


def forward(motors):
    """Tip position (N, 2) for motors (N, 2); NaN where the distal links cannot meet."""
    e_l, e_r = elbows(motors)
    gap = np.linalg.norm(e_r - e_l, axis=-1)
    tip = circles(e_l, L2, e_r, L2, side=+1.0)
    return np.where((gap < 2 * L2)[:, None], tip, np.nan)


def inverse(tips):
    """Motors (N, 2) reaching tips (N, 2) on the rest branch."""
    tips = np.atleast_2d(tips)
    side_l = np.sign(cross(T0 - B_L, E_L0 - B_L))
    side_r = np.sign(cross(T0 - B_R, E_R0 - B_R))
    e_l = circles(B_L, L1, tips, L2, side_l)
    e_r = circles(B_R, L1, tips, L2, side_r)
    a_l = np.arctan2(*(e_l - B_L).T[::-1]) - PHI_L0
    a_r = np.arctan2(*(e_r - B_R).T[::-1]) - PHI_R0
    return np.angle(np.exp(1j * np.stack([a_l, a_r], -1)))


def forward_singular_height():
    """Tip height on the symmetry axis where the distal links become collinear."""
    return float(np.sqrt(L1**2 - (L2 - B_R[0]) ** 2))


def backward_singular_height():
    """Tip height on the symmetry axis where crank and distal link are stretched out."""
    return float(np.sqrt((L1 + L2) ** 2 - B_R[0] ** 2))
