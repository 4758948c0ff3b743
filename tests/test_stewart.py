"""The 6-UPS Stewart platform (``mechanisms/stewart.toml``) against its closed-form
inverse kinematics and its textbook Jacobian.

Leg ``i`` joins the base point ``a_i`` to the platform point ``b_i`` (platform frame,
about the centre ``p``): its length is ``|p + R b_i - a_i|`` with
``R = Rot(x, roll) Rot(y, pitch) Rot(z, yaw)``, the convention of the orientation
outputs, and its motor value is that length minus the rest length. The forward
singularities are where the 6 x 6 matrix of the legs' unit line coordinates
``[u_iᵀ, (R b_i × u_i)ᵀ]`` is singular; turning the platform about z reaches one.
"""

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt

BASE = 100.0 * np.array(
    [[np.cos(t), np.sin(t), 0.0] for t in np.radians([-15, 15, 105, 135, 225, 255])]
)
TOP = 60.0 * np.array(
    [[np.cos(t), np.sin(t), 0.0] for t in np.radians([-45, 45, 75, 165, 195, 285])]
)
HOME = np.array([0.0, 0.0, 120.0])


def _rotation(roll, pitch, yaw):
    def about(k, a):
        c, s = np.cos(a), np.sin(a)
        i, j = [m for m in range(3) if m != k]
        r = np.eye(3)
        r[i, i], r[i, j], r[j, i], r[j, j] = c, -s, s, c
        return r if k != 1 else r.T  # Rot(y) has the sine signs swapped

    return about(0, roll) @ about(1, pitch) @ about(2, yaw)


def _legs(pose):
    """Leg vectors ``p + R b_i - a_i`` (6, 3) and ``R b_i`` for a pose (x, y, z, roll,
    pitch, yaw)."""
    turned = TOP @ _rotation(*pose[3:]).T
    return pose[:3] + turned - BASE, turned


def _extensions(pose):
    rest = np.linalg.norm(_legs(np.r_[HOME, 0, 0, 0])[0], axis=1)
    return np.linalg.norm(_legs(pose)[0], axis=1) - rest


def _textbook_sigma(pose):
    """σ_min of the unit line coordinates of the legs, moments in platform radii."""
    legs, turned = _legs(pose)
    u = legs / np.linalg.norm(legs, axis=1, keepdims=True)
    jac = np.hstack([u, np.cross(turned, u) / 60.0])
    return np.linalg.svd(jac, compute_uv=False)[-1], np.linalg.det(jac)


POSES = np.array(
    [
        [0.0, 0.0, 120.0, 0.0, 0.0, 0.0],
        [10.0, -10.0, 130.0, 0.1, -0.1, 0.1],
        [-8.0, 5.0, 112.0, -0.07, 0.09, -0.1],
        [4.0, 9.0, 126.0, 0.1, 0.1, -0.06],
    ]
)


@pytest.fixture(scope="module")
def stewart():
    return linkopt.load(MECHANISMS / "stewart.toml")


def test_rest_pose_and_rotation_convention():
    assert np.allclose(
        _rotation(0.3, 0, 0)[1:, 1:],
        [[np.cos(0.3), -np.sin(0.3)], [np.sin(0.3), np.cos(0.3)]],
    )
    assert np.isclose(_rotation(0, 0.3, 0)[0, 2], np.sin(0.3))


def test_bk_motor_values_are_the_closed_form_leg_extensions(stewart):
    back = linkopt.solve_bk(stewart, POSES)
    assert bool(np.all(back.converged))
    motors = np.asarray(linkopt.motor_values(stewart, back.state))
    expected = np.array([_extensions(p) for p in POSES])
    assert np.abs(motors - expected).max() < 1e-9
    forward = linkopt.solve_fk(stewart, expected)
    assert bool(np.all(forward.converged))
    pose = np.asarray(linkopt.output_values(stewart, forward.state))
    assert np.abs(pose - POSES).max() < 1e-9


def test_forward_singularity_where_the_leg_line_matrix_is_singular(stewart):
    low, high = 1.4, 1.7  # det of the line matrix changes sign between them
    for _ in range(60):
        mid = 0.5 * (low + high)
        if _textbook_sigma(np.r_[HOME, 0, 0, mid])[1] < 0:
            low = mid
        else:
            high = mid
    yaws = np.r_[np.linspace(0.0, 1.5, 7), low]
    path = np.column_stack(
        [np.tile(HOME, (yaws.size, 1)), np.zeros((yaws.size, 2)), yaws]
    )
    back = linkopt.solve_bk_path(stewart, path)
    assert bool(np.all(back.converged))
    fk, bk = np.asarray(linkopt.singular_values(stewart, back.state)).T
    textbook = np.array([_textbook_sigma(p)[0] for p in path])
    assert textbook[-1] < 1e-9 and fk[-1] < 1e-6
    assert np.all(np.diff(fk) < 0) and np.all(np.diff(textbook) < 0)
    ratio = fk[:-1] / textbook[:-1]
    assert ratio.max() / ratio.min() < 1.2  # measured 0.150-0.167
    assert bk.min() > 1e-2  # the pose always determines the legs


def test_default_verification_grid_fits_the_budget(stewart):
    """Six outputs: the default grid is the finest within the cell and memory limits
    (13 per output, as for three outputs, would be 4.8 million cells)."""
    from linkopt._design.maps import MAX_BYTES
    from linkopt._design.verify import check_resolution, default_resolution

    resolution = default_resolution(stewart)
    assert resolution == check_resolution(stewart) >= 3
    with pytest.raises(linkopt.InputError, match="memory|cells"):
        check_resolution(stewart, resolution + 1, max_bytes=MAX_BYTES)


@pytest.mark.slow
def test_wide_tilt_example_fails_at_its_tilted_corner(stewart):
    """``stewart_wide_tilt.toml`` (the README's Stewart optimisation) is stewart.toml
    with roll and pitch in [-0.5, 0.5]: its initial design fails verification, because
    at the corner x -10, y 10, z 110, roll 0.5, pitch 0.5, yaw 0.1 (a cell of every
    verification grid) f_sing exceeds α₋, the rest pose's f_sing times alpha_factor
    (the same rest pose, so the same α₋ as stewart.toml). With base radius 85 and
    platform radius 90 that corner is below α₋ (that design passes `linkopt.verify`
    at 3 points per output, max f_sing 25.5; the optimiser's design: README). Solved
    on stewart.toml, the same linkage, whose compiled path programs the test above
    has made (measured 311 s cold at a load of 12 on 2 cores)."""
    from linkopt._design.evaluation import alpha_minus

    wide = linkopt.load(MECHANISMS / "stewart_wide_tilt.toml")
    np.testing.assert_array_equal(
        wide.output_min, stewart.output_min * [1, 1, 1, 5, 5, 1]
    )
    np.testing.assert_array_equal(
        wide.output_max, stewart.output_max * [1, 1, 1, 5, 5, 1]
    )
    assert (
        wide.evaluation == stewart.evaluation
        and wide.design.names == stewart.design.names
    )
    threshold = alpha_minus(stewart)
    corner = np.array([-10.0, 10.0, 110.0, 0.5, 0.5, 0.1])
    path = np.r_[HOME, 0, 0, 0] + np.linspace(0.0, 1.0, 8)[:, None] * (
        corner - np.r_[HOME, 0, 0, 0]
    )
    initial = linkopt.solve_bk_path(stewart, path)
    wider = linkopt.solve_bk_path(stewart, path, design=[85.0, 90.0])
    assert bool(np.all(initial.converged)) and bool(np.all(wider.converged))
    f_initial = np.asarray(linkopt.f_sing(stewart, initial.state))[-1]
    f_wider = np.asarray(linkopt.f_sing(stewart, wider.state, design=[85.0, 90.0]))[-1]
    assert f_initial > 1.05 * threshold  # measured 33.6 against 30.5
    assert f_wider < 0.9 * threshold
    # the textbook line matrix agrees that the tilted corner is the ill-conditioned one
    assert _textbook_sigma(corner)[0] < 0.6 * _textbook_sigma(np.r_[HOME, 0, 0, 0])[0]
