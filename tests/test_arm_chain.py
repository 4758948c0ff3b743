"""The serial chain every arm family hands to the engine (:mod:`linkopt._arms.chain`):
for module arms, DH tables and planar trace arms alike, the closed-form chain state of a
configuration closes the engine's FK constraints at that configuration's motor values,
and the engine's ``tip`` at that state is the family's own closed-form tip."""

import jax.numpy as jnp
import numpy as np
import pytest
from arm_tasks import TINY_ARM
from test_arm_model import dh_arm

import linkopt
from linkopt._arms.chain import chain_definition, chain_state
from linkopt._arms.codesign.model import chain, direct_state
from linkopt._arms.codesign.task import loads_task as loads_arm_task
from linkopt._arms.dh import table as dh
from linkopt._arms.trace import geometry as geo
from linkopt._arms.trace.export import engine_state, mechanism_text, rest_pose
from linkopt._arms.trace.synthesis import TraceResult
from linkopt._arms.trace.task import loads_task as loads_trace_task
from linkopt._arms.trace.verify import PlanarArm
from linkopt._engine.constraints import fk_residual
from linkopt._engine.geometry import geometry
from linkopt._files.writer import dumps

RNG = np.random.default_rng(7)
TRACE_TASK = (
    '[task]\nname = "t"\nlink_diameter = 0.02\n'
    '[[primitives]]\ntype = "line"\nstart = [0.3, -0.1]\nend = [0.3, 0.1]\n'
)


def _module_arm(which: str):
    """``(mechanism, [(motors, state, closed-form tip)])`` of a module arm."""
    if which == "tiny":
        target = "[[targets]]\nposition = [0.0, 0.0, 0.0]\n"
        arm = loads_arm_task(TINY_ARM + target, "tiny.toml").arm
    else:
        arm = dh_arm()
    d = jnp.asarray(arm.d0)
    cases = []
    for _ in range(4):
        theta = jnp.asarray(RNG.uniform(-3.0, 3.0, arm.num_joints))
        ends, _ = chain(arm.modules, theta, d)
        cases.append((theta, direct_state(arm, theta, d), ends[-1][1]))
    return arm.mechanism, cases


def _dh_arm(types: str):
    """The same for a DH table with a random rest pose."""
    n = len(types)
    table = dh.table_from_arrays(
        types,
        RNG.uniform(0.2, 0.6, n),
        RNG.uniform(-1.5, 1.5, n),
        RNG.uniform(-0.3, 0.3, n),
    )
    q_rest = jnp.asarray(RNG.uniform(-1.0, 1.0, n))
    mech, _ = dh.to_mechanism(types, table, q_rest)
    cases = []
    for _ in range(4):
        q = jnp.asarray(RNG.uniform(-2.5, 2.5, n))
        state = dh.engine_state(types, table, q, q_rest, float(mech.length_scale))
        cases.append(
            (dh.motor_values(q, q_rest), state, dh.tip_position(types, table, q))
        )
    return mech, cases


def _trace_arm(lengths):
    """The same for an exported planar arm (2 or 3 links) at random joint angles."""
    task = loads_trace_task(TRACE_TASK, "t.toml")
    n = len(lengths)
    design = PlanarArm(
        np.array([0.02, -0.01]), np.array(lengths), np.full(n - 2, 0.3), 1
    )
    result = TraceResult(task, design, None, "app", 0.0)
    mech = linkopt.loads(mechanism_text(result), "arm.toml")
    rest = rest_pose(result)
    rest_angles = np.asarray(geo.joint_angles(jnp.asarray(rest)[None]))[0]
    angles = RNG.uniform(-3.0, 3.0, (4, n))
    states = np.asarray(geo.forward(jnp.asarray(design.base), design.lengths, angles))
    cases = []
    for a, s in zip(angles, states):
        motors = np.angle(np.exp(1j * (a - rest_angles)))
        tip = np.append(s[-1], 0.0)
        cases.append((jnp.asarray(motors), engine_state(mech, rest, s), tip))
    return mech, cases


FAMILIES = {
    "modules, tiny": lambda: _module_arm("tiny"),
    "modules, DH rows": lambda: _module_arm("dh"),
    "DH RPR": lambda: _dh_arm("RPR"),
    "DH RRPR": lambda: _dh_arm("RRPR"),
    "DH PR": lambda: _dh_arm("PR"),
    "trace, 2 links": lambda: _trace_arm([0.2, 0.25]),
    "trace, 3 links": lambda: _trace_arm([0.1, 0.15, 0.15]),
}


@pytest.mark.parametrize("family", list(FAMILIES))
def test_chain_state_closes_the_engine_and_puts_the_tip_at_the_closed_form(family):
    mech, cases = FAMILIES[family]()
    geom = geometry(mech)
    tip = mech.point_names.index("tip")
    for motors, state, expected in cases:
        homogenised = jnp.asarray(motors) / mech.motor_scale
        residual = fk_residual(mech, geom, homogenised, state)
        assert float(jnp.max(jnp.abs(residual))) < 1e-12
        position = np.asarray(linkopt.point_positions(mech, state))[tip]
        np.testing.assert_allclose(position, expected, atol=1e-12)


def test_chain_definition_is_a_serial_chain_the_loader_accepts():
    """Joint k joins bodies k and k+1 and drives motor k; a prismatic joint slides; the
    rest state is the chain state at rest."""
    anchors = np.array([[0.0, 0.0, 0.0], [0.5, 0.0, 0.0]])
    axes = np.array([[0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
    data = chain_definition(
        "pair",
        ["ground", "a", "b"],
        ["hinge", "slide"],
        ["m1", "m2"],
        anchors,
        axes,
        points=[("tip", 2, [0.9, 0.0, 0.0])],
        outputs=[
            {"name": "x", "point": "tip", "coordinate": "x", "min": 0.0, "max": 2.0},
            {"name": "y", "point": "tip", "coordinate": "y", "min": -1.0, "max": 1.0},
        ],
        types="RP",
    )
    assert [j["bodies"] for j in data["joints"]] == [["ground", "a"], ["a", "b"]]
    assert [j["type"] for j in data["joints"]] == ["revolute", "prismatic"]
    mech = linkopt.loads(dumps(data), "pair.toml")
    assert list(mech.motor_names) == ["m1", "m2"]
    identity = jnp.tile(jnp.array([1.0, 0.0, 0.0, 0.0]), (3, 1))
    origins = jnp.asarray(mech.body_origins)
    state = chain_state(identity, origins, identity, mech.length_scale)
    geom = geometry(mech)
    residual = fk_residual(mech, geom, jnp.zeros(2), state)
    assert float(jnp.max(jnp.abs(residual))) < 1e-12
