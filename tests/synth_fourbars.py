"""Four-bar files of given link lengths and their closed-form coupler curves (tests
of linkopt._synth)."""

from __future__ import annotations

import numpy as np

import linkopt


def circle_intersection(b, d, r_b, r_d, branch):
    """The point at ``r_b`` from ``b`` and ``r_d`` from ``d`` (rows of ``(N, 2)``),
    on the left (branch +1) or right (-1) of ``b -> d``; NaN where none."""
    b, d = np.atleast_2d(b), np.atleast_2d(d)
    span = d - b
    length = np.linalg.norm(span, axis=1)
    along = (r_b**2 - r_d**2 + length**2) / (2 * length)
    with np.errstate(invalid="ignore"):
        height = np.sqrt(r_b**2 - along**2)
    unit = span / length[:, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], axis=1)
    return b + along[:, None] * unit + branch * height[:, None] * normal


def coupler_curve(a, b, c, d, u, v, crank, branch):
    """Closed-form coupler point of the four-bar A=(0,0), D=(d,0) at crank angles
    ``crank`` (rad from the x axis): ``(N, 2)``, NaN where it does not assemble."""
    crank = np.asarray(crank, dtype=float)
    pin = a * np.stack([np.cos(crank), np.sin(crank)], axis=1)
    ground = np.broadcast_to([d, 0.0], pin.shape)
    rocker = circle_intersection(pin, ground, b, c, branch)
    e = (rocker - pin) / b
    normal = np.stack([-e[:, 1], e[:, 0]], axis=1)
    return pin + u * e + v * normal


def four_bar_text(a, b, c, d, u, v, crank0, branch, extra="", motor=""):
    """A four-bar file (mm): crank ``a`` at ``crank0`` rad, coupler ``b`` with the
    point ``(u, v)`` in its frame (along B->C, left of it), rocker ``c``, ground
    ``d``; the rocker pin on ``branch``; ``motor`` more lines of the motor's table
    (its limits), ``extra`` more tables."""
    pin = a * np.array([np.cos(crank0), np.sin(crank0)])
    rocker = circle_intersection(pin, [d, 0.0], b, c, branch)[0]
    point = coupler_curve(a, b, c, d, u, v, [crank0], branch)[0]

    def xyz(p):
        return f"[{float(p[0])!r}, {float(p[1])!r}, 0.0]"

    joints = [
        ("A", "ground", "crank", [0, 0]),
        ("B", "crank", "coupler", pin),
        ("C", "coupler", "rocker", rocker),
        ("D", "ground", "rocker", [d, 0]),
    ]
    lines = ['[mechanism]\nname = "four-bar"\nground = "ground"\nunits = "mm"\n']
    for body in ("ground", "crank", "coupler", "rocker"):
        lines.append(f'[[bodies]]\nname = "{body}"\n')
    for name, i, j, p in joints:
        lines.append(
            f'[[joints]]\nname = "{name}"\ntype = "revolute"\nbodies = ["{i}", "{j}"]\n'
            f"anchor = {xyz(np.asarray(p, float))}\naxis = [0.0, 0.0, 1.0]\n"
        )
    lines.append('[[motors]]\nname = "crank"\njoint = "A"\n' + motor)
    lines.append(
        f'[[points]]\nname = "tip"\nbody = "coupler"\nposition = {xyz(point)}\n'
        'follow = "anchors"\n'
    )
    lines.append('[[outputs]]\nname = "rocker"\njoint = "D"\nmin = -0.1\nmax = 0.1\n')
    lines.append(
        f'[[parameters]]\nname = "ground_d"\njoint = "D"\ncoordinate = "x"\n'
        f"min = {float(d) - 5.0!r}\nmax = {float(d) + 5.0!r}\n"
    )
    return "\n".join(lines) + extra


def four_bar(a, b, c, d, u=0.0, v=0.0, crank0=np.pi / 2, branch=1, **tables):
    return linkopt.loads(four_bar_text(a, b, c, d, u, v, crank0, branch, **tables))
