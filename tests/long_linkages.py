"""Generated planar linkages of any number of bodies and one degree of freedom, as
mechanism-file text: a chain and a ladder of closed loops
(``benchmarks/bench_bodies.py`` times them; ``tests/test_banded.py`` solves them).

* :func:`chain`: lazy tongs, ``n`` scissors of two links pinned at their middles,
  neighbouring scissors pinned at both ends (a closed four-bar loop between each
  pair); the ground is the first scissor's first link, the motor its middle pivot and
  the output the last scissor's middle angle. ``2n`` bodies.
* :func:`ladder`: rungs ``r0`` (the ground) .. ``rk`` standing on the x axis, each
  pair of neighbours joined by a top and a bottom link, a closed four-bar loop per
  cell; every cell after the first is braced by a diagonal link, so the first cell's
  motor (its top-left joint) swings the rest as one truss, and the output is the first
  cell's bottom-left angle. ``4k`` bodies.

The heights vary a little along the x axis, so no loop is a parallelogram.
"""

from __future__ import annotations

import numpy as np

LINK = 10.0  # mm between neighbouring pivots along x
HEIGHT = 20.0  # mm, the mean rung height


def _head(name: str, ground: str) -> list[str]:
    return [
        "[mechanism]",
        f'name = "{name}"',
        f'ground = "{ground}"',
        'units = "mm"',
        "",
    ]


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


def _motor_and_output(motor: str, output: str) -> list[str]:
    return [
        "[[motors]]",
        'name = "m"',
        f'joint = "{motor}"',
        "",
        "[[outputs]]",
        'name = "o"',
        f'joint = "{output}"',
        "min = -0.3",
        "max = 0.3",
        "",
    ]


def _heights(count: int):
    return HEIGHT * (1.0 + 0.1 * np.sin(np.arange(count)))


def chain(bodies: int) -> str:
    """Lazy tongs of ``bodies // 2`` scissors (``a0``, the ground, and ``b0`` first)."""
    n = max(2, bodies // 2)
    half = _heights(n + 1) / 2.0  # at the junction left of scissor i
    lines = _head(f"lazy-tongs-{2 * n}", "a0")
    for i in range(n):
        lines += _body(f"a{i}") + _body(f"b{i}")
    for i in range(n):
        lines += _joint(f"c{i}", f"a{i}", f"b{i}", (LINK * i, 0.0))
    for i in range(n - 1):
        x = LINK * (i + 0.5)
        lines += _joint(f"u{i}", f"a{i}", f"b{i + 1}", (x, half[i + 1]))
        lines += _joint(f"d{i}", f"b{i}", f"a{i + 1}", (x, -half[i + 1]))
    return "\n".join(lines + _motor_and_output("c0", f"c{n - 1}"))


def ladder_cells(bodies: int) -> int:
    """Cells of the ladder with the number of bodies nearest ``bodies``."""
    return max(1, round(bodies / 4))


def ladder(cells: int) -> str:
    """A ladder of ``cells`` four-bar loops, all braced but the first; ``4 cells``
    bodies."""
    heights = _heights(cells + 1)
    lines = _head(f"ladder-{cells}", "r0")
    lines += _body("r0")
    for i in range(1, cells + 1):
        lines += _body(f"t{i}") + _body(f"d{i}") + _body(f"r{i}")
        if i > 1:
            lines += _body(f"x{i}")
    for i in range(1, cells + 1):
        left, right = f"r{i - 1}", f"r{i}"
        x0, x1 = LINK * (i - 1), LINK * i
        lines += _joint(f"tl{i}", left, f"t{i}", (x0, heights[i - 1]))
        lines += _joint(f"tr{i}", f"t{i}", right, (x1, heights[i]))
        lines += _joint(f"bl{i}", left, f"d{i}", (x0, 0.0))
        lines += _joint(f"br{i}", f"d{i}", right, (x1, 0.0))
        if i > 1:  # the brace: top of the left rung to the middle of the right one
            lines += _joint(f"xl{i}", left, f"x{i}", (x0, 0.8 * heights[i - 1]))
            lines += _joint(f"xr{i}", f"x{i}", right, (x1, 0.3 * heights[i]))
    return "\n".join(lines + _motor_and_output("tl1", "bl1"))
