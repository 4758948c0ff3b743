"""Motor limits (issue 44): ``[[motors]]`` ``min``/``max`` are read and checked at load,
keep the IK and adversarial samples within them, fail ``verify`` where the target range
needs a motor beyond them, and travel into ``check``, the written file, the maps and
the MJCF and URDF exports. A file without limits is computed as before."""

import dataclasses
import functools
import json
import math
from types import SimpleNamespace

import matplotlib
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._cli.main import main
from linkopt._design.evaluation import targets
from linkopt._design.motor_box import motor_box
from linkopt._engine.lifting import numbers, padded
from linkopt._engine.model import digest, fingerprint
from linkopt._engine.structure import structure
from linkopt._export import mjcf, urdf
from linkopt._files.writer import write_design

matplotlib.use("Agg")

SLIDER = (MECHANISMS / "slider_crank_linear.toml").read_text()
MOTOR = '[[motors]]\nname = "slide"\njoint = "slide"\n'


def slider(limits: str, source: str = "slider.toml") -> linkopt.Mechanism:
    """``slider_crank_linear.toml`` (a linear motor, mm) with ``limits`` added to its
    motor."""
    assert MOTOR in SLIDER
    return linkopt.loads(SLIDER.replace(MOTOR, MOTOR + limits), source)


@functools.cache
def tight() -> linkopt.Mechanism:
    """A stroke of -3..2 mm where the crank range needs about -13.6..15.1 mm."""
    return slider("min = -3.0\nmax = 2.0\n", "tight.toml")


@pytest.mark.parametrize(
    "limits, field, words",
    [
        ("min = 2.0\nmax = 1.0\n", "motors[0].min", "rest value 0 must lie"),
        ("min = -1.0\nmax = -0.5\n", "motors[0].max", "rest value 0 must lie"),
        ("min = 0.0\nmax = 0.0\n", "motors[0].min", "min < max"),
        ("min = nan\n", "motors[0].min", "finite number"),
        ("max = inf\n", "motors[0].max", "finite number"),
        ('max = "10"\n', "motors[0].max", "finite number"),
        ("min = -1e9\n", "motors[0].min", "magnitude at most"),
        ("lower = -1.0\n", "motors[0]", "lower"),
    ],
)
def test_bad_limits_are_refused_naming_file_and_field(limits, field, words):
    with pytest.raises(linkopt.MechanismFileError) as caught:
        slider(limits, "bad.toml")
    message = str(caught.value)
    assert "bad.toml" in message and field in message and words in message
    assert "\n" not in message


def test_a_rotary_limit_lies_within_half_a_turn():
    text = (MECHANISMS / "five_bar.toml").read_text()
    motor = '[[motors]]\nname = "left"\njoint = "base_left"\n'
    with pytest.raises(linkopt.MechanismFileError, match=r"motors\[0\]\.max.*±π"):
        linkopt.loads(text.replace(motor, motor + "max = 3.5\n"), "turn.toml")


def test_limits_are_read_in_file_units_and_homogenised_for_the_samples():
    mech = slider("min = -3.0\n", "one_sided.toml")
    assert mech.motor_limited
    assert mech.motor_min.tolist() == [-3.0] and mech.motor_max.tolist() == [math.inf]
    low, high = motor_box(mech)
    assert float(low[0]) == -3.0 / mech.length_scale and float(high[0]) == math.inf


def test_a_file_without_limits_has_none_and_keeps_its_fingerprint_and_key():
    plain = linkopt.loads(SLIDER, "plain.toml")
    assert plain.motor_min is None and plain.motor_max is None
    assert not plain.motor_limited and "motor_min" not in numbers(plain)
    # the fields are left out of the digest while None: no key or fingerprint changed
    seen = Recorder()
    digest(plain, seen)
    assert b"motor_min" not in seen.data and b"motor_max" not in seen.data
    digest(tight(), seen)
    assert b"motor_min" in seen.data
    assert fingerprint(plain) != fingerprint(tight())
    assert structure(padded(plain)) != structure(padded(tight()))


class Recorder:
    """A hash sink that keeps what it is fed."""

    def __init__(self):
        self.data = b""

    def update(self, data: bytes) -> None:
        self.data += data


def test_limits_are_program_numbers_not_structure():
    """Two files that differ only in their limits share one program, each computed
    with its own limits (a limit baked into the program would give both the same
    samples)."""
    other = slider("min = -8.0\nmax = 6.0\n", "other.toml")
    assert structure(padded(other)) == structure(padded(tight()))
    assert numbers(other)["motor_min"].tolist() == [-8.0]
    ours, theirs = linkopt.evaluate(tight()), linkopt.evaluate(other)
    for ev, mech in ((ours, tight()), (theirs, other)):
        _assert_within(mech, ev)
    ik_ours = np.asarray(ours.ik_motors)[:, 0] * tight().length_scale
    ik_theirs = np.asarray(theirs.ik_motors)[:, 0] * other.length_scale
    assert ik_ours.min() == pytest.approx(-3.0, abs=1e-12)
    assert ik_theirs.min() == pytest.approx(-8.0, abs=1e-12)


def _assert_within(mech, ev) -> None:
    """Every IK and adversarial sample's motors within the file's limits (file
    units), and the states solve FK at those motors."""
    for motors in (ev.ik_motors, ev.adv_motors):
        values = np.asarray(motors) * mech.motor_scale
        assert np.all(values >= mech.motor_min - 1e-12)
        assert np.all(values <= mech.motor_max + 1e-12)
    values = np.asarray(linkopt.motor_values(mech, np.asarray(ev.ik_states)))
    np.testing.assert_allclose(
        values, np.asarray(ev.ik_motors) * mech.motor_scale, atol=1e-8
    )


def test_samples_stay_within_the_limits_and_an_unreachable_target_fails():
    """The crank's range needs strokes of about -13.6 and +15.1 mm at its ends:
    with a stroke of -3..2 mm those two targets are missed with the motor held at its
    limit (the reach term counts them), the middle one is reached."""
    mech = tight()
    ev = linkopt.evaluate(mech)
    _assert_within(mech, ev)
    ik = np.asarray(ev.ik_motors)[:, 0] * mech.length_scale
    goals = targets(mech)[:, 0]
    middle = int(np.argmin(np.abs(goals)))
    ends = [k for k in range(len(goals)) if k != middle]
    assert sorted(ik[ends].tolist()) == pytest.approx([-3.0, 2.0], abs=1e-12)
    reach = np.asarray(ev.ik_reach)
    assert np.all(reach[ends] > 1e-3) and reach[middle] < 1e-12
    assert float(ev.f_design) == pytest.approx(float(np.mean(reach)), rel=1e-12)
    assert float(ev.f_design) > 1e-3
    # the IK sample at a limit is the best the stroke allows: the crank angle there
    # is the one FK gives at the limit
    angle = np.asarray(linkopt.output_values(mech, np.asarray(ev.ik_states)))[:, 0]
    at_limit = linkopt.solve_fk(mech, np.array([[-3.0], [2.0]]))
    reached = np.asarray(linkopt.output_values(mech, at_limit.state))[:, 0]
    assert sorted(angle[ends]) == pytest.approx(sorted(reached), abs=1e-8)


def test_wide_limits_give_the_evaluation_without_limits():
    """Limits the samples never reach change no number: the projected step is the
    plain step inside the box."""
    plain = linkopt.evaluate(linkopt.loads(SLIDER, "plain.toml"))
    wide = linkopt.evaluate(slider("min = -40.0\nmax = 40.0\n", "wide.toml"))
    for field in ("f_design", "ik_motors", "adv_motors", "adv_f_sing", "ik_states"):
        np.testing.assert_array_equal(
            np.asarray(getattr(wide, field)), np.asarray(getattr(plain, field))
        )


def test_verify_names_the_motor_cell_and_value(tmp_path, capsys):
    path = tmp_path / "tight.toml"
    path.write_text(SLIDER.replace(MOTOR, MOTOR + "min = -3.0\nmax = 2.0\n"))
    assert main(["verify", str(path), "--resolution", "9", "--json"]) == 1
    entry = json.loads(capsys.readouterr().out)["motor_limits"]
    assert entry["motor"] == "slide" and not entry["kept"]
    # the worst cell is a corner of the range, where FK's stroke is furthest out
    stroke = linkopt.solve_bk(tight(), np.array([[entry["cell"]["crank_angle"]]]))
    assert entry["value"] == pytest.approx(
        float(np.asarray(linkopt.motor_values(tight(), stroke.state))[0, 0]), abs=1e-6
    )
    assert abs(entry["cell"]["crank_angle"]) == pytest.approx(0.8)
    assert entry["excess"] == pytest.approx(
        max(entry["value"] - 2.0, -3.0 - entry["value"])
    )
    assert main(["verify", str(path), "--resolution", "9"]) == 1
    text = capsys.readouterr().out
    assert "motor limits: FAIL: motor slide needs" in text
    assert "crank_angle=" in text and "[-3, 2]" in text


def test_verify_passes_with_limits_wide_enough(tmp_path, capsys):
    path = tmp_path / "wide.toml"
    path.write_text(SLIDER.replace(MOTOR, MOTOR + "min = -20.0\nmax = 20.0\n"))
    assert main(["verify", str(path), "--resolution", "9", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    entry = result["motor_limits"]
    assert result["passed"] and entry["kept"] and entry["excess"] < 0
    assert entry["value"] == pytest.approx(20.0 + entry["excess"])
    plain = tmp_path / "plain.toml"
    plain.write_text(SLIDER)
    assert main(["verify", str(plain), "--resolution", "9", "--json"]) == 0
    assert "motor_limits" not in json.loads(capsys.readouterr().out)


def test_check_shows_the_limits(tmp_path, capsys):
    path = tmp_path / "one_sided.toml"
    path.write_text(SLIDER.replace(MOTOR, MOTOR + "min = -3.0\n"))
    assert main(["check", str(path), "--json"]) == 0
    motor = json.loads(capsys.readouterr().out)["motors"]["slide"]
    assert motor["min"] == -3.0 and "max" not in motor
    assert main(["check", str(path)]) == 0
    assert "linear at slide, limits [-3, inf]" in capsys.readouterr().out
    assert main(["check", str(MECHANISMS / "slider_crank_linear.toml")]) == 0
    assert ", limits [" not in capsys.readouterr().out


def test_the_written_file_keeps_the_limits(tmp_path):
    mech = slider("min = -3.0\n", "one_sided.toml")
    path = write_design(mech, mech.design.upper, 12.0, tmp_path / "written.toml")
    again = linkopt.load(path)
    assert again.motor_min.tolist() == [-3.0] and again.motor_max.tolist() == [math.inf]
    assert "min = -3.0" in path.read_text()


def test_the_maps_draw_the_limits():
    from matplotlib import pyplot as plt

    from linkopt._draw.plot_maps import plot_windows
    from linkopt._draw.space_plots import limit_lines

    text = (MECHANISMS / "five_bar.toml").read_text()
    for name, joint, limits in (
        ("left", "base_left", "min = -0.5\nmax = 0.25\n"),
        ("right", "base_right", "max = 0.75\n"),
    ):
        motor = f'[[motors]]\nname = "{name}"\njoint = "{joint}"\n'
        text = text.replace(motor, motor + limits)
    mech = linkopt.loads(text, "limited_five_bar.toml")
    samples = SimpleNamespace(ik_motors=np.zeros((1, 2)), adv_motors=np.zeros((1, 2)))
    rest = linkopt.rest_state(mech)
    (low, high), _, _ = plot_windows(mech, samples, rest, None)
    assert np.all(low < [-0.5, -0.3]) and np.all(high > [0.3, 0.75])
    fig, ax = plt.subplots()
    assert limit_lines(ax, mech) == 3
    lines = [(tuple(line.get_xdata()), tuple(line.get_ydata())) for line in ax.lines]
    assert ((-0.5, -0.5), (0, 1)) in lines and ((0.25, 0.25), (0, 1)) in lines
    assert ((0, 1), (0.75, 0.75)) in lines
    assert limit_lines(plt.subplots()[1], linkopt.loads(SLIDER, "plain.toml")) == 0
    plt.close("all")


def test_mjcf_carries_the_limits_in_metres():
    import mujoco

    mech = slider("min = -3.0\nmax = 2.0\n")
    text, _ = mjcf.mjcf_text(mech)
    model = mujoco.MjModel.from_xml_string(text)
    joint, actuator = model.joint("slide"), model.actuator("slide")
    assert bool(model.jnt_limited[joint.id]) and bool(actuator.ctrllimited[0])
    np.testing.assert_allclose(joint.range, [-0.003, 0.002], rtol=0, atol=1e-15)
    np.testing.assert_allclose(actuator.ctrlrange, [-0.003, 0.002], rtol=0, atol=1e-15)
    plain, _ = mjcf.mjcf_text(linkopt.loads(SLIDER, "plain.toml"))
    assert "ctrlrange" not in plain and "range=" not in plain


ARM = """
[mechanism]
name = "slide and swing"
ground = "g"
units = "mm"
[[bodies]]
name = "g"
[[bodies]]
name = "carriage"
[[bodies]]
name = "arm"
[[joints]]
name = "rail"
type = "prismatic"
bodies = ["g", "carriage"]
anchor = [0.0, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]
[[joints]]
name = "hinge"
type = "revolute"
bodies = ["carriage", "arm"]
anchor = [10.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[motors]]
name = "push"
joint = "rail"
min = -10.0
max = 25.0
[[motors]]
name = "swing"
joint = "hinge"
min = -1.0
[[points]]
name = "tip"
body = "arm"
position = [50.0, 30.0, 0.0]
[[outputs]]
name = "x"
point = "tip"
coordinate = "x"
min = 40.0
max = 60.0
[[outputs]]
name = "y"
point = "tip"
coordinate = "y"
min = 20.0
max = 30.0
"""


def test_urdf_and_mjcf_of_an_open_chain_read_back(tmp_path):
    import mujoco
    import yourdfpy

    mech = linkopt.loads(ARM, "arm.toml")
    path = tmp_path / "arm.urdf"
    urdf.export_urdf(mech, path)
    robot = yourdfpy.URDF.load(
        str(path), load_meshes=False, build_collision_scene_graph=False
    )
    rail, hinge = robot.joint_map["rail"], robot.joint_map["hinge"]
    assert rail.type == "prismatic" and hinge.type == "revolute"
    assert (rail.limit.lower, rail.limit.upper) == pytest.approx((-0.01, 0.025))
    # the side the file leaves open: ±π for a hinge
    assert (hinge.limit.lower, hinge.limit.upper) == pytest.approx((-1.0, math.pi))
    model = mujoco.MjModel.from_xml_string(mjcf.mjcf_text(mech)[0])
    np.testing.assert_allclose(model.actuator("push").ctrlrange, [-0.01, 0.025])
    assert model.actuator("swing").ctrlrange[0] == -1.0
    assert model.actuator("swing").ctrlrange[1] == math.inf


def test_a_rotary_limit_held_while_the_other_motor_moves():
    """Two motors, one limit each side of the hinge's rest angle: the targets at
    y = 20 need the arm turned to about -0.23 rad, below its limit of -0.2; their IK
    samples stop with the hinge held at -0.2 while the slide still moves (projected
    Newton), and the other targets are reached."""
    text = ARM.replace("min = -1.0\n", "min = -0.2\nmax = 0.3\n")
    mech = linkopt.loads(text.replace("min = -10.0\n", "min = -20.0\n"), "swing.toml")
    ev = linkopt.evaluate(mech)
    _assert_within(mech, ev)
    goals, reach = targets(mech), np.asarray(ev.ik_reach)
    swing = np.asarray(ev.ik_motors)[:, 1]
    low = goals[:, 1] == 20.0
    assert np.all(swing[low] == -0.2) and np.all(reach[low] > 1e-4)
    assert np.all(reach[~low] < 1e-12)
    # held at the limit, the slide puts the tip at the target's x: only y is missed
    tips = np.asarray(linkopt.output_values(mech, np.asarray(ev.ik_states)))
    np.testing.assert_allclose(tips[low, 0], goals[low, 0], atol=1e-6)


def test_a_verification_round_adds_the_cell_beyond_the_limits():
    from linkopt._design.rounds import failing_places
    from linkopt._design.verify import Verification

    mech = tight()
    cell = np.array([-0.8])
    check = Verification(
        passed=False,
        coverage=1.0,
        cells=9,
        threshold=15.0,
        max_f_sing=10.0,
        min_sigma_fk=0.1,
        min_sigma_bk=0.3,
        worst_outputs=np.array([0.8]),
        unreached_example=None,
        grid_shape=(9,),
        limit_motor="slide",
        limit_value=15.06,
        limit_outputs=cell,
        limit_excess=13.06,
    )
    assert check.beyond_limits
    assert failing_places(mech, check) == []  # -0.8 is a grid target already
    inside = dataclasses.replace(check, limit_outputs=np.array([-0.7]))
    assert failing_places(mech, inside) == [[-0.7]]
    kept = dataclasses.replace(inside, limit_excess=-1.0, passed=True)
    assert not kept.beyond_limits and failing_places(mech, kept) == []
    assert kept.as_json()["limit_motor"] == "slide"
    assert "limit_motor" not in dataclasses.replace(kept, limit_excess=None).as_json()


def test_evaluate_names_the_samples_held_at_a_limit(tmp_path, capsys):
    path = tmp_path / "tight.toml"
    path.write_text(SLIDER.replace(MOTOR, MOTOR + "min = -3.0\nmax = 2.0\n"))
    assert main(["evaluate", str(path), "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    entry = payload["motor_limits"]["slide"]
    assert (entry["min"], entry["max"]) == (-3.0, 2.0)
    missed = [k for k, s in enumerate(payload["samples"]) if s["ik"]["f_bk"] > 1e-6]
    assert entry["held"] == missed and len(missed) == 2
    assert main(["evaluate", str(path)]) == 0
    line = f"IK samples held at a motor limit: slide (targets {missed[0]}, {missed[1]})"
    assert line in capsys.readouterr().out
