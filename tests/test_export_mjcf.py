"""MJCF export round trip through MuJoCo (issue 18).

Two properties per mechanism, at FK solutions away from the rest pose and for a design
other than the file's:

* kinematics: linkopt's FK state written as MuJoCo joint coordinates puts every body and
  every site where linkopt has them (1e-9 m), the equality constraints hold (efc_pos of
  the equality rows ≈ 0) and each actuator's joint reads its motor value;
* settling: from a perturbed configuration, with the actuators at the motor values,
  MuJoCo's own dynamics and soft-constraint solver return the sites to linkopt's FK
  positions within 1e-4 of the mechanism's size. Gravity is zero in the file, so at the
  exact solution neither the soft constraints nor the position servos push: the
  settled state *is* the FK solution and the remaining error is only how far the
  slowest mode has decayed (the initial designs sit near forward singularities, where
  the constraint stiffness along the singular direction is small: seconds of simulated
  time, not steps).
"""

import functools
from pathlib import Path

import mujoco
import numpy as np
import pytest

import linkopt
from linkopt._export import mjcf

ROOT = Path(__file__).resolve().parent.parent
WEDGE = """
[mechanism]
name = "wedge"
ground = "ground"
units = "cm"
[[bodies]]
name = "ground"
[[bodies]]
name = "pusher"
[[bodies]]
name = "lifter"
[[joints]]
name = "push"
type = "prismatic"
bodies = ["ground", "pusher"]
anchor = [0.0, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]
[[joints]]
name = "ramp"
type = "prismatic"
bodies = ["pusher", "lifter"]
anchor = [2.0, 1.0, 0.0]
axis = [-1.0, 1.0, 0.0]
[[joints]]
name = "guide"
type = "prismatic"
bodies = ["lifter", "ground"]
anchor = [3.0, 3.0, 0.0]
axis = [0.0, 1.0, 0.0]
[[motors]]
name = "push"
joint = "push"
[[points]]
name = "top"
body = "lifter"
joint = "guide"
[[outputs]]
name = "height"
point = "top"
coordinate = "y"
min = 2.0
max = 4.0
"""

#: (file, motor values, design as a fraction of the way from p0 to the upper bound)
CASES = [
    ("five_bar", [0.2, 0.1], 0.2),
    ("jansen_2dof", [0.4, 0.2], 0.1),
    ("neck_2dof", [0.15, -0.1], 0.1),
]


@functools.cache
def _mechanism(name: str) -> linkopt.Mechanism:
    if name == "wedge":
        return linkopt.loads(WEDGE, "wedge.toml")
    return linkopt.load(ROOT / "mechanisms" / f"{name}.toml")


def _design(mech, fraction):
    d = mech.design
    return d.p0 + fraction * (d.upper - d.p0) if d.size else None


def _fk(mech, motors, design=None) -> np.ndarray:
    """linkopt's FK state at ``motors`` ``(M,)`` from rest, converged (asserted).

    Solved in a batch with half the motor values: a batch from rest runs the 64-row
    block program, which test_reference_values.py compiles for every shipped mechanism
    anyway, where one row alone would compile the one-row program beside it (2-8 CPU s
    per mechanism, cold)."""
    motors = np.asarray(motors, dtype=np.float64)
    sol = linkopt.solve_fk(mech, np.stack([motors, 0.5 * motors]), design=design)
    assert np.asarray(sol.converged).all()
    return np.asarray(sol.state[0])


def _posed(mech, motors, design):
    """MuJoCo model and data at linkopt's FK solution, and the solution's state."""
    text, summary = mjcf.mjcf_text(mech, design)
    model = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(model)
    state = _fk(mech, motors, design)
    for name, value in mjcf.joint_values(mech, state, design).items():
        address = model.joint(name).qposadr[0]
        data.qpos[address : address + len(value)] = value
    mujoco.mj_forward(model, data)
    return model, data, state, summary["metres_per_unit"]


def _site_error(mech, data, points) -> float:
    return max(
        float(np.abs(data.site(name).xpos - points[k]).max())
        for k, name in enumerate(mech.point_names)
    )


@pytest.mark.parametrize("name, motors, fraction", [*CASES, ("wedge", [0.7], 0.0)])
def test_mujoco_kinematics_match_fk(name, motors, fraction):
    mech = _mechanism(name)
    design = _design(mech, fraction)
    model, data, state, s = _posed(mech, motors, design)
    points = np.asarray(linkopt.point_positions(mech, state, design=design)) * s
    assert _site_error(mech, data, points) < 1e-9
    bodies = np.asarray(state).reshape(-1, 7)
    for b, body in enumerate(mech.body_names):
        assert (
            np.abs(data.body(body).xpos - bodies[b, :3] * mech.length_scale * s).max()
            < 1e-9
        )
        assert (
            min(
                np.abs(data.body(body).xquat - sign * bodies[b, 3:]).max()
                for sign in (1, -1)
            )
            < 1e-9
        )
    equality = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    closures = len(mech.joint_names) - (mech.num_bodies - 1)
    assert equality.sum() >= 3 * closures > 0
    assert np.abs(data.efc_pos[equality]).max() < 1e-9
    scale = np.where(mech.motor_linear, s, 1.0)
    for m, motor in enumerate(mech.motor_names):
        joint = model.actuator(motor).trnid[0]
        address = model.jnt_qposadr[joint]
        assert data.qpos[address] == pytest.approx(motors[m] * scale[m], abs=1e-10)


def test_wedge_closure_body_and_closed_form():
    """The prismatic loop closes through a closure body welded to the ground, and the
    lifter rises by the push (closed form: ``y = 3 + a`` cm)."""
    mech = _mechanism("wedge")
    model, data, state, s = _posed(mech, [0.7], None)
    assert model.body("guide_closure").id > 0
    assert model.eq("guide").type == mujoco.mjtEq.mjEQ_WELD
    assert data.site("top").xpos[1] == pytest.approx((3.0 + 0.7) * s, abs=1e-12)


@pytest.mark.parametrize("name, motors, fraction", CASES)
def test_mujoco_settles_onto_fk(name, motors, fraction):
    mech = _mechanism(name)
    design = _design(mech, fraction)
    model, data, state, s = _posed(mech, motors, design)
    points = np.asarray(linkopt.point_positions(mech, state, design=design)) * s
    kick = np.random.default_rng(0).normal(scale=0.02, size=model.nv)
    mujoco.mj_integratePos(model, data.qpos, kick, 1.0)
    data.ctrl[:] = np.asarray(motors) * np.where(mech.motor_linear, s, 1.0)
    mujoco.mj_forward(model, data)
    size = mech.length_scale * s
    assert _site_error(mech, data, points) > 1e-3 * size  # it did start away
    for _ in range(int(6.0 / model.opt.timestep)):
        mujoco.mj_step(model, data)
    assert _site_error(mech, data, points) < 1e-4 * size


def test_units_and_structure(five_bar):
    text, summary = mjcf.mjcf_text(five_bar)
    assert "file units mm x 0.001" in text
    model = mujoco.MjModel.from_xml_string(text)
    assert summary["closures"] == ["tip"]
    assert {model.eq(k).name for k in range(model.neq)} == {"tip", "tip_axis"}
    assert model.nu == 2 and model.nsite == 1
    assert model.opt.gravity.tolist() == [0.0, 0.0, 0.0]
    # qpos0 is the rest pose: the end effector sits at its file position (metres)
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    assert np.abs(data.site("ee").xpos - [0.0, 0.070, 0.0]).max() < 1e-15


def test_optimize_writes_the_mjcf_beside_the_toml(tmp_path, five_bar, monkeypatch):
    """``write_outputs`` stages ``optimized.xml``: the MJCF of the returned design, the
    same document ``linkopt export`` writes for ``optimized.toml``. (The rest of the
    outputs is stood in for by a stop right after the two files.)"""
    import dataclasses

    from linkopt._design.optimizer import OptimizerSettings, start
    from linkopt._draw.run_folder import write_outputs

    settings = OptimizerSettings(particles=2, iterations=1)
    design = five_bar.design.p0 + 0.1 * (five_bar.design.upper - five_bar.design.p0)
    record = dict.fromkeys(
        ["iteration", "best_total", "best_f_design", "regularizer", "reach"], 0.0
    )
    run = dataclasses.replace(
        start(five_bar, settings),
        iteration=1,
        finished=True,
        result_pos=design,
        history=({**record, "singularity": 0.0, "evaluations": 2, "wall_time": 0},),
    )
    seen = {}

    def stop(mech, current, stage, *_):
        seen["xml"] = (stage / "optimized.xml").read_text()
        seen["toml"] = linkopt.load(stage / "optimized.toml")
        raise RuntimeError("stop after the design files")

    monkeypatch.setattr("linkopt._design.run._design_outputs", stop)
    with pytest.raises(RuntimeError, match="stop after"):
        write_outputs(five_bar, tmp_path, run, settings)
    optimized = seen["toml"]
    assert np.allclose(optimized.design.p0, design, rtol=0, atol=1e-12)
    model = mujoco.MjModel.from_xml_string(seen["xml"])
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    tip = optimized.anchors[optimized.joint_names.index("tip")] * 1e-3
    assert np.abs(data.site("ee").xpos - tip).max() < 1e-15


# ---- issue 45: driven from rest, every shipped closed-loop mechanism settles -------

SHIPPED = sorted(p.stem for p in (ROOT / "mechanisms").glob("*.toml"))


@functools.cache
def _spherical_five_bar() -> linkopt.Mechanism:
    """The spherical five-bar of ``test_assembly_spherical`` (every axis through one
    centre), assembled from its drawing."""
    from test_assembly_spherical import drawing

    from linkopt._files.assembly import assemble
    from linkopt._files.fields import parse_toml
    from linkopt._files.writer import dumps

    result = assemble(parse_toml(drawing(), "sph.toml"), "sph.toml")
    return linkopt.loads(dumps(result.data), "spherical_five_bar.toml")


def _offsets(mech) -> np.ndarray:
    """Motor values away from rest: 0.2 rad, or 5 % of the reference length for a
    linear motor, alternating in sign (0.2, -0.14, 0.2, ...)."""
    signs = np.where(np.arange(mech.num_motors) % 2 == 0, 1.0, -0.7)
    return 0.2 * signs * np.where(mech.motor_linear, 0.25 * mech.length_scale, 1.0)


def _settling_error(mech, data, state, s) -> float:
    """Largest distance (m) of a body origin or a site from linkopt's FK state."""
    bodies = np.asarray(state).reshape(-1, 7)[:, :3] * mech.length_scale * s
    points = np.asarray(linkopt.point_positions(mech, state)).reshape(-1, 3) * s
    return max(
        *(
            np.linalg.norm(data.body(b).xpos - bodies[k])
            for k, b in enumerate(mech.body_names)
        ),
        *(
            np.linalg.norm(data.site(p).xpos - points[k])
            for k, p in enumerate(mech.point_names)
        ),
    )


@pytest.mark.parametrize("name", [*SHIPPED, "spherical_five_bar_drawn"])
def test_driven_from_rest_settles_onto_fk(name):
    """Issue 45: the actuators' controls set to motor values that FK solves, from the
    rest pose, MuJoCo settles onto linkopt's FK within 1e-3 reference lengths in 5
    simulated seconds (bodies and sites), with the equalities closed, and the file
    carries no settling warning."""
    if name == "spherical_five_bar_drawn":
        mech = _spherical_five_bar()
    else:
        mech = _mechanism(name)
    motors = _offsets(mech)
    state = _fk(mech, motors)
    text, summary = mjcf.mjcf_text(mech)
    assert summary["warnings"] == [] and "warning" not in text
    model = mujoco.MjModel.from_xml_string(text)
    data = mujoco.MjData(model)
    s = summary["metres_per_unit"]
    size = mech.length_scale * s
    data.ctrl[:] = motors * np.where(mech.motor_linear, s, 1.0)
    mujoco.mj_forward(model, data)
    assert _settling_error(mech, data, state, s) > 1e-2 * size  # it starts away
    mujoco.mj_step(model, data, nstep=int(5.0 / model.opt.timestep))
    error = _settling_error(mech, data, state, s) / size
    equality = data.efc_type == mujoco.mjtConstraint.mjCNSTR_EQUALITY
    print(f"{name}: settled to {error:.1e} reference lengths")
    assert error < 1e-3
    assert np.abs(data.efc_pos[equality]).max() < 1e-6 * size
    assert np.abs(data.qvel).max() < 1e-3  # at rest, not passing through


LOCKED = """
[[parameters]]
name = "tilt"
joint = "D"
coordinate = "axis_x"
min = -0.5
max = 0.5
"""


def test_a_design_that_locks_the_loop_is_named_in_the_file_and_by_the_cli(
    tmp_path, capsys
):
    """A four-bar whose design tilts the rocker's axis out of parallel is a spatial
    4R loop: redundant in the plane, locked once tilted (mobility 0). Its MJCF cannot
    settle onto FK and says so in the file; the command line refuses the design with
    the mobility it has; the file's own design (the axis parallel) carries no
    warning."""
    from linkopt._cli.main import main

    source = tmp_path / "tilted.toml"
    source.write_text((ROOT / "mechanisms" / "four_bar.toml").read_text() + LOCKED)
    mech = linkopt.load(source)
    assert mjcf.mjcf_text(mech)[1]["warnings"] == []
    design = np.append(mech.design.p0[:-1], 0.3)
    text, summary = mjcf.mjcf_text(mech, design)
    assert len(summary["warnings"]) == 1
    assert "mobility 0 at rest but 1 motor(s)" in summary["warnings"][0]
    assert "<!-- warning: this design has mobility 0" in text
    # the command line refuses such a design before exporting it, as every command
    # that takes --design does (linkopt._engine.mobility), naming the locked motor
    out = tmp_path / "tilted.xml"
    args = ["export", str(source), "--format", "mjcf", "--out", str(out)]
    assert main([*args, "--design", ",".join(map(repr, design.tolist()))]) == 2
    err = capsys.readouterr().err
    assert "has mobility 0 at the rest pose, the file's 1: motor(s) crank" in err
    assert not out.exists()
