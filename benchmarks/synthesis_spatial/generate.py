"""Write the synthesis files of issue 41's breadth cases from their closed forms
and seeds (run from the repository root; the files are shipped, this script says
where their numbers come from):

* ``mechanisms/rssr.toml``: a spatial RSSR function generator. Its ``[synthesis]``
  table is the output angle of the RSSR with the *target* dimensions
  (:data:`RSSR_TARGET`) at nine crank angles, from the closed form of the RSSR
  input-output equation (:func:`rssr_output`); the file's own design differs.
* ``mechanisms/spherical_four_bar.toml``: a spherical crank-rocker (four revolute
  axes through the origin). Its ``[synthesis]`` path is the coupler point of the
  target link angles (:data:`SPHERICAL_TARGET`) at twelve crank angles, from the
  closed form of the spherical four-bar (:func:`spherical_coupler`).
* ``mechanisms/jansen_foot_path.toml``: the Jansen leg of
  ``mechanisms/jansen_1dof.toml`` with every one of its 13 lengths perturbed by up to
  ±5 % (seed :data:`JANSEN_SEED`) and reassembled by circle intersections on the
  same branch (:func:`jansen_joints`); its ``[synthesis]`` path is the shipped leg's
  foot point at 24 crank angles, traced by linkopt.

``python benchmarks/synthesis_spatial/generate.py`` rewrites the three files.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
MECHANISMS = ROOT / "mechanisms"

# ---------------------------------------------------------------- RSSR
#: Input axis z through the origin; output axis x through D (skew: 50 apart).
RSSR_D = np.array([0.0, 50.0, 20.0])
RSSR_OUTPUT_AXIS = np.array([1.0, 0.0, 0.0])
#: The file's design (B.x, C.y, C.z) and the target's.
RSSR_DESIGN = np.array([10.0, 25.0, 35.0])
RSSR_TARGET = np.array([11.5, 21.0, 36.5])
RSSR_BOUNDS = ((8.0, 13.0), (18.0, 30.0), (32.0, 40.0))
RSSR_C_X = 10.0
#: Crank angles of the function table (rad from the rest pose).
RSSR_INPUTS = np.linspace(-2.5, 2.5, 11)


def rotate(axis: np.ndarray, angle: float, v: np.ndarray) -> np.ndarray:
    """Rodrigues: ``v`` turned by ``angle`` about the unit ``axis``."""
    c, s = np.cos(angle), np.sin(angle)
    return v * c + np.cross(axis, v) * s + axis * (axis @ v) * (1.0 - c)


def _wrap(angle):
    return np.angle(np.exp(1j * np.asarray(angle)))


def rssr_roots(a, u, b0, d, w, c0, theta) -> np.ndarray:
    """The two output angles of an RSSR at input ``theta`` (both from the rest pose),
    in closed form: the crank turns ``b0`` about the unit axis ``u`` through ``a``,
    the rocker ``c0`` about ``w`` through ``d``, and ``|C − B|`` keeps its rest
    length ``L``. With ``r = c0 − d`` and ``q = d − B(θ)``, ``|q + R(φ) r|² = L²`` is
    ``P cos φ + Q sin φ = S``, ``P = q·r − (q·w)(w·r)``, ``Q = q·(w × r)``,
    ``S = (L² − |q|² − |r|²)/2 − (q·w)(w·r)``: ``φ = atan2(Q, P) ± acos(S/√(P²+Q²))``
    (NaN where the crank cannot reach ``theta``)."""
    r = c0 - d
    length2 = float((c0 - b0) @ (c0 - b0))
    q = d - (a + rotate(u, theta, b0 - a))
    p_ = q @ r - (q @ w) * (w @ r)
    q_ = q @ np.cross(w, r)
    s_ = (length2 - q @ q - r @ r) / 2.0 - (q @ w) * (w @ r)
    base = np.arctan2(q_, p_)
    with np.errstate(invalid="ignore"):
        spread = np.arccos(s_ / np.hypot(p_, q_))
    return _wrap(np.array([base + spread, base - spread]))


def rssr_output(a, u, b0, d, w, c0, thetas) -> np.ndarray:
    """The output angles at the inputs ``thetas`` on the rest pose's assembly: the
    root that is 0 at ``θ = 0``, the same sign of the ``acos`` term after it."""
    branch = int(np.argmin(np.abs(rssr_roots(a, u, b0, d, w, c0, 0.0))))
    return np.array([rssr_roots(a, u, b0, d, w, c0, t)[branch] for t in thetas])


def rssr_pins(design) -> tuple[np.ndarray, np.ndarray]:
    """B and C at rest for a design ``(B.x, C.y, C.z)``."""
    return np.array([design[0], 0.0, 0.0]), np.array([RSSR_C_X, design[1], design[2]])


def rssr_table(design, inputs) -> np.ndarray:
    b0, c0 = rssr_pins(design)
    z = np.array([0.0, 0.0, 1.0])
    return rssr_output(np.zeros(3), z, b0, RSSR_D, RSSR_OUTPUT_AXIS, c0, inputs)


# ---------------------------------------------------------------- spherical four-bar
#: Sphere radius (the joint anchors lie on it, at R times their axes).
SPHERE = 50.0
#: Link angles (rad): ground (A to D), crank (A to B), coupler (B to C), rocker
#: (D to C). Crank shortest and crank + ground < coupler + rocker: a crank-rocker.
SPHERICAL_GROUND = np.radians(70.0)
SPHERICAL_DESIGN = np.radians([25.0, 65.0, 55.0])
#: The target's crank and rocker angles (the file's design parameters).
SPHERICAL_TARGET = np.radians([22.0, 60.0])
SPHERICAL_COUNT = 12


def cone_meet(u: np.ndarray, v: np.ndarray, cu: float, cv: float, sign: float):
    """The unit vector ``x`` with ``x·u = cu`` and ``x·v = cv`` on the side ``sign``
    of ``u × v`` (NaN where the two cones do not meet)."""
    n = np.cross(u, v)
    g = u @ v
    x, y = np.linalg.solve(np.array([[1.0, g], [g, 1.0]]), [cu, cv])
    base = x * u + y * v
    with np.errstate(invalid="ignore"):
        z = np.sqrt((1.0 - base @ base) / (n @ n))
    return base + sign * z * n


def spherical_axes(crank: float, coupler: float, rocker: float):
    """The four unit axes at rest: A and D in the x-z plane, ``SPHERICAL_GROUND``
    apart; B turned ``crank`` from A towards +y; C where the coupler and rocker
    cones meet, on the +y side."""
    half = SPHERICAL_GROUND / 2.0
    a = np.array([-np.sin(half), 0.0, np.cos(half)])
    d = np.array([np.sin(half), 0.0, np.cos(half)])
    b = np.cos(crank) * a + np.sin(crank) * np.array([0.0, 1.0, 0.0])
    c = cone_meet(b, d, np.cos(coupler), np.cos(rocker), 1.0)
    return a, b, c, d


def frame(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """The orthonormal frame (columns) of two non-parallel unit vectors."""
    e1 = u
    e2 = v - (v @ u) * u
    e2 = e2 / np.linalg.norm(e2)
    return np.column_stack([e1, e2, np.cross(e1, e2)])


def spherical_coupler(axes, point: np.ndarray, thetas) -> np.ndarray:
    """The coupler point of a spherical four-bar at crank angles ``thetas`` (rad
    from rest), in closed form: the crank axis ``B(θ) = R(A, θ) B₀``; the coupler
    axis ``C`` the meeting of the cones about ``B`` (the coupler angle) and ``D``
    (the rocker angle) on the rest pose's side of ``B × D`` (the spherical
    counterpart of the planar circle intersection); the coupler's rotation the one
    taking the frame of ``(B₀, C₀)`` to that of ``(B, C)``, applied to ``point``."""
    a, b0, c0, d = axes
    side = np.sign(np.cross(b0, d) @ c0)
    rest = frame(b0, c0)
    rows = []
    for theta in thetas:
        b = rotate(a, theta, b0)
        c = cone_meet(b, d, b0 @ c0, d @ c0, side)
        rows.append(frame(b, c) @ rest.T @ point)
    return np.array(rows)


def spherical_point(axes) -> np.ndarray:
    """The coupler point at rest: on the sphere, off the great circle through B and
    C (a point of the coupler away from its joints)."""
    _, b, c, _ = axes
    v = b + c + 0.6 * np.cross(b, c)
    return SPHERE * v / np.linalg.norm(v)


# ---------------------------------------------------------------- Jansen leg
#: Jansen's 13 "holy numbers" (a, l: the frame; m: the crank). The foot tip's h and
#: i are not perturbed: the tip is a point of the foot, not a joint, and follows D
#: and F (``follow = "anchors"``).
JANSEN = dict(
    a=38.0, b=41.5, c=39.3, d=40.1, e=55.8, f=39.4, g=36.7,
    h=65.7, i=49.0, j=50.0, k=61.9, l=7.8, m=15.0,
)  # fmt: skip
JANSEN_SEED = 7
JANSEN_PERTURBATION = 0.05
JANSEN_COUNT = 24
#: The leg's moving joints and the ground pivot A: their x, y are the parameters.
JANSEN_JOINTS = ("C", "A", "B", "D", "E", "F")


def circles(p: np.ndarray, r: float, q: np.ndarray, s: float, side: float):
    """The meeting of the circle about ``p`` (radius ``r``) and about ``q`` (``s``)
    on the side ``side`` (+1: left of ``p → q``)."""
    gap = q - p
    dist = float(np.hypot(*gap))
    along = (r * r - s * s + dist * dist) / (2.0 * dist)
    across = np.sqrt(r * r - along * along)
    unit = gap / dist
    return p + along * unit + side * across * np.array([-unit[1], unit[0]])


def jansen_joints(lengths: dict) -> dict:
    """The leg's joints at crank angle 0 (crank along +x) for Jansen's lengths, on
    the branch of ``mechanisms/jansen_1dof.toml`` (its header): B above the line
    A → C, D below it, E left of A → B, F on the outer side of E → D, the foot G the
    lower intersection."""
    L = lengths
    o = np.zeros(2)
    a = np.array([-L["a"], -L["l"]])
    c = o + np.array([L["m"], 0.0])
    b = circles(a, L["b"], c, L["j"], 1.0)
    d = circles(a, L["c"], c, L["k"], -1.0)
    e = circles(a, L["d"], b, L["e"], 1.0)
    f = circles(e, L["f"], d, L["g"], -1.0)
    g = circles(f, L["h"], d, L["i"], -1.0)
    return dict(O=o, A=a, C=c, B=b, D=d, E=e, F=f, G=g)


def jansen_perturbed(seed: int = JANSEN_SEED) -> dict:
    """Each length scaled by a uniform factor in ``1 ± JANSEN_PERTURBATION``."""
    rng = np.random.default_rng(seed)
    factor = rng.uniform(1 - JANSEN_PERTURBATION, 1 + JANSEN_PERTURBATION, len(JANSEN))
    return {k: v if k in "hi" else v * f for (k, v), f in zip(JANSEN.items(), factor)}


# ---------------------------------------------------------------- the files
def _vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def _rows(rows, indent: str = "  ") -> str:
    return "\n".join(f"{indent}{_vec(r)}," for r in rows)


RSSR_HEAD = """\
# A spatial RSSR function generator (issue 41): a revolute input crank (axis z
# through the origin), a spherical-spherical coupler, a revolute output rocker on
# the axis x through D = (0, 50, 20), skew to the input axis (50 apart).
# The crank turns fully. The coupler's spin about its own line is fixed by the
# loader's gauge row (an idle spin).
# Design: the crank radius (B.x) and the rocker pin (C.y, C.z).
# [synthesis]: the output angle of the RSSR with (B.x, C.y, C.z) =
# ({t[0]:g}, {t[1]:g}, {t[2]:g}) at {n} crank angles from -2.5 to 2.5 rad, from the
# closed form of the RSSR input-output equation (P cos phi + Q sin phi = S;
# benchmarks/synthesis_spatial/generate.py, which writes this file).
# `linkopt synthesize mechanisms/rssr.toml --out runs/rssr` runs it.
[mechanism]
name = "RSSR function generator"
ground = "ground"
units = "mm"

[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "coupler"
[[bodies]]
name = "rocker"

[[joints]]
name = "A"
type = "revolute"
bodies = ["ground", "crank"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[joints]]
name = "B"
type = "spherical"
bodies = ["crank", "coupler"]
anchor = {b}

[[joints]]
name = "C"
type = "spherical"
bodies = ["coupler", "rocker"]
anchor = {c}

[[joints]]
name = "D"
type = "revolute"
bodies = ["ground", "rocker"]
anchor = {d}
axis = {w}

[[motors]]
name = "crank"
joint = "A"

[[outputs]]
name = "rocker"
joint = "D"
min = -1.0
max = 1.0

[[parameters]]
name = "crank_radius"
joint = "B"
coordinate = "x"
min = {bounds[0][0]}
max = {bounds[0][1]}

[[parameters]]
name = "pin_y"
joint = "C"
coordinate = "y"
min = {bounds[1][0]}
max = {bounds[1][1]}

[[parameters]]
name = "pin_z"
joint = "C"
coordinate = "z"
min = {bounds[2][0]}
max = {bounds[2][1]}

[synthesis]
kind = "function"
name = "rocker"
tolerance = 0.0035  # rad: under 1 % of the output's swing (0.398 rad)
points = [
{rows}
]
"""


def rssr_text() -> str:
    b, c = rssr_pins(RSSR_DESIGN)
    table = np.c_[RSSR_INPUTS, rssr_table(RSSR_TARGET, RSSR_INPUTS)]
    return RSSR_HEAD.format(
        t=RSSR_TARGET, n=len(RSSR_INPUTS), b=_vec(b), c=_vec(c), d=_vec(RSSR_D),
        w=_vec(RSSR_OUTPUT_AXIS), bounds=RSSR_BOUNDS, rows=_rows(table),
    )  # fmt: skip


SPHERICAL_HEAD = """\
# A spherical four-bar (issue 41): four revolute joints whose axes pass through the
# origin, each anchor on the sphere of radius {r:g} at {r:g} times its axis. Link
# angles: ground {g:g} deg (A to D), crank {a:g} (A to B), coupler {b:g} (B to C),
# rocker {c:g} (D to C): the crank is the shortest and crank + ground < coupler +
# rocker, a crank-rocker, so the crank turns fully.
# Design: the crank's and the rocker's link angles (twists).
# [synthesis]: the coupler point's closed curve for the crank and rocker angles
# ({ta:g}, {tc:g}) deg, at {n} crank angles, from the closed form of the spherical
# four-bar (the cones about B and D meet at C; benchmarks/synthesis_spatial/
# generate.py, which writes this file).
[mechanism]
name = "spherical four-bar"
ground = "ground"
units = "mm"

[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "coupler"
[[bodies]]
name = "rocker"
{joints}
[[motors]]
name = "crank"
joint = "A"

[[points]]
name = "coupler_point"
body = "coupler"
position = {p}

[[outputs]]
name = "rocker"
joint = "D"
min = -1.0
max = 1.0

[[parameters]]
name = "crank_angle"
kind = "twist"
body = "crank"
from = "A"
to = "B"
min = 0.3
max = 0.55

[[parameters]]
name = "rocker_angle"
kind = "twist"
body = "rocker"
from = "D"
to = "C"
min = 0.85
max = 1.15

[synthesis]
kind = "path"
name = "coupler_point"
closed = true
tolerance = 0.25  # mm: under 1 % of the curve's extent (28.8 mm)
points = [
{rows}
]
"""


def spherical_joints(axes) -> str:
    pairs = (("ground", "crank"), ("crank", "coupler"), ("coupler", "rocker"),
             ("ground", "rocker"))  # fmt: skip
    out = []
    for name, axis, bodies in zip("ABCD", axes, pairs):
        out.append(
            f'\n[[joints]]\nname = "{name}"\ntype = "revolute"\n'
            f'bodies = ["{bodies[0]}", "{bodies[1]}"]\n'
            f"anchor = {_vec(SPHERE * axis)}\naxis = {_vec(axis)}\n"
        )
    return "".join(out)


def spherical_target_axes():
    """The target's axes: crank and rocker angles of :data:`SPHERICAL_TARGET`, the
    coupler angle of the file's design (a twist turns B or C about the common
    normal of its link's axes, keeping the others)."""
    a, b0, c0, d = spherical_axes(*SPHERICAL_DESIGN)
    b = np.cos(SPHERICAL_TARGET[0]) * a + np.sin(SPHERICAL_TARGET[0]) * np.array(
        [0.0, 1.0, 0.0]
    )
    m = c0 - (c0 @ d) * d
    c = np.cos(SPHERICAL_TARGET[1]) * d + np.sin(
        SPHERICAL_TARGET[1]
    ) * m / np.linalg.norm(m)
    return a, b, c, d


def spherical_text() -> str:
    axes = spherical_axes(*SPHERICAL_DESIGN)
    point = spherical_point(axes)
    thetas = 2.0 * np.pi * np.arange(SPHERICAL_COUNT) / SPHERICAL_COUNT
    rows = spherical_coupler(spherical_target_axes(), point, thetas)
    deg = np.degrees
    return SPHERICAL_HEAD.format(
        r=SPHERE, g=deg(SPHERICAL_GROUND), a=deg(SPHERICAL_DESIGN[0]),
        b=deg(SPHERICAL_DESIGN[1]), c=deg(SPHERICAL_DESIGN[2]),
        ta=deg(SPHERICAL_TARGET[0]), tc=deg(SPHERICAL_TARGET[1]), n=SPHERICAL_COUNT,
        joints=spherical_joints(axes), p=_vec(point), rows=_rows(rows),
    )  # fmt: skip


JANSEN_PARAMETERS = """
# Design: x and y of the crank pin C, the second frame pivot A and the joints B, D,
# E, F (joints that share an anchor move together); the foot tip follows D and F.
"""

JANSEN_SYNTHESIS = """
# The shipped leg's foot path (mechanisms/jansen_1dof.toml), at {n} crank angles
# 15 degrees apart from the rest pose: the synthesis goes back to it from this
# file's perturbed design.
[synthesis]
kind = "path"
name = "foot"
closed = true
tolerance = 0.33  # cm: under 0.5 % of the stride (67.8 cm)
points = [
{rows}
]
"""

#: The file's α₋: the shipped leg's least forward σ_min over its turn is 0.034
#: (homogenised), so the synthesis objective's 2/σ_min stays below α₋ = 80 on it.
JANSEN_ALPHA_MINUS = 80.0
#: The parameters' bounds: each coordinate within this of the shipped leg's.
JANSEN_BOUND = 8.0


def jansen_parameters(joints: dict) -> str:
    names = {"C": "C_j", "A": "A_triangle", "B": "B", "D": "D_kc", "E": "E", "F": "F"}
    out = [JANSEN_PARAMETERS]
    for key in JANSEN_JOINTS:
        for k, axis in enumerate("xy"):
            value = float(joints[key][k])
            out.append(
                f'\n[[parameters]]\nname = "{key}_{axis}"\njoint = "{names[key]}"\n'
                f'coordinate = "{axis}"\nmin = {value - JANSEN_BOUND!r}\n'
                f"max = {value + JANSEN_BOUND!r}\n"
            )
    return "".join(out)


def jansen_foot_path(mech) -> np.ndarray:
    """The foot point of ``mech``'s file design at :data:`JANSEN_COUNT` crank angles
    over one turn from rest, traced by continuation."""
    import linkopt

    angles = 2.0 * np.pi * np.arange(JANSEN_COUNT + 1) / JANSEN_COUNT
    sol = linkopt.solve_fk_path(mech, angles[:, None])
    assert bool(np.all(sol.converged)), "the shipped leg turns fully"
    return linkopt.named_points(mech, sol.state)["foot"][:JANSEN_COUNT]


def jansen_design(joints: dict) -> np.ndarray:
    return np.concatenate([joints[key] for key in JANSEN_JOINTS])


def jansen_text(path: Path) -> str:
    """The shipped leg with its parameters and the foot-path target."""
    import linkopt

    text = (MECHANISMS / "jansen_1dof.toml").read_text()
    text = text.replace(
        'body = "foot"\nposition', 'body = "foot"\nfollow = "anchors"\nposition'
    )
    text += jansen_parameters(jansen_joints(JANSEN))
    shipped = linkopt.loads(text, source=str(path))
    rows = jansen_foot_path(shipped)[:, :2]
    return text + JANSEN_SYNTHESIS.format(n=JANSEN_COUNT, rows=_rows(rows))


def jansen_write(path: Path) -> None:
    """``mechanisms/jansen_foot_path.toml``: :func:`jansen_text` written at the
    perturbed design."""
    import linkopt

    mech = linkopt.loads(jansen_text(path), source=str(path))
    design = jansen_design(jansen_joints(jansen_perturbed()))
    # write_design keeps the source file's header below this one: the source is the
    # file being replaced, whose header is this one already (it was kept three times)
    path.unlink(missing_ok=True)
    header = (
        "Issue 41's Jansen case: mechanisms/jansen_1dof.toml with each of its link\n"
        f"lengths a..g, j..m scaled by a factor in 1 +- {JANSEN_PERTURBATION:g} (seed "
        f"{JANSEN_SEED}) and\nreassembled on the same branch; the [synthesis] target "
        "is the shipped leg's foot path.\nWritten by "
        "benchmarks/synthesis_spatial/generate.py."
    )
    linkopt.write_design(mech, design, JANSEN_ALPHA_MINUS, path, header=header)


def main() -> None:
    (MECHANISMS / "rssr.toml").write_text(rssr_text())
    (MECHANISMS / "spherical_four_bar.toml").write_text(spherical_text())
    jansen_write(MECHANISMS / "jansen_foot_path.toml")
    print("wrote mechanisms/rssr.toml, spherical_four_bar.toml, jansen_foot_path.toml")


if __name__ == "__main__":
    main()
