"""A strandbeest as mechanism-file text: one crank driving ``legs`` Jansen legs
(``mechanisms/strandbeest_12.toml`` is :func:`strandbeest` of 12, written by
``benchmarks/make_strandbeest.py``; ``tests/test_arrowhead.py`` solves smaller ones).

Each leg is ``mechanisms/jansen_1dof.toml``'s (Jansen's link lengths, six moving
bodies); every leg hangs from the same ``ground`` (its frame pivot A) and the same
``crank`` (its crank pin C), so those two bodies are joined to every other: the
arrowhead of :mod:`linkopt._engine.arrowhead`.

Phasing, as Jansen's walkers: legs come in mirrored pairs (one leg and its mirror
image across the plane x = 0, frame pivots at ``(∓38, -7.8)``) sharing one crank pin,
and the pins sit on one crank at multiples of ``360° / (legs / 2)``: for 12 legs six
pins 60° apart, i.e. three phases 120° apart on each side of the animal and the two
sides half a turn apart. The model is planar (every joint turns about z, every anchor
in z = 0): the legs' depth along the crank shaft plays no part in their kinematics, and
leaving it out lets the frame pivots of all legs on one side coincide, so one
parameter moves them all (a mirrored ``[symmetry]`` moves the other side).
"""

from __future__ import annotations

import numpy as np

#: Jansen's "holy numbers" (cm).
LENGTHS = dict(
    a=38.0, b=41.5, c=39.3, d=40.1, e=55.8, f=39.4, g=36.7,
    h=65.7, i=49.0, j=50.0, k=61.9, l=7.8, m=15.0,
)  # fmt: skip
PIVOT = np.array([-LENGTHS["a"], -LENGTHS["l"]])  # frame pivot A of a left leg


def _cross(u, v) -> float:
    return float(u[0] * v[1] - u[1] * v[0])


def _circles(p1, r1: float, p2, r2: float, side: float) -> np.ndarray:
    """The point at distance ``r1`` from ``p1`` and ``r2`` from ``p2`` on the ``side``
    (+1 left, -1 right) of the line from ``p1`` to ``p2``."""
    gap = p2 - p1
    dist = float(np.hypot(*gap))
    along = (r1**2 - r2**2 + dist**2) / (2.0 * dist)
    across = np.sqrt(r1**2 - along**2)
    unit = gap / dist
    normal = np.array([-unit[1], unit[0]])
    return p1 + along * unit + side * across * normal


def leg(angle: float) -> dict[str, np.ndarray]:
    """The joints of a left leg (frame pivot at ``PIVOT``) with its crank pin at
    ``angle`` rad from +x: Jansen's assembly branch, as ``jansen_1dof.toml``."""
    n = LENGTHS
    a, c = PIVOT, n["m"] * np.array([np.cos(angle), np.sin(angle)])
    b = _circles(a, n["b"], c, n["j"], +1.0)  # above the line A -> C
    d = _circles(a, n["c"], c, n["k"], -1.0)  # below it
    e = _circles(a, n["d"], b, n["e"], +1.0)  # left of A -> B
    f = _circles(e, n["f"], d, n["g"], -1.0)  # right of E -> D
    g = _circles(d, n["i"], f, n["h"], +1.0)  # the foot, left of D -> F
    return dict(A=a, C=c, B=b, D=d, E=e, F=f, G=g)


def mirrored_leg(angle: float) -> dict[str, np.ndarray]:
    """The right leg driven by the pin at ``angle``: the mirror image (x -> -x) of
    the left leg whose pin is the mirror image of this one."""
    flip = np.array([-1.0, 1.0])
    return {k: v * flip for k, v in leg(np.pi - angle).items()}


def _body(name: str) -> str:
    return f'[[bodies]]\nname = "{name}"\n'


def _joint(name: str, first: str, second: str, at) -> str:
    x, y = (float(v) for v in at)
    return (
        f'[[joints]]\nname = "{name}"\ntype = "revolute"\n'
        f'bodies = ["{first}", "{second}"]\n'
        f"anchor = [{x!r}, {y!r}, 0.0]\naxis = [0.0, 0.0, 1.0]\n"
    )


def _leg_text(index: int, at: dict[str, np.ndarray]) -> tuple[list[str], list[str]]:
    s = f"_{index}"
    bodies = [_body(b + s) for b in ("j", "k", "triangle", "c", "f", "foot")]
    joints = [
        _joint("C_j" + s, "crank", "j" + s, at["C"]),
        _joint("C_k" + s, "crank", "k" + s, at["C"]),
        _joint("A_triangle" + s, "ground", "triangle" + s, at["A"]),
        _joint("A_c" + s, "ground", "c" + s, at["A"]),
        _joint("B" + s, "j" + s, "triangle" + s, at["B"]),
        _joint("D_kc" + s, "k" + s, "c" + s, at["D"]),
        _joint("D_foot" + s, "c" + s, "foot" + s, at["D"]),
        _joint("E" + s, "triangle" + s, "f" + s, at["E"]),
        _joint("F" + s, "f" + s, "foot" + s, at["F"]),
    ]
    return bodies, joints


def pin_angles(legs: int) -> np.ndarray:
    """The crank-pin angle of each mirrored pair: ``legs / 2`` pins evenly spread."""
    pairs = legs // 2
    return 2.0 * np.pi * np.arange(pairs) / pairs


def strandbeest(legs: int = 12, design: bool = True) -> str:
    """``legs`` (even, at least 2) Jansen legs on one crank; leg ``2 q`` is the left
    leg of pin ``q`` and ``2 q + 1`` its mirror image. The motor turns the crank, the
    output is leg 0's foot x over its stance (as ``jansen_1dof.toml``'s), and with
    ``design`` the parameters are the frame pivot A of the left legs (all coincide,
    so they move together) and, by the mirror symmetry, of the right legs."""
    if legs < 2 or legs % 2:
        raise ValueError(f"legs must be even and at least 2, got {legs}")
    bodies, joints, points = [_body("ground"), _body("crank")], [], []
    joints.append(_joint("O", "ground", "crank", (0.0, 0.0)))
    for q, angle in enumerate(pin_angles(legs)):
        for index, at in ((2 * q, leg(angle)), (2 * q + 1, mirrored_leg(angle))):
            more_bodies, more_joints = _leg_text(index, at)
            bodies += more_bodies
            joints += more_joints
            x, y = (float(v) for v in at["G"])
            points.append(
                f'[[points]]\nname = "foot_{index}"\nbody = "foot_{index}"\n'
                f"position = [{x!r}, {y!r}, 0.0]\n"
            )
    head = (
        f'[mechanism]\nname = "strandbeest-{legs}"\nground = "ground"\nunits = "cm"\n'
    )
    tail = [
        '[[motors]]\nname = "crank"\njoint = "O"\n',
        '[[outputs]]\nname = "foot_x"\npoint = "foot_0"\ncoordinate = "x"\n'
        "min = -60.0\nmax = -15.0\n",
    ]
    if design:
        ax, ay = (float(v) for v in PIVOT)
        tail += [
            "[symmetry]\nnormal = [1.0, 0.0, 0.0]\npoint = [0.0, 0.0, 0.0]\n",
            '[[parameters]]\nname = "A_x"\njoint = "A_triangle_0"\ncoordinate = "x"\n'
            f'min = {ax - 5.0!r}\nmax = {ax + 5.0!r}\nmirror = "A_triangle_1"\n',
            '[[parameters]]\nname = "A_y"\njoint = "A_triangle_0"\ncoordinate = "y"\n'
            f'min = {ay - 5.0!r}\nmax = {ay + 5.0!r}\nmirror = "A_triangle_1"\n',
        ]
    return "\n".join([head] + bodies + joints + points + tail)
