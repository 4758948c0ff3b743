"""Design parameters a designer can state (issue 20, part 3): rotated copies under an
n-fold symmetry, ties between different anchors, link lengths and radii. Each is a
linear map of the DesignSpace: it moves the anchors it should (closed forms), keeps
the rest pose assembled, has implicit-function sensitivities that match finite
differences, and survives a write and a reload; malformed ones name their field."""

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine.constraints import passive_residual
from linkopt._engine.geometry import geometry, rest_state
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build
from linkopt._files.writer import design_definition, dumps


def rotation(k: int, order: int = 3) -> np.ndarray:
    """The rotation by 2πk/order about z."""
    a = 2.0 * np.pi * k / order
    return np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])


def vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


#: A planar 3-RRR parallel robot with 3-fold symmetry: arm k's base, elbow and
#: platform joints are the images of arm 0's under the rotation by 120k degrees.
REST = {"base": [60.0, 0, 0], "elbow": [55.0, 30.0, 0], "plat": [7.5, 12.99, 0]}
SYMMETRY = """
[symmetry]
kind = "rotation"
axis = [0.0, 0.0, 1.0]
point = [0.0, 0.0, 0.0]
order = 3
"""


def _joint(name: str, k: int, bodies: tuple[str, str]) -> str:
    anchor = rotation(k) @ np.array(REST[name])
    return (
        f'[[joints]]\nname = "{name}{k}"\ntype = "revolute"\n'
        f'bodies = ["{bodies[0]}", "{bodies[1]}"]\nanchor = {vec(anchor)}\n'
        "axis = [0.0, 0.0, 1.0]\n"
    )


def three_rrr(parameters: str = "", symmetry: str = SYMMETRY) -> str:
    """The TOML text of the 3-RRR with ``parameters`` appended."""
    out = ['[mechanism]\nname = "3-RRR"\nground = "ground"\n']
    names = ["ground", "platform"] + [
        f"{n}{k}" for k in range(3) for n in ("crank", "distal")
    ]
    out += [f'[[bodies]]\nname = "{b}"\n' for b in names]
    for k in range(3):
        out.append(_joint("base", k, ("ground", f"crank{k}")))
        out.append(_joint("elbow", k, (f"crank{k}", f"distal{k}")))
        out.append(_joint("plat", k, (f"distal{k}", "platform")))
        out.append(f'[[motors]]\nname = "m{k}"\njoint = "base{k}"\n')
    out.append('[[points]]\nname = "c"\nbody = "platform"\nposition = [0.0, 0, 0]\n')
    for axis in "xy":
        out.append(
            f'[[outputs]]\nname = "{axis}"\npoint = "c"\ncoordinate = "{axis}"\n'
            "min = -5.0\nmax = 5.0\n"
        )
    out.append('[[outputs]]\nname = "phi"\njoint = "elbow0"\nmin = -0.5\nmax = 0.5\n')
    return "\n".join(out) + symmetry + parameters


RADIUS = """
[[parameters]]
name = "base_radius"
kind = "radius"
joints = ["base0", "base1", "base2"]
center = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
min = 50.0
max = 70.0
"""
COPIES = """
[[parameters]]
name = "plat_x"
joint = "plat0"
coordinate = "x"
min = 0.0
max = 12.0
copies = ["plat1", "plat2"]
"""
TIE = """
[[parameters]]
name = "elbow_y"
joint = "elbow0"
coordinate = "y"
min = 20.0
max = 40.0
ties = [{ joint = "elbow1", coordinate = "x", factor = -0.5 }]
"""
CRANK = """
[[parameters]]
name = "crank"
kind = "length"
body = "crank0"
from = "base0"
to = "elbow0"
min = 20.0
max = 40.0
copies = ["crank1", "crank2"]
"""
DISTAL = """
[[parameters]]
name = "distal"
kind = "length"
body = "distal0"
from = "elbow0"
to = "plat0"
min = 40.0
max = 60.0
copies = ["distal1", "distal2"]
"""
#: The five-bar, its crank lengths a parameter under its mirror symmetry.
FIVE_BAR = (MECHANISMS / "five_bar.toml").read_text()
FIVE_BAR_CRANK = FIVE_BAR.split("[[parameters]]")[0] + (
    '[[parameters]]\nname = "crank"\nkind = "length"\nbody = "crank_right"\n'
    'from = "base_right"\nto = "elbow_right"\nmin = 30.0\nmax = 60.0\n'
    'copies = ["crank_left"]\n'
)
TEXTS = {
    "copies_ties_radius": three_rrr(RADIUS + COPIES + TIE),
    "lengths_radius": three_rrr(RADIUS + CRANK + DISTAL),
    "five_bar_crank": FIVE_BAR_CRANK,
}


def parsed(text: str, source: str = "<test>") -> linkopt.Mechanism:
    """The mechanism without the mobility check (pure numpy: no compilation)."""
    return build(parse_toml(text, source), source, check=False)


def anchors(mech, design) -> np.ndarray:
    return np.asarray(geometry(mech, design).anchors) * mech.length_scale


def perturbed(mech, count: int, seed: int = 0) -> np.ndarray:
    """``count`` designs drawn inside the bounds (seeded)."""
    rng = np.random.default_rng(seed)
    d = mech.design
    return d.lower + rng.uniform(0.1, 0.9, (count, d.size)) * (d.upper - d.lower)


@pytest.fixture(scope="module")
def loaded():
    """The two 3-RRR design spaces, loaded with the mobility and rest checks."""
    return {name: linkopt.loads(TEXTS[name], name) for name in list(TEXTS)[:2]}


def test_rotated_copies_and_ties_move_the_expected_anchors():
    mech = parsed(TEXTS["copies_ties_radius"])
    index = {n: k for k, n in enumerate(mech.joint_names)}
    design = mech.design.p0 + np.array([3.0, 2.0, -4.0])
    moved, rest = anchors(mech, design), mech.anchors
    for k in range(3):  # the platform joints stay the rotated images of plat0
        np.testing.assert_allclose(
            moved[index[f"plat{k}"]], rotation(k) @ moved[index["plat0"]], atol=1e-12
        )
    assert moved[index["plat0"]][0] == pytest.approx(design[1], abs=1e-12)
    assert moved[index["elbow0"]][1] == pytest.approx(design[2], abs=1e-12)
    np.testing.assert_allclose(  # the tie: elbow1.x moves by -0.5 of elbow0.y's change
        moved[index["elbow1"]] - rest[index["elbow1"]], [2.0, 0, 0], atol=1e-12
    )
    np.testing.assert_allclose(moved[index["elbow2"]], rest[index["elbow2"]], atol=0)


def test_copies_may_be_listed_in_any_order():
    """Each copy is matched to the symmetry element that maps onto it."""
    swapped = {
        name: parsed(TEXTS[name].replace(a, b))
        for name, a, b in (
            ("copies_ties_radius", '["plat1", "plat2"]', '["plat2", "plat1"]'),
            ("lengths_radius", '["crank1", "crank2"]', '["crank2", "crank1"]'),
        )
    }
    for name, mech in swapped.items():
        np.testing.assert_array_equal(
            mech.design.matrix, parsed(TEXTS[name]).design.matrix
        )


def hexapod(parameters: str, prismatic: bool = False) -> str:
    """Six spherical-jointed legs between a base hexagon (radius 100, at 120k +- 15
    degrees) and a hub hexagon (radius 60, at 60 + 120k -+ 15 degrees, 50 above): the
    Stewart platform's layout, symmetric under the rotations by 120 degrees and the
    mirror y = 0 (the dihedral group D3). With ``prismatic`` each leg is a cylinder
    and a piston joined by a prismatic joint ``p{i}`` a third of the way up."""
    out = ['[mechanism]\nname = "hexapod"\nground = "ground"\n']
    out += [f'[[bodies]]\nname = "{b}"\n' for b in ["ground", "hub"]]
    for i in range(6):
        k, sign = divmod(i, 2)
        sign = 1 if sign == 0 else -1
        base = np.radians(120 * k + 15 * sign)
        top = np.radians(120 * k + 45 * sign)
        legs = [f"cyl{i}", f"pis{i}"] if prismatic else [f"leg{i}"] * 2
        out += [f'[[bodies]]\nname = "{b}"\n' for b in sorted(set(legs))]
        for name, bodies, r, a, z in (
            ("g", ("ground", legs[0]), 100.0, base, 0.0),
            ("t", (legs[1], "hub"), 60.0, top, 50.0),
        ):
            anchor = [r * np.cos(a), r * np.sin(a), z]
            out.append(
                f'[[joints]]\nname = "{name}{i}"\ntype = "spherical"\n'
                f'bodies = ["{bodies[0]}", "{bodies[1]}"]\nanchor = {vec(anchor)}\n'
            )
        if prismatic:
            g = np.array([100 * np.cos(base), 100 * np.sin(base), 0.0])
            t = np.array([60 * np.cos(top), 60 * np.sin(top), 50.0])
            out.append(
                f'[[joints]]\nname = "p{i}"\ntype = "prismatic"\n'
                f'bodies = ["cyl{i}", "pis{i}"]\nanchor = {vec(g + (t - g) / 3)}\n'
                f"axis = {vec((t - g) / np.linalg.norm(t - g))}\n"
            )
    out.append(  # a motor, for the loader: only the design map is tested here
        '[[bodies]]\nname = "crank"\n[[joints]]\nname = "drive"\ntype = "revolute"\n'
        'bodies = ["ground", "crank"]\nanchor = [0.0, 0.0, -20.0]\n'
        'axis = [0.0, 0.0, 1.0]\n[[motors]]\nname = "m"\njoint = "drive"\n'
        '[[outputs]]\nname = "a"\njoint = "drive"\nmin = -1.0\nmax = 1.0\n'
    )
    out.append(
        '[symmetry]\nkind = "rotation"\naxis = [0.0, 0.0, 1.0]\n'
        "point = [0.0, 0.0, 0.0]\norder = 3\nnormal = [0.0, 1.0, 0.0]\n"
    )
    return "\n".join(out) + parameters


HEXAPOD = hexapod(
    """
[[parameters]]
name = "leg"
kind = "length"
body = "leg0"
from = "g0"
to = "t0"
min = 50.0
max = 150.0
copies = ["leg5", "leg1", "leg3", "leg2", "leg4"]

[[parameters]]
name = "base_radius"
kind = "radius"
joints = ["g0", "g1", "g2", "g3", "g4", "g5"]
center = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
min = 80.0
max = 120.0
"""
)

TEXTS["hexapod"] = HEXAPOD
TEXTS["prismatic_legs"] = hexapod(
    RADIUS.replace("base0", "g0")
    .replace('"base1", "base2"', '"g1", "g2", "g3", "g4", "g5"')
    .replace("min = 50.0\nmax = 70.0", "min = 80.0\nmax = 120.0")
    + RADIUS.replace("base_radius", "hub_radius")
    .replace('"base0", "base1", "base2"', '"t0", "t1", "t2", "t3", "t4", "t5"')
    .replace("center = [0.0, 0.0, 0.0]", "center = [0.0, 0.0, 50.0]")
    .replace("min = 50.0\nmax = 70.0", "min = 40.0\nmax = 80.0"),
    prismatic=True,
)


def test_a_straight_leg_stays_straight():
    """Radii move a prismatic leg's ends; its joint stays a third of the way up and
    its axis along the leg."""
    mech = parsed(TEXTS["prismatic_legs"])
    index = {n: k for k, n in enumerate(mech.joint_names)}
    for design in perturbed(mech, 3):
        geom = geometry(mech, design)
        moved = np.asarray(geom.anchors) * mech.length_scale
        for i in range(6):
            g, p, t = (moved[index[f"{n}{i}"]] for n in "gpt")
            np.testing.assert_allclose(p, g + (t - g) / 3, atol=1e-12)
            axis = np.asarray(geom.axes)[index[f"p{i}"]]
            np.testing.assert_allclose(
                axis, (t - g) / np.linalg.norm(t - g), atol=1e-14
            )
            assert np.hypot(*g[:2]) == pytest.approx(design[0], rel=1e-14)
            assert np.hypot(*t[:2]) == pytest.approx(design[1], rel=1e-14)


def test_a_dihedral_copy_set_moves_all_six_legs_alike():
    """Under D3 the mirrored legs are copies too: every leg keeps the length, and the
    moved hexagons stay D3-symmetric."""
    mech = parsed(HEXAPOD)
    index = {n: k for k, n in enumerate(mech.joint_names)}
    flip = np.diag([1.0, -1.0, 1.0])
    for leg, radius in perturbed(mech, 3):
        moved = anchors(mech, [leg, radius])
        for i in range(6):
            g, t = moved[index[f"g{i}"]], moved[index[f"t{i}"]]
            assert np.linalg.norm(t - g) == pytest.approx(leg, rel=1e-14)
            assert np.hypot(*g[:2]) == pytest.approx(radius, rel=1e-14)
            k, side = divmod(i, 2)
            image = rotation(k) @ (
                moved[index["t0"]] if side == 0 else flip @ moved[index["t0"]]
            )
            np.testing.assert_allclose(t, image, atol=1e-12)


@pytest.mark.parametrize("name", list(TEXTS)[:2])
def test_a_radius_parameter_is_the_distance_to_the_axis(name):
    mech = parsed(TEXTS[name])
    for design in perturbed(mech, 3):
        bases = anchors(mech, design)[
            [mech.joint_names.index(f"base{k}") for k in range(3)]
        ]
        np.testing.assert_allclose(np.hypot(*bases[:, :2].T), design[0], atol=1e-12)
        angles = np.arctan2(bases[:, 1], bases[:, 0])  # moved radially: same angles
        np.testing.assert_allclose(
            angles, 2 * np.pi * np.array([0, 1, -1]) / 3, atol=1e-14
        )


def test_length_parameters_are_the_link_lengths_of_every_arm():
    """A chain of lengths (crank from the base, distal from the elbow) composes: each
    link keeps its length while the links before it change."""
    mech = parsed(TEXTS["lengths_radius"])
    index = {n: k for k, n in enumerate(mech.joint_names)}
    rest = mech.anchors
    for radius, crank, distal in perturbed(mech, 4):
        moved = anchors(mech, [radius, crank, distal])
        for k in range(3):
            b, e, p = (index[f"{n}{k}"] for n in ("base", "elbow", "plat"))
            assert np.linalg.norm(moved[e] - moved[b]) == pytest.approx(
                crank, rel=1e-14
            )
            assert np.linalg.norm(moved[p] - moved[e]) == pytest.approx(
                distal, rel=1e-14
            )
            for a, z in ((b, e), (e, p)):  # along the rest direction of the link
                np.testing.assert_allclose(
                    np.cross(moved[z] - moved[a], rest[z] - rest[a]), 0, atol=1e-10
                )
            np.testing.assert_allclose(
                moved[p], rotation(k) @ moved[index["plat0"]], atol=1e-12
            )


def test_a_mirrored_length_is_the_length_of_both_cranks():
    mech = parsed(FIVE_BAR_CRANK)
    assert mech.design.p0[0] == pytest.approx(np.hypot(17.0, 36.0), rel=1e-15)
    moved = anchors(mech, [50.0])
    left, right = (
        moved[mech.joint_names.index(f"elbow_{s}")]
        - moved[mech.joint_names.index(f"base_{s}")]
        for s in ("left", "right")
    )
    assert np.linalg.norm(left) == pytest.approx(50.0, rel=1e-14)
    np.testing.assert_allclose(left, right * [-1, 1, 1], atol=1e-12)


@pytest.mark.parametrize("name", list(TEXTS))
def test_every_design_keeps_the_rest_pose_assembled(name):
    mech = parsed(TEXTS[name])
    state = rest_state(mech)
    for design in perturbed(mech, 5, seed=1):
        residual = np.asarray(passive_residual(mech, geometry(mech, design), state))
        assert np.abs(residual).max() < 1e-14
        assert np.abs(anchors(mech, design) - mech.anchors).max() > 0.1


@pytest.mark.parametrize("name", list(TEXTS))
def test_a_written_design_reads_back_as_the_same_design(name):
    """load -> set a design -> write -> load: the same geometry, the design as the new
    file's initial design, and the same map for any further design."""
    mech = parsed(TEXTS[name])
    design, later = perturbed(mech, 2, seed=2)
    text = dumps(design_definition(mech, design, alpha_minus=1.0))
    again = parsed(text, "written")
    np.testing.assert_allclose(again.design.p0, design, rtol=1e-13)
    np.testing.assert_allclose(anchors(again, None), anchors(mech, design), atol=1e-12)
    for p in (later, mech.design.lower, mech.design.upper):
        np.testing.assert_allclose(anchors(again, p), anchors(mech, p), atol=1e-12)
        axes, axes_again = (np.asarray(geometry(m, p).axes) for m in (mech, again))
        np.testing.assert_allclose(axes_again, axes, atol=1e-14)


@pytest.mark.parametrize("name", list(TEXTS)[:2])
def test_sensitivities_match_finite_differences(loaded, name):
    """ds/dp (implicit function theorem) and d(outputs)/dp at fixed motors, against
    central differences of FK re-solved at each design."""
    import jax

    mech = loaded[name]
    motors = np.array([0.1, 0.05, -0.1])
    state = linkopt.solve_fk(mech, motors).state
    exact = np.asarray(linkopt.sensitivity(mech, state, "design"))
    p0, h = mech.design.p0, 1e-3

    def solve(p):
        return np.asarray(linkopt.solve_fk(mech, motors, start=state, design=p).state)

    def outputs(s):
        return linkopt.output_values(mech, s)

    fd_states, fd_outputs = [], []
    for e in np.eye(p0.size):
        plus, minus = solve(p0 + h * e), solve(p0 - h * e)
        fd_states.append((plus - minus) / (2 * h))
        fd_outputs.append(
            (np.asarray(outputs(plus)) - np.asarray(outputs(minus))) / (2 * h)
        )
    fd_states, fd_outputs = np.stack(fd_states, 1), np.stack(fd_outputs, 1)
    d_outputs = np.asarray(jax.jacfwd(outputs)(state)) @ exact
    for got, want in ((exact, fd_states), (d_outputs, fd_outputs)):
        assert np.abs(want).max() > 1e-3
        np.testing.assert_allclose(got, want, rtol=1e-6, atol=1e-6 * np.abs(want).max())


def test_a_joint_sharing_an_anchor_moves_with_it():
    """Jansen's C_j and C_k are one point at rest: a tie naming only C_k, or a radius
    through C_j, moves both."""
    jansen = (MECHANISMS / "jansen_1dof.toml").read_text()
    mech = parsed(jansen)
    c_j, c_k = (mech.joint_names.index(n) for n in ("C_j", "C_k"))
    a = mech.anchors
    radius = float(np.hypot(*a[c_j][:2]))
    tie = f"""
[[parameters]]
name = "o_x"
joint = "O"
coordinate = "x"
min = -100.0
max = 100.0
ties = [{{ joint = "C_k", coordinate = "y", factor = 2.0 }}]

[[parameters]]
name = "r"
kind = "radius"
joints = ["C_j"]
center = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
min = {radius / 2}
max = {radius * 2}
"""
    mech = parsed(jansen + tie)
    rows = mech.design.matrix[: 3 * len(a)].reshape(len(a), 3, -1)
    np.testing.assert_array_equal(rows[c_j], rows[c_k])
    assert rows[c_k][1, 0] == 2.0 and np.abs(rows[c_k][:, 1]).max() > 0.1


def edit(text: str, old: str, new: str) -> str:
    assert text.count(old) == 1, old
    return text.replace(old, new)


A, B = TEXTS["copies_ties_radius"], TEXTS["lengths_radius"]
MALFORMED = {
    "unknown_kind": (
        edit(A, 'kind = "radius"', 'kind = "angle"'),
        "parameters[0].kind",
        "expected one of ['coordinate', 'length', 'radius', 'twist', 'offset', "
        "'point'], got 'angle'",
    ),
    "unknown_symmetry": (
        edit(A, 'kind = "rotation"', 'kind = "helix"'),
        "[symmetry].kind",
        "expected 'mirror' or 'rotation'",
    ),
    "order_one": (
        edit(A, "order = 3", "order = 1"),
        "[symmetry].order",
        "expected an integer from 2 to 360",
    ),
    "rotation_without_axis": (
        edit(A, "axis = [0.0, 0.0, 1.0]\npoint", "point"),
        "[symmetry].axis",
        "missing required field",
    ),
    "copy_not_an_image": (
        edit(A, '["plat1", "plat2"]', '["plat1", "elbow2"]'),
        "parameters[1].copies[1]",
        "anchor of 'elbow2' is not an image of 'plat0' under the [symmetry]; the "
        "nearest, its image under the rotation by 240 degrees, is [",
    ),
    "copies_without_symmetry": (
        three_rrr(COPIES, symmetry=""),
        "parameters[0].copies",
        "copies need a [symmetry] table",
    ),
    "too_many_copies": (
        edit(A, '["plat1", "plat2"]', '["plat1", "plat2", "base0"]'),
        "parameters[1].copies",
        "expected a list of 1 to 2 names",
    ),
    "own_copy": (
        edit(A, '["plat1", "plat2"]', '["plat0"]'),
        "parameters[1].copies[0]",
        "a joint cannot be its own copy",
    ),
    "mirror_under_rotation": (
        edit(A, 'copies = ["plat1", "plat2"]', 'mirror = "plat1"'),
        "parameters[1].mirror",
        "under a rotation, use copies",
    ),
    "tie_unknown_joint": (
        edit(A, 'joint = "elbow1"', 'joint = "elbow9"'),
        "parameters[2].ties[0].joint",
        "unknown joint 'elbow9'",
    ),
    "tie_zero_factor": (
        edit(A, "factor = -0.5", "factor = 0.0"),
        "parameters[2].ties[0].factor",
        "expected a non-zero factor",
    ),
    "tie_axis_with_anchor": (
        edit(A, 'coordinate = "x", factor', 'coordinate = "axis_x", factor'),
        "parameters[2].ties[0].coordinate",
        "a tie moves the same kind of coordinate",
    ),
    "tie_missing_factor": (
        edit(A, ", factor = -0.5 }", " }"),
        "parameters[2].ties[0].factor",
        "missing required field",
    ),
    "ties_not_a_list": (
        edit(
            A,
            'ties = [{ joint = "elbow1", coordinate = "x", factor = -0.5 }]',
            "ties = 3",
        ),
        "parameters[2].ties",
        "expected a non-empty list of tables",
    ),
    "tie_on_own_coordinate": (
        edit(
            A,
            'joint = "elbow1", coordinate = "x"',
            'joint = "elbow0", coordinate = "y"',
        ),
        "parameters[2].ties[0]",
        "ties a coordinate this parameter already drives",
    ),
    "length_from_off_body": (
        edit(B, 'from = "base0"', 'from = "base1"'),
        "parameters[1].from",
        "joint 'base1' is not a joint of body 'crank0'",
    ),
    "length_unknown_body": (
        edit(B, 'body = "crank0"', 'body = "crank7"'),
        "parameters[1].body",
        "unknown body 'crank7'",
    ),
    "length_to_is_from": (
        edit(B, 'to = "elbow0"', 'to = "base0"'),
        "parameters[1].to",
        "a joint is listed twice (or is also from)",
    ),
    "length_copy_not_an_image": (
        edit(B, '["crank1", "crank2"]', '["crank1", "distal2"]'),
        "parameters[1].copies[1]",
        "body 'distal2' has no joints at an image of 'base0' and 'elbow0'",
    ),
    "mirror_plane_off_the_axis": (
        edit(A, "order = 3", "order = 3\nnormal = [0.0, 0.6, 0.8]"),
        "[symmetry].normal",
        "the mirror plane of a rotation must contain its axis",
    ),
    "length_non_positive_min": (
        edit(B, "min = 20.0", "min = -1.0"),
        "parameters[1].min",
        "a link length needs min > 0",
    ),
    "length_rest_outside_bounds": (
        edit(B, "min = 20.0", "min = 31.0"),
        "parameters[1].min",
        "the rest value 30.4138 of the link length lies outside [31, 40]",
    ),
    "length_loop": (
        three_rrr(
            CRANK
            + CRANK.replace('"crank"', '"back"')
            .replace('from = "base0"\nto = "elbow0"', 'from = "elbow0"\nto = "base0"')
            .replace("min = 20.0", "min = 10.0")
        ),
        "parameters[0]",
        "length parameters form a loop",
    ),
    "radius_on_the_axis": (
        edit(A, "center = [0.0, 0.0, 0.0]", "center = [60.0, 0.0, 0.0]"),
        "parameters[0].joints",
        "joint 'base0' lies on the axis",
    ),
    "radius_not_a_circle": (
        edit(A, 'joints = ["base0", "base1", "base2"]', 'joints = ["base0", "elbow1"]'),
        "parameters[0].joints",
        "expected joints on one circle",
    ),
    "radius_no_joints": (
        edit(A, 'joints = ["base0", "base1", "base2"]', "joints = []"),
        "parameters[0].joints",
        "expected a non-empty list of joints",
    ),
    "radius_zero_axis": (
        edit(A, "axis = [0.0, 0.0, 1.0]\nmin", "axis = [0.0, 0.0, 0.0]\nmin"),
        "parameters[0].axis",
        "zero-length axis",
    ),
    "radius_unknown_joint": (
        edit(A, '"base0", "base1", "base2"', '"base0", "bass1"'),
        "parameters[0].joints",
        "unknown joint 'bass1'",
    ),
    "two_parameters_on_one_coordinate": (
        three_rrr(
            RADIUS
            + COPIES.replace("plat", "base")
            .replace("max = 12.0", "max = 70.0")
            .replace("min = 0.0", "min = 50.0")
        ),
        "parameters[1]",
        "drives a coordinate already driven by parameters[0]",
    ),
    "mirrored_length_on_the_plane": (
        FIVE_BAR.split("[[parameters]]")[0]
        + '[[parameters]]\nname = "distal"\nkind = "length"\nbody = "distal_right"\n'
        'from = "elbow_right"\nto = "tip"\nmin = 30.0\nmax = 60.0\n'
        'copies = ["distal_left"]\n',
        "parameters[0].copies[0]",
        "joint 'tip' is its own mirror image",
    ),
}


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_a_malformed_parameter_names_its_field(name):
    text, where, words = MALFORMED[name]
    with pytest.raises(linkopt.MechanismFileError) as info:
        parsed(text, "bad.toml")
    message = str(info.value)
    assert message.startswith(f"bad.toml: {where}: ") and words in message, message
    assert "\n" not in message


def test_coincident_joints_moved_differently_are_refused():
    jansen = (MECHANISMS / "jansen_1dof.toml").read_text()
    text = jansen + (
        '[[parameters]]\nname = "c"\njoint = "C_j"\ncoordinate = "x"\nmin = -100.0\n'
        'max = 100.0\nties = [{ joint = "C_k", coordinate = "y", factor = 1.0 }]\n'
    )
    with pytest.raises(linkopt.MechanismFileError, match="share their anchor at rest"):
        parsed(text, "bad.toml")
