"""Generated planar linkages of any number of bodies, as mechanism-file text: a serial
chain and a ladder of closed four-bar loops (``benchmarks/bench_bodies.py`` times
them; ``tests/test_banded.py`` solves them).

* :func:`chain`: the ground and ``bodies - 1`` links in a row, joined by revolute
  joints about z, every joint a motor and its angle an output (mobility
  ``bodies - 1``).
* :func:`ladder`: rungs ``r0`` (the ground) .. ``rk`` standing on the x axis, each
  pair of neighbours joined by a top and a bottom link (four revolute joints per
  cell, a closed four-bar loop); the rung heights vary a little, so no cell is a
  parallelogram. The top-left joint of each cell is a motor, the bottom-left one's
  angle an output (mobility ``k``, ``3k + 1`` bodies).
"""

from __future__ import annotations

import numpy as np

LINK = 10.0  # mm between neighbouring joints along x
HEIGHT = 20.0  # mm, the mean rung height


def _head(name: str) -> list[str]:
    return ["[mechanism]", f'name = "{name}"', 'ground = "b0"', 'units = "mm"', ""]


def _body(name: str) -> list[str]:
    return ["[[bodies]]", f'name = "{name}"', ""]


def _joint(name: str, first: str, second: str, anchor) -> list[str]:
    x, y = (float(v) for v in anchor)
    return [
        "[[joints]]",
        f'name = "{name}"',
        'type = "revolute"',
        f'bodies = ["{first}", "{second}"]',
        f"anchor = [{x!r}, {y!r}, 0.0]",
        "axis = [0.0, 0.0, 1.0]",
        "",
    ]


def _motor_and_output(index: int, motor: str, output: str) -> list[str]:
    return [
        "[[motors]]",
        f'name = "m{index}"',
        f'joint = "{motor}"',
        "",
        "[[outputs]]",
        f'name = "o{index}"',
        f'joint = "{output}"',
        "min = -0.5",
        "max = 0.5",
        "",
    ]


def chain(bodies: int) -> str:
    """A serial chain of ``bodies`` bodies (``b0`` the ground), one motor per joint."""
    lines = _head(f"chain-{bodies}")
    for b in range(bodies):
        lines += _body(f"b{b}")
    for j in range(1, bodies):
        lines += _joint(f"j{j}", f"b{j - 1}", f"b{j}", (LINK * (j - 1), 0.0))
    for j in range(1, bodies):
        lines += _motor_and_output(j, f"j{j}", f"j{j}")
    return "\n".join(lines)


def ladder_cells(bodies: int) -> int:
    """Cells of the ladder with the number of bodies nearest ``bodies``."""
    return max(1, round((bodies - 1) / 3))


def ladder(cells: int) -> str:
    """A ladder of ``cells`` four-bar loops, ``3 cells + 1`` bodies."""
    heights = HEIGHT * (1.0 + 0.1 * np.sin(np.arange(cells + 1)))
    lines = _head(f"ladder-{cells}")
    names = ["b0"] + [f"b{k}" for k in range(1, 3 * cells + 1)]
    for name in names:
        lines += _body(name)
    motors = []
    for i in range(1, cells + 1):
        left, top, bottom, right = names[3 * i - 3], *names[3 * i - 2 : 3 * i + 1]
        x0, x1 = LINK * (i - 1), LINK * i
        lines += _joint(f"tl{i}", left, top, (x0, heights[i - 1]))
        lines += _joint(f"tr{i}", top, right, (x1, heights[i]))
        lines += _joint(f"bl{i}", left, bottom, (x0, 0.0))
        lines += _joint(f"br{i}", bottom, right, (x1, 0.0))
        motors += _motor_and_output(i, f"tl{i}", f"bl{i}")
    return "\n".join(lines + motors)
