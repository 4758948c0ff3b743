"""Every shipped mechanism loads and closes its loops; broken files give clear
errors."""

import ast
import importlib
from pathlib import Path

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt

SHIPPED = sorted(MECHANISMS.glob("*.toml"))
FIVE_BAR = (MECHANISMS / "five_bar.toml").read_text()


@pytest.mark.parametrize("path", SHIPPED, ids=[p.stem for p in SHIPPED])
def test_shipped_file_assembles_and_closes_loops(path):
    mech = linkopt.load(path)
    assert linkopt.mobility(mech) == mech.num_motors == mech.num_outputs
    # the rest motors and a nudge, in one batch: the block program that
    # test_reference_values.py compiles for every shipped file
    nudge = np.full(mech.num_motors, 0.05) * mech.motor_scale
    rows = np.stack([np.zeros(mech.num_motors), nudge])
    solved = linkopt.solve_fk(mech, rows)
    assert np.all(solved.converged) and float(np.max(solved.residual)) <= 1e-10
    np.testing.assert_allclose(
        linkopt.motor_values(mech, solved.state), rows, atol=1e-10
    )


def _header_paragraphs(text: str) -> list[str]:
    """The leading comment block's paragraphs (split at lines holding ``#`` alone)."""
    lines = []
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            break
        lines.append(line.rstrip())
    return [p.strip() for p in "\n".join(lines).split("\n#\n") if p.strip()]


def test_no_shipped_header_repeats_a_paragraph():
    """A generator that rewrites its own output keeps the old file's header below
    its new one (``write_design``): ``jansen_foot_path.toml`` carried its header three
    times."""
    assert _header_paragraphs("# a\n# b\n#\n# a\n# b\n\nx = 1\n") == ["# a\n# b"] * 2
    for path in SHIPPED:
        paragraphs = _header_paragraphs(path.read_text())
        assert len(paragraphs) == len(set(paragraphs)), path.name


def test_five_bar_sizes(five_bar):
    assert five_bar.state_size == 35
    assert five_bar.design.size == 3
    assert linkopt.constraint_rows(five_bar) == {"passive": 36, "fk": 38, "bk": 38}
    assert five_bar.length_scale == pytest.approx(74.0)  # elbow to elbow at rest


def edit(old, new, count=1):
    assert FIVE_BAR.count(old) >= count, old
    return FIVE_BAR.replace(old, new, count)


BROKEN = {
    "malformed_toml": (
        edit('name = "five-bar"', 'name = "five-bar'),
        "invalid TOML",
        "line 11",
    ),
    "unknown_body": (
        edit('bodies = ["ground", "crank_left"]', 'bodies = ["ground", "crank_lft"]'),
        "joints[0].bodies",
        "unknown body 'crank_lft'",
    ),
    "unknown_joint_type": (
        edit('type = "revolute"', 'type = "hinge"'),
        "joints[0].type",
        "unknown joint type 'hinge'; expected one of ['revolute', 'spherical', "
        "'universal', 'prismatic', 'cylindrical', 'fixed']",
    ),
    "missing_anchor": (
        edit("anchor = [-20.0, 0.0, 0.0]\n", ""),
        "joints[0].anchor",
        "missing required field",
    ),
    "zero_axis": (
        edit("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.0, 0.0]"),
        "joints[0].axis",
        "zero-length axis",
    ),
    "duplicate_body": (
        edit('name = "crank_right"', 'name = "crank_left"'),
        "bodies[2].name",
        "duplicated name 'crank_left'",
    ),
    "empty_range": (
        edit("min = -40.0\nmax = 40.0", "min = 40.0\nmax = 40.0"),
        "outputs[0].min",
        "min < max",
    ),
    "one_motor": (
        edit('[[motors]]\nname = "right"\njoint = "base_right"\n', ""),
        "[[motors]]",
        "mobility 2 at the rest pose but 1 motor(s)",
    ),
    "typo_field": (
        edit("anchor = [0.0, 70.0, 0.0]", "anchr = [0.0, 70.0, 0.0]"),
        "joints[4].anchr",
        "unknown field",
    ),
    "bad_vector": (
        edit("anchor = [0.0, 70.0, 0.0]", "anchor = [0.0, 70.0]"),
        "joints[4].anchor",
        "expected a list of 3 finite numbers",
    ),
    "motor_on_unknown_joint": (
        edit('joint = "base_right"\n\n[[points]]', 'joint = "base_rite"\n\n[[points]]'),
        "motors[1].joint",
        "unknown joint 'base_rite'",
    ),
    "not_a_mirror": (
        edit("anchor = [-37.0, 36.0, 0.0]", "anchor = [-37.0, 35.0, 0.0]"),
        "parameters[1].mirror",
        "not the mirror image",
    ),
    "rest_outside_bounds": (
        edit("min = 5.0\nmax = 45.0", "min = 25.0\nmax = 45.0"),
        "parameters[0].min",
        "outside [25, 45]",
    ),
    "unknown_table": (
        FIVE_BAR + "\n[optimiser]\nparticles = 3\n",
        "optimiser",
        "unknown table",
    ),
    "bad_coordinate": (
        edit('coordinate = "x"\nmin = -40.0', 'coordinate = "w"\nmin = -40.0'),
        "outputs[0].coordinate",
        "expected 'x', 'y' or 'z'",
    ),
    "floating_body": (
        FIVE_BAR.replace(
            '[[bodies]]\nname = "ground"',
            '[[bodies]]\nname = "ground"\n[[bodies]]\nname = "loose"',
        ),
        "bodies[1]",
        "has no joint",
    ),
    "singular_rest": (
        edit("anchor = [0.0, 70.0, 0.0]", "anchor = [0.0, 36.0, 0.0]"),
        "",
        "singularity",
    ),
}

NECK_2 = (MECHANISMS / "neck_2dof.toml").read_text()
NECK_3 = (MECHANISMS / "neck_3dof.toml").read_text()
BROKEN |= {
    "universal_angle_missing": (
        NECK_2.replace('joint = "neck"\nangle = 1\n', 'joint = "neck"\n'),
        "outputs[0].angle",
        "missing required field for an angle of a universal joint",
    ),
    "universal_has_two_angles": (
        NECK_2.replace('joint = "neck"\nangle = 2\n', 'joint = "neck"\nangle = 3\n'),
        "outputs[1].angle",
        "expected an integer from 1 to 2, got 3",
    ),
    "revolute_angle_index": (
        NECK_2.replace(
            'joint = "neck"\nangle = 1\n', 'joint = "motor_left"\nangle = 1\n'
        ),
        "outputs[0].angle",
        "it has one angle",
    ),
    "spherical_without_frame": (
        NECK_3.replace("axis = [0.0, 0.0, 1.0]\naxis2 = [1.0, 0.0, 0.0]\n", "", 1),
        "outputs[0].joint",
        "needs axis and axis2",
    ),
    "spherical_half_frame": (
        NECK_3.replace(
            "axis = [0.0, 0.0, 1.0]\naxis2 = [1.0, 0.0, 0.0]\n",
            "axis = [0.0, 0.0, 1.0]\n",
            1,
        ),
        "joints[0].axis2",
        "needs both axis and axis2",
    ),
}


@pytest.mark.parametrize("name", sorted(BROKEN))
def test_broken_file_reports_file_field_and_expectation(name, tmp_path):
    text, where, message = BROKEN[name]
    path = tmp_path / f"{name}.toml"
    path.write_text(text)
    with pytest.raises(linkopt.MechanismFileError) as info:
        linkopt.load(path)
    rendered = str(info.value)
    assert (
        rendered.startswith(str(path)) and where in rendered and message in rendered
    ), rendered
    assert "\n" not in rendered


JANSEN = (MECHANISMS / "jansen_1dof.toml").read_text()
PIVOT_A = """
[[parameters]]
name = "pivot_a_x"
joint = {joints}
coordinate = "x"
min = -45.0
max = -30.0
"""


def test_parameter_moves_coincident_joints_together(tmp_path):
    path = tmp_path / "jansen_pivot.toml"
    path.write_text(JANSEN + PIVOT_A.format(joints='["A_triangle", "A_c"]'))
    mech = linkopt.load(path)
    design = np.array([-40.0])
    joints = np.asarray(
        linkopt.joint_positions(mech, linkopt.rest_state(mech), design=design)
    )
    for name in ("A_triangle", "A_c"):
        np.testing.assert_allclose(joints[mech.joint_names.index(name)][0], -40.0)
    path_solution = linkopt.solve_fk_path(
        mech, np.linspace(0, 1.0, 11)[:, None], design=design
    )
    assert np.all(path_solution.converged)
    moved = np.asarray(
        linkopt.joint_positions(mech, path_solution.state[-1], design=design)
    )
    np.testing.assert_allclose(
        moved[mech.joint_names.index("A_triangle")],
        moved[mech.joint_names.index("A_c")],
        atol=1e-9,
    )


def test_parameter_on_non_coincident_joints_is_rejected(tmp_path):
    path = tmp_path / "jansen_bad.toml"
    path.write_text(JANSEN + PIVOT_A.format(joints='["A_triangle", "O"]'))
    with pytest.raises(
        linkopt.MechanismFileError,
        match="parameters\\[0\\].joint: joints moved together must share their anchor",
    ):
        linkopt.load(path)


def test_public_names_resolve_and_match_the_type_checking_imports():
    """``linkopt`` imports its public names on first use (PEP 562); the eager imports
    kept for type checkers must name the same objects, or the two lists have drifted."""
    init = Path(linkopt.__file__)
    tree = ast.parse(init.read_text())
    block = next(
        node
        for node in tree.body
        if isinstance(node, ast.If) and getattr(node.test, "id", "") == "TYPE_CHECKING"
    )
    eager = {
        (alias.asname or alias.name): (stmt.module, alias.name)
        for stmt in block.body
        for alias in stmt.names
    }
    assert linkopt.__all__ == sorted(eager)
    for name in linkopt.__all__:  # the lazy name is the eagerly imported object
        module, attribute = eager[name]
        assert getattr(linkopt, name) is getattr(
            importlib.import_module(f"linkopt.{module}"), attribute
        )
