"""Closed forms of the Clavel delta of ``mechanisms/delta.toml`` and a generator of its
definition (any sizes, ball-ball or ball-universal rods) for the tests.

Geometry (mm, rad): motor ``i`` sits at ``B_i = R_b u_i`` on the base circle,
``u_i = (cos φ_i, sin φ_i, 0)`` with ``φ_i = 0°, 120°, 240°``, and turns its arm about
``t_i = z × u_i``; a positive motor value lowers the arm. With ``θ_i = θ₀ + a_i`` the
elbow is ``E_i = B_i + L_a (cos θ_i u_i - sin θ_i z)``. Each arm carries a
parallelogram of two rods of length ``L_r``, ``±w/2`` along ``t_i``, to the platform,
whose joints sit at ``p + R_p u_i ± (w/2) t_i`` (the parallelograms keep the platform
level), so the platform centre ``p`` lies on the three spheres of radius ``L_r`` about
``C_i = E_i - R_p u_i``: the lower of their two intersections.

Textbook Jacobian: differentiating ``|p - C_i|² = L_r²`` gives ``J_x ṗ = J_q θ̇``
with row ``i`` of ``J_x`` the rod vector ``s_i = p - C_i`` and
``J_q = diag(s_i · ∂E_i/∂θ_i)``;
``det J_x = 0`` (the three rods parallel to one plane) is the forward singularity,
``s_i · ∂E_i/∂θ_i = 0`` (rod and arm in line) the backward one.
"""

from __future__ import annotations

import numpy as np

SIZES = {"base": 60.0, "arm": 80.0, "rod": 180.0, "platform": 30.0, "spacing": 20.0}
REST_ANGLE = 0.0  # θ₀: arms horizontal at rest
PHI = np.radians([0.0, 120.0, 240.0])
Z = np.array([0.0, 0.0, 1.0])


def frames() -> tuple[np.ndarray, np.ndarray]:
    """Radial ``u_i`` and tangential ``t_i = z × u_i`` unit vectors, each ``(3, 3)``."""
    u = np.stack([np.cos(PHI), np.sin(PHI), np.zeros(3)], axis=1)
    return u, np.cross(Z, u)


def elbows(motors, sizes=SIZES, rest=REST_ANGLE) -> np.ndarray:
    """Elbow centres ``E_i`` ``(N, 3, 3)`` for motor values ``(N, 3)`` (rad)."""
    theta = rest + np.atleast_2d(motors)
    u, _ = frames()
    radial = np.cos(theta)[..., None] * u - np.sin(theta)[..., None] * Z
    return sizes["base"] * u + sizes["arm"] * radial


def elbow_rates(motors, sizes=SIZES, rest=REST_ANGLE) -> np.ndarray:
    """``∂E_i/∂θ_i``, ``(N, 3, 3)``."""
    theta = rest + np.atleast_2d(motors)
    u, _ = frames()
    return sizes["arm"] * (-np.sin(theta)[..., None] * u - np.cos(theta)[..., None] * Z)


def platform_centre(motors, sizes=SIZES, rest=REST_ANGLE) -> np.ndarray:
    """Closed-form FK: the lower intersection of the three spheres, ``(N, 3)``."""
    u, _ = frames()
    c = elbows(motors, sizes, rest) - sizes["platform"] * u
    e1 = c[:, 1] - c[:, 0]
    d = np.linalg.norm(e1, axis=1, keepdims=True)
    e1 = e1 / d
    a = c[:, 2] - c[:, 0]
    i = np.sum(e1 * a, axis=1, keepdims=True)
    e2 = a - i * e1
    j = np.linalg.norm(e2, axis=1, keepdims=True)
    e2 = e2 / j
    e3 = np.cross(e1, e2)
    e3 = np.where(e3[:, 2:3] > 0, -e3, e3)  # point down: the lower branch
    x = d / 2  # equal radii
    y = (i * i + j * j - 2 * i * x) / (2 * j)
    h = np.sqrt(sizes["rod"] ** 2 - x * x - y * y)
    return c[:, 0] + x * e1 + y * e2 + h * e3


def textbook_jacobians(motors, sizes=SIZES, rest=REST_ANGLE):
    """``(J_x (N, 3, 3), J_q diagonal (N, 3))`` at the closed-form pose."""
    u, _ = frames()
    p = platform_centre(motors, sizes, rest)
    s = p[:, None, :] - (elbows(motors, sizes, rest) - sizes["platform"] * u)
    return s, np.sum(s * elbow_rates(motors, sizes, rest), axis=2)


def definition(sizes=SIZES, rest=REST_ANGLE, elbow="spherical") -> dict:
    """The parsed TOML of a delta with ``elbow`` ("spherical" or "universal") joints at
    the arm end of every rod and ball joints at the platform end."""
    u, t = frames()
    e = elbows(np.zeros(3), sizes, rest)[0]
    p = platform_centre(np.zeros(3), sizes, rest)[0]
    half = sizes["spacing"] / 2
    arms = [f"arm{i + 1}" for i in range(3)]
    rods = [f"rod{i + 1}{side}" for i in range(3) for side in "ab"]
    joints = []
    for i in range(3):
        joints.append(
            _joint(
                f"shoulder{i + 1}", "revolute", "base", arms[i], sizes["base"] * u[i]
            )
            | {"axis": list(t[i])}
        )
    for i in range(3):
        for side, sign in (("a", 1.0), ("b", -1.0)):
            rod = f"rod{i + 1}{side}"
            joint = _joint(
                f"elbow{i + 1}{side}", elbow, arms[i], rod, e[i] + sign * half * t[i]
            )
            if elbow == "universal":
                direction = (p + sizes["platform"] * u[i] - e[i]) / sizes["rod"]
                second = np.cross(direction, t[i])
                joint |= {
                    "axis": list(t[i]),
                    "axis2": list(second / np.linalg.norm(second)),
                }
            joints.append(joint)
            wrist = p + sizes["platform"] * u[i] + sign * half * t[i]
            joints.append(
                _joint(f"wrist{i + 1}{side}", "spherical", rod, "platform", wrist)
            )
    return {
        "mechanism": {"name": "delta", "ground": "base", "units": "mm"},
        "bodies": [{"name": n} for n in ["base", *arms, *rods, "platform"]],
        "joints": joints,
        "motors": [
            {"name": f"m{i + 1}", "joint": f"shoulder{i + 1}"} for i in range(3)
        ],
        "points": [{"name": "tcp", "body": "platform", "position": list(p)}],
        "outputs": [
            {"name": c, "point": "tcp", "coordinate": c, "min": lo, "max": hi}
            for c, lo, hi in (
                ("x", -50.0, 50.0),
                ("y", -50.0, 50.0),
                ("z", -200.0, -140.0),
            )
        ],
    }


def _joint(name, kind, first, second, anchor) -> dict:
    return {
        "name": name,
        "type": kind,
        "bodies": [first, second],
        "anchor": [float(v) for v in anchor],
    }


def quat_axis_angle(axis, angle) -> np.ndarray:
    return np.concatenate([[np.cos(angle / 2)], np.sin(angle / 2) * np.asarray(axis)])


def quat_mul(a, b) -> np.ndarray:
    w1, v1, w2, v2 = a[0], a[1:], b[0], b[1:]
    return np.concatenate([[w1 * w2 - v1 @ v2], w1 * v2 + w2 * v1 + np.cross(v1, v2)])


def _rotate(q, v) -> np.ndarray:
    w, u = q[0], q[1:]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def _rod_quaternion(q_arm, d0, d, t, universal: bool) -> np.ndarray:
    """A rod's orientation taking its rest direction ``d0`` to ``d``: the swing alone
    (zero twist, the S-S gauge) or, for a universal joint with ``axis = t`` on the arm
    and ``axis2 = n2 = d0 × t`` on the rod, ``q_arm ⊗ Rot(t, α) ⊗ Rot(n2, β)``."""
    if not universal:
        q = np.concatenate([[1.0 + d0 @ d], np.cross(d0, d)])
        return q / np.linalg.norm(q)
    n2 = np.cross(d0, t)
    local = _rotate(q_arm * np.array([1.0, -1.0, -1.0, -1.0]), d)  # in the arm frame
    beta = np.arcsin(np.clip(local @ t, -1.0, 1.0))
    alpha = np.arctan2(-(local @ n2), local @ d0)
    return quat_mul(
        quat_mul(q_arm, quat_axis_angle(t, alpha)), quat_axis_angle(n2, beta)
    )


def exact_state(mech, motors, sizes=SIZES, rest=REST_ANGLE) -> np.ndarray:
    """The homogenised state ``(7B,)`` of a delta built by :func:`definition` at motor
    values ``(3,)``, from the closed forms (no solver)."""
    u, t = frames()
    motors = np.asarray(motors, dtype=float)
    e = elbows(motors, sizes, rest)[0]
    p = platform_centre(motors, sizes, rest)[0]
    p0 = platform_centre(np.zeros(3), sizes, rest)[0]
    name = {n: k for k, n in enumerate(mech.body_names)}
    joint = {n: k for k, n in enumerate(mech.joint_names)}
    origins = mech.body_origins
    poses = {"base": (np.array([1.0, 0, 0, 0]), origins[name["base"]])}
    poses["platform"] = (np.array([1.0, 0, 0, 0]), origins[name["platform"]] + p - p0)
    half = sizes["spacing"] / 2
    for i in range(3):
        q_arm = quat_axis_angle(t[i], motors[i])
        b = sizes["base"] * u[i]
        poses[f"arm{i + 1}"] = (
            q_arm,
            b + _rotate(q_arm, origins[name[f"arm{i + 1}"]] - b),
        )
        for side, sign in (("a", 1.0), ("b", -1.0)):
            k_e, k_w = joint[f"elbow{i + 1}{side}"], joint[f"wrist{i + 1}{side}"]
            d0 = mech.anchors[k_w] - mech.anchors[k_e]
            elbow = e[i] + sign * half * t[i]
            d = p + sizes["platform"] * u[i] + sign * half * t[i] - elbow
            universal = mech.joint_types[k_e] == "universal"
            q = _rod_quaternion(
                q_arm, d0 / np.linalg.norm(d0), d / np.linalg.norm(d), t[i], universal
            )
            rod = f"rod{i + 1}{side}"
            poses[rod] = (q, elbow + _rotate(q, origins[name[rod]] - mech.anchors[k_e]))
    state = np.zeros((mech.num_bodies, 7))
    for body, (q, x) in poses.items():
        state[name[body]] = np.concatenate([x / mech.length_scale, q])
    return state.ravel()


def arm_angles(p, sizes=SIZES, rest=REST_ANGLE) -> np.ndarray:
    """Closed-form BK: motor values ``(3,)`` putting the platform centre at ``p`` (the
    elbow-out branch of the rest pose)."""
    u, t = frames()
    angles = []
    for i in range(3):
        q = np.asarray(p, dtype=float) + (sizes["platform"] - sizes["base"]) * u[i]
        k = (sizes["arm"] ** 2 + q @ q - sizes["rod"] ** 2) / (2 * sizes["arm"])
        radius, delta = np.hypot(q @ u[i], q[2]), np.arctan2(q[2], q @ u[i])
        angles.append(-delta - np.arccos(k / radius) - rest)
    return np.array(angles)


def backward_singular_angle(sizes=SIZES, rest=REST_ANGLE) -> float:
    """Equal motor value at which arms and rods come in line (``J_q = 0``), found by
    bisection on the symmetric path below the rest pose, between 80° and 120° of arm
    angle."""
    low, high = np.radians(80.0) - rest, np.radians(120.0) - rest

    def alignment(a):
        return textbook_jacobians(np.full(3, a), sizes, rest)[1][0, 0]

    assert alignment(low) * alignment(high) < 0
    for _ in range(80):
        middle = 0.5 * (low + high)
        if alignment(low) * alignment(middle) <= 0:
            high = middle
        else:
            low = middle
    return 0.5 * (low + high)
