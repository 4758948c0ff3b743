"""URDF export round trip through yourdfpy (issue 18): at random joint values, every
link frame and the tool frame of the loaded URDF sit where linkopt's FK puts them
(1e-9 m, 1e-9 in the rotation), on the 3R arm file, an RPR arm from a DH table (a
prismatic joint, skew axes, no units), the files `arm design` and `arm trace` write,
and the 3R arm at another design; a closed-loop
file is refused with one line pointing to MJCF."""

import functools
from pathlib import Path

import numpy as np
import pytest
import yourdfpy

import linkopt
from linkopt._export import urdf

ROOT = Path(__file__).resolve().parent.parent


@functools.cache
def _arm_3r():
    return linkopt.load(ROOT / "tests" / "data" / "arm_3r.toml")


def _dh_arm():
    table = linkopt.arms.dh.DHTable(
        a=np.array([0.3, 0.0, 0.2]),
        alpha=np.array([1.2, -0.5, 0.0]),
        offset=np.array([0.1, 0.4, 0.05]),
    )
    mech, _ = linkopt.arms.dh.to_mechanism("RPR", table, np.array([0.2, 0.3, -0.4]))
    return mech


def _arm_design_file():
    """The mechanism file `linkopt arm design` writes (design.toml), for the tiny
    co-design arm at a design inside its bounds."""
    from arm_tasks import TINY_ARM

    from linkopt._arms.codesign.model import mechanism_definition
    from linkopt._arms.codesign.task import loads_task
    from linkopt._files.writer import dumps

    target = "[[targets]]\nposition = [0.0, 0.0, 0.0]\n"
    arm = loads_task(TINY_ARM + target, "tiny.toml").arm
    design = 0.5 * (arm.lower + arm.upper)
    return linkopt.loads(dumps(mechanism_definition(arm, design)), "design.toml")


def _arm_trace_file():
    """The mechanism file `linkopt arm trace` writes (arm.toml), for a 3-link planar
    arm."""
    from linkopt._arms.trace.export import mechanism_text
    from linkopt._arms.trace.synthesis import TraceResult
    from linkopt._arms.trace.task import loads_task
    from linkopt._arms.trace.verify import PlanarArm

    task = loads_task(
        '[task]\nname = "t"\nlink_diameter = 0.02\n[[primitives]]\ntype = "line"\n'
        "start = [0.3, -0.1]\nend = [0.3, 0.1]\n",
        "t.toml",
    )
    design = PlanarArm(np.array([0.02, -0.01]), np.array([0.2, 0.15, 0.1]), [0.3], 1)
    result = TraceResult(task, design, None, "app", 0.0)
    return linkopt.loads(mechanism_text(result), "arm.toml")


def _round_trip(mech, tmp_path, design=None, samples=6):
    path = tmp_path / "arm.urdf"
    summary = urdf.export_urdf(mech, path, design)
    robot = yourdfpy.URDF.load(
        str(path), load_meshes=False, build_collision_scene_graph=False
    )
    assert robot.base_link == mech.body_names[mech.ground]
    s = summary["metres_per_unit"]
    rng = np.random.default_rng(7)
    worst_pose, worst_value = 0.0, 0.0
    for motors in rng.uniform(-0.6, 0.6, (samples, mech.num_motors)):
        motors = motors * mech.motor_scale
        sol = linkopt.solve_fk(mech, motors, design=design)
        assert bool(sol.converged)
        values = urdf.urdf_joint_values(mech, sol.state, design)
        worst_value = max(
            worst_value,
            np.abs(
                [values[n] for n in robot.actuated_joint_names]
                - motors * np.where(mech.motor_linear, s, 1.0)
            ).max(),
        )
        robot.update_cfg(values)
        for link, pose in urdf.link_poses(mech, sol.state, design).items():
            found = robot.get_transform(frame_to=link, frame_from=robot.base_link)
            worst_pose = max(worst_pose, float(np.abs(found - pose).max()))
    return worst_pose, worst_value, robot


@pytest.mark.parametrize("which", ["arm_3r", "dh_rpr", "arm_design", "arm_trace"])
def test_urdf_forward_kinematics_match(which, tmp_path):
    mech = {
        "arm_3r": _arm_3r,
        "dh_rpr": _dh_arm,
        "arm_design": _arm_design_file,
        "arm_trace": _arm_trace_file,
    }[which]()
    pose_error, value_error, robot = _round_trip(mech, tmp_path)
    assert pose_error < 1e-9
    assert value_error < 1e-9  # the URDF joints are the motors
    assert set(robot.link_map) >= set(mech.body_names) | set(mech.point_names)


def test_urdf_of_another_design(tmp_path):
    mech = _arm_3r()
    design = mech.design.upper.copy()  # elbow_z = 50 mm instead of 40
    pose_error, _, robot = _round_trip(mech, tmp_path, design, samples=3)
    assert pose_error < 1e-9
    elbow = robot.joint_map["elbow"]
    assert elbow.origin[2, 3] == pytest.approx((50.0 - 10.0) * 1e-3, abs=1e-15)


def test_revolute_limits_from_angle_outputs():
    text = """
[mechanism]
name = "pendulum"
ground = "g"
units = "m"
reference_length = 1.0
[[bodies]]
name = "g"
[[bodies]]
name = "arm"
[[joints]]
name = "hinge"
type = "revolute"
bodies = ["g", "arm"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[motors]]
name = "hinge"
joint = "hinge"
[[points]]
name = "tip"
body = "arm"
position = [1.0, 0.0, 0.0]
[[outputs]]
name = "angle"
joint = "hinge"
min = -0.5
max = 1.25
"""
    mech = linkopt.loads(text, "pendulum.toml")
    document, _ = urdf.urdf_text(mech)
    assert '<joint name="hinge" type="revolute">' in document
    assert 'lower="-0.5" upper="1.25"' in document


def test_closed_loop_is_refused(five_bar):
    with pytest.raises(
        linkopt.InputError, match=r"closed loops .*tip.*as MJCF, which holds loops"
    ):
        urdf.urdf_text(five_bar)
