"""Continuous-path task files (TOML) for planar arm synthesis (paper 002, Sec. II-A).

A task ``T = (SP_q, O, B)`` is an ordered, connected list of shape primitives (line
segments, arcs with a direction, circles), circular obstacles and optional base
rectangles, plus the link diameter Δ. Everything is checked while loading; each problem
is one :class:`MechanismFileError` naming the file, the field and what was expected.

File layout (lengths in one unit, e.g. metres)::

    [task]
    name = "rose"
    link_diameter = 0.03175        # Δ, tube diameter
    # min_link_length = 0.0635     # optional; default 2 Δ (a link holds two modules)
    # max_link_length = 0.5        # optional; default 4 × the task size (tube stock)

    [[primitives]]                 # line: start, end
    type = "line"
    start = [0.1, 0.5]
    end = [0.3, 0.5]

    [[primitives]]                 # arc: start, end, center, direction (cw | ccw)
    type = "arc"
    start = [0.3, 0.5]
    end = [0.4, 0.6]
    center = [0.3, 0.6]
    direction = "ccw"

    [[primitives]]                 # circle: center, radius, start (= end), direction
    type = "circle"
    center = [0.5, 0.6]
    radius = 0.1
    start = [0.4, 0.6]
    direction = "cw"

    [[obstacles]]
    center = [0.0, 0.8]
    radius = 0.05

    [[base_regions]]               # optional; axis-aligned rectangles for s_1
    min = [-0.1, -0.1]
    max = [0.1, 0.1]

Consecutive primitives must meet (end of one = start of the next, within 1e-6 of the
task size); as the paper assumes, no obstacle may lie inside a circle or the circle of
an arc of the path.

Limits (checked before any work): every coordinate, radius
and length at most 1e6 in magnitude (:data:`~linkopt._arms.limits.MAX_MAGNITUDE`), the
link diameter at least :data:`MIN_DIAMETER_FRACTION` of the task size (the verifier
samples the path every Δ/16), at most :data:`MAX_PRIMITIVES` primitives,
:data:`MAX_OBSTACLES` obstacles and :data:`MAX_REGIONS` base regions (the NLP's
constraints grow with their product), task files at most 16 MiB.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from jaxtyping import Float

from ..._errors import MechanismFileError
from ..._files.fields import Reader, parse_text, parse_toml
from .. import limits

KINDS = ("line", "arc", "circle")
FIELDS = {
    "line": ({"type", "start", "end"}, set()),
    "arc": ({"type", "start", "end", "center", "direction"}, set()),
    "circle": ({"type", "center", "radius", "direction"}, {"start"}),
}
TOP_LEVEL = {"task", "primitives", "obstacles", "base_regions"}
HEAD_FIELDS = {"name", "link_diameter", "min_link_length", "max_link_length"}
REL_TOL = 1e-6
MAX_PRIMITIVES = 100
MAX_OBSTACLES = 1000
MAX_REGIONS = 100
MIN_DIAMETER_FRACTION = 1e-6


@dataclass(frozen=True)
class Primitive:
    """One shape primitive (Table I), parameterised by ``t ∈ [0, 1]``.

    Lines: ``p(t) = start + t (end - start)``. Arcs and circles:
    ``p(t) = center + radius [cos(angle0 + sweep t), sin(angle0 + sweep t)]`` with a
    signed ``sweep`` (counter-clockwise positive; ±2π for a circle). For lines
    ``center`` is the midpoint and ``radius``/``angle0``/``sweep`` are 0.
    """

    kind: str
    start: Float[np.ndarray, 2]
    end: Float[np.ndarray, 2]
    center: Float[np.ndarray, 2]
    radius: float
    angle0: float
    sweep: float

    @property
    def length(self) -> float:
        if self.kind == "line":
            return float(np.linalg.norm(self.end - self.start))
        return abs(self.sweep) * self.radius


@dataclass(frozen=True)
class TraceTask:
    """A parsed task: primitives, obstacles ``(n_obs, 3)`` rows ``(x, y, r)``, base
    rectangles ``(n_B, 4)`` rows ``(x_min, y_min, x_max, y_max)`` (empty: anywhere)."""

    name: str
    source: str
    primitives: tuple[Primitive, ...]
    obstacles: Float[np.ndarray, "n_obs 3"]
    base_regions: Float[np.ndarray, "n_B 4"]
    link_diameter: float
    min_link_length: float
    max_link_length: float

    @property
    def scale(self) -> float:
        """Size of the task (diagonal of the box around the path), for tolerances."""
        pts = np.concatenate([_outline(p) for p in self.primitives])
        return float(np.linalg.norm(pts.max(0) - pts.min(0))) or 1.0


def _outline(p: Primitive) -> np.ndarray:
    if p.kind == "line":
        return np.stack([p.start, p.end])
    ang = p.angle0 + p.sweep * np.linspace(0.0, 1.0, 65)
    return p.center + p.radius * np.stack([np.cos(ang), np.sin(ang)], axis=1)


def load_task(path: str | Path) -> TraceTask:
    """Read and validate a task file; raises :class:`MechanismFileError` on bad
    input."""
    path = Path(path)
    limits.file_size(path, lambda m: MechanismFileError(str(path), "", m), "task file")
    return parse_task(parse_text(path), str(path))


def loads_task(text: str, source: str = "<string>") -> TraceTask:
    """Parse task TOML ``text``; ``source`` names it in error messages."""
    return parse_task(parse_toml(text, source), source)


def parse_task(data: dict, source: str) -> TraceTask:
    """Validate parsed task TOML (as :func:`loads_task`)."""
    rd = Reader(source)
    rd.top_level(data, TOP_LEVEL)
    if "task" not in data:
        raise rd.fail("task", "missing required table [task]")
    head = rd.table(data["task"], "task", HEAD_FIELDS, {"name", "link_diameter"})
    name = rd.string(head, "name", "task")
    diameter = limits.positive(rd, head, "link_diameter", "task", as_written=True)
    min_link = (
        limits.positive(rd, head, "min_link_length", "task", as_written=True)
        if "min_link_length" in head
        else 2 * diameter
    )
    raw = rd.array(data, "primitives")
    if not raw:
        raise rd.fail("primitives", "expected at least one [[primitives]] entry")
    limits.count_limit(rd, "primitives", len(raw), MAX_PRIMITIVES, "primitives")
    for key, most in (("obstacles", MAX_OBSTACLES), ("base_regions", MAX_REGIONS)):
        limits.count_limit(rd, key, len(rd.array(data, key)), most, key)
    prims = tuple(
        _read_primitive(rd, item, f"primitives[{k}]") for k, item in enumerate(raw)
    )
    obstacles = _read_obstacles(rd, data)
    regions = _read_regions(rd, data)
    task = TraceTask(
        name, source, prims, obstacles, regions, diameter, min_link, np.inf
    )
    _check_diameter(rd, task)
    max_link = (
        limits.positive(rd, head, "max_link_length", "task", as_written=True)
        if "max_link_length" in head
        else 4 * task.scale
    )
    if max_link <= min_link:
        raise rd.fail(
            "task.max_link_length",
            f"expected more than min_link_length {min_link:g}, got {max_link:g}",
        )
    task = dataclasses.replace(task, max_link_length=max_link)
    _check_connected(rd, task)
    _check_obstacles_outside_circles(rd, task)
    return task


def _check_diameter(rd: Reader, task: TraceTask) -> None:
    """Δ at least :data:`MIN_DIAMETER_FRACTION` of the task size."""
    if task.link_diameter < MIN_DIAMETER_FRACTION * task.scale:
        raise rd.fail(
            "task.link_diameter",
            f"expected at least {MIN_DIAMETER_FRACTION:g} of the task size "
            f"{task.scale:g}, got {task.link_diameter:g}",
        )


def _read_primitive(rd: Reader, item, where: str) -> Primitive:
    if not isinstance(item, dict) or "type" not in item:
        raise rd.fail(
            f"{where}.type", f"missing required field; expected one of {list(KINDS)}"
        )
    kind = item["type"]
    if kind not in KINDS:
        raise rd.fail(
            f"{where}.type",
            f"unknown primitive type {kind!r}; expected one of {list(KINDS)}",
        )
    required, optional = FIELDS[kind]
    rd.keys(item, where, required | optional, required)
    if kind == "line":
        a, b = (
            limits.point(rd, item, "start", where),
            limits.point(rd, item, "end", where),
        )
        if np.linalg.norm(b - a) <= 0:
            raise rd.fail(f"{where}.end", "a line segment needs end != start")
        return Primitive("line", a, b, 0.5 * (a + b), 0.0, 0.0, 0.0)
    direction = item["direction"]
    if direction not in ("cw", "ccw"):
        raise rd.fail(
            f"{where}.direction", f'expected "cw" or "ccw", got {direction!r}'
        )
    sign = 1.0 if direction == "ccw" else -1.0
    center = limits.point(rd, item, "center", where)
    if kind == "circle":
        return _circle(rd, item, where, center, sign)
    return _arc(rd, item, where, center, sign)


def _circle(
    rd: Reader, item: dict, where: str, center: np.ndarray, sign: float
) -> Primitive:
    radius = limits.positive(rd, item, "radius", where, as_written=True)
    start = (
        limits.point(rd, item, "start", where)
        if "start" in item
        else center + [radius, 0.0]
    )
    if abs(np.linalg.norm(start - center) - radius) > REL_TOL * max(radius, 1.0):
        raise rd.fail(
            f"{where}.start",
            f"expected a point on the circle (distance {radius:g} from center), "
            f"got distance {np.linalg.norm(start - center):g}",
        )
    angle0 = math.atan2(*(start - center)[::-1])
    return Primitive(
        "circle", start, start.copy(), center, radius, angle0, sign * 2 * math.pi
    )


def _arc(
    rd: Reader, item: dict, where: str, center: np.ndarray, sign: float
) -> Primitive:
    a, b = limits.point(rd, item, "start", where), limits.point(rd, item, "end", where)
    radius = float(np.linalg.norm(a - center))
    if radius <= 0:
        raise rd.fail(f"{where}.center", "an arc needs start != center")
    if abs(np.linalg.norm(b - center) - radius) > REL_TOL * max(radius, 1.0):
        raise rd.fail(
            f"{where}.end",
            f"expected a point at the start's distance {radius:g} from center, "
            f"got {np.linalg.norm(b - center):g}",
        )
    if np.linalg.norm(b - a) <= REL_TOL * radius:
        raise rd.fail(
            f"{where}.end", "an arc needs end != start (use a circle for a full turn)"
        )
    angle0 = math.atan2(*(a - center)[::-1])
    angle1 = math.atan2(*(b - center)[::-1])
    sweep = ((angle1 - angle0) * sign) % (2 * math.pi)
    return Primitive("arc", a, b, center, radius, angle0, sign * sweep)


def _read_obstacles(rd: Reader, data: dict) -> np.ndarray:
    rows = []
    for k, item in enumerate(rd.array(data, "obstacles")):
        where = f"obstacles[{k}]"
        rd.table(item, where, {"center", "radius"}, {"center", "radius"})
        rows.append(
            [
                *limits.point(rd, item, "center", where),
                limits.positive(rd, item, "radius", where, as_written=True),
            ]
        )
    return np.asarray(rows, dtype=float).reshape(-1, 3)


def _read_regions(rd: Reader, data: dict) -> np.ndarray:
    rows = []
    for k, item in enumerate(rd.array(data, "base_regions")):
        where = f"base_regions[{k}]"
        rd.table(item, where, {"min", "max"}, {"min", "max"})
        lo, hi = (
            limits.point(rd, item, "min", where),
            limits.point(rd, item, "max", where),
        )
        if np.any(hi <= lo):
            raise rd.fail(
                f"{where}.max",
                "expected max > min in x and y, "
                f"got min {lo.tolist()} max {hi.tolist()}",
            )
        rows.append([*lo, *hi])
    return np.asarray(rows, dtype=float).reshape(-1, 4)


def _check_connected(rd: Reader, task: TraceTask) -> None:
    tol = REL_TOL * task.scale
    for k in range(len(task.primitives) - 1):
        gap = np.linalg.norm(task.primitives[k].end - task.primitives[k + 1].start)
        if gap > tol:
            end = task.primitives[k].end.tolist()
            raise rd.fail(
                f"primitives[{k + 1}].start",
                f"expected the end of primitives[{k}] {end} (primitives must be "
                f"connected), gap {gap:g}",
            )


def _check_obstacles_outside_circles(rd: Reader, task: TraceTask) -> None:
    for k, (x, y, _) in enumerate(task.obstacles):
        for j, p in enumerate(task.primitives):
            if (
                p.kind != "line"
                and np.hypot(x - p.center[0], y - p.center[1]) < p.radius
            ):
                raise rd.fail(
                    f"obstacles[{k}].center",
                    f"inside the circle of primitives[{j}] ({p.kind}); the task must "
                    "keep obstacles outside circles and arcs' circles",
                )
