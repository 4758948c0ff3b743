"""Assembly: a mechanism file from approximate anchors and declared dimensions.

A file may describe its mechanism the way a drawing does, and let linkopt solve the
loop closures:

* ``[[lengths]]``: ``joints = ["a", "b"]`` and ``length = 40.0``, the distance between
  two joint anchors (file units), held exactly;
* a body in its own frame: ``frame = [x, y, z]`` (approximate world position of the
  body frame at rest), optional ``orientation = [w, x, y, z]`` (unit quaternion, body
  to world, identity by default), ``anchors = { joint = [x, y, z], ... }``, the
  anchors of *all* its joints in that frame (as MJCF/URDF bodies), held exactly, and
  optional ``axes = { joint = [x, y, z], ... }``, joint axes in that frame;
* ``[mechanism].assemble = true`` asks the loader to assemble before reading the file,
  so every command uses such a file directly; ``linkopt assemble`` writes the result.

What is solved (choices the issue leaves open, made here):

* Unknowns are the world anchors of the joints at the rest pose, plus the pose
  (position, rotation vector) of each body given in its own frame. The anchors of
  joints on the ground are the world frame: they are held where written, and a
  declared length between two of them must already hold.
* A body in its own frame is rigid and carries its joint axes: an axis in its
  ``axes`` is in its frame, one written in ``[[joints]]`` is the world direction at
  the body's drawn pose; both turn with the body. The ground and a body given by world
  anchors hold their axes as written. Each joint keeps its carriers' axes together:
  parallel (two rows) for a revolute, prismatic or cylindrical joint, perpendicular
  (one row) for a universal joint's ``axis`` and ``axis2``. So a spatial loop of
  bodies in their own frames (a spherical five-bar) closes with its moving axes
  turned. A body given by world anchors is held together only by the declared lengths
  (fine for a planar loop, where every anchor stays in its plane); give the bodies of a
  spatial mechanism in their own frames, and a slider too (its rail anchor on the
  ground is held, so a slider in its own frame stays where that anchor is written). An
  assembly that turns a body given by world anchors off the axes it holds is refused
  (:func:`.refusal.check_held_axes`).
* A prismatic or cylindrical joint slides (:mod:`.lines`): its anchor belongs to the
  ground or its first body, and the other body only has to bring its anchor of the
  joint onto the axis line through it (two rows), so the travel takes up what the
  drawing got wrong; a prismatic joint also keeps its bodies from turning about the
  axis (a third axis row). A body given by world anchors that carries such an axis is
  read as a part drawing at its drawn pose (rigid, its axis turning with it).
* Each motor is held at its drawn value: a rotary motor keeps the angle about its axis
  (as its first body carries it) between the anchor of its second body farthest from
  the axis and that of its first body (a fixed world direction when the first body is
  the ground); a linear motor keeps the offset along its axis between the second
  body's farthest anchor and the first body's (or the joint's anchor on the ground):
  the drawn stroke between the pins, not the slide, which stays free. ``motors``
  (``--motors``) turns them by these values (rad, file units) from the drawing before
  assembling. The assembled rest pose then *defines* motor zero, as for every file
  (motors are measured from the rest pose).
* Of the assemblies that hold all of that, the one that moves the anchors least:
  ``min Σ_j |a_j - a_j⁰|² (+ 10⁻² Σ_b |Δframe_b|², rotations in rad, lengths in
  reference lengths)``. It is found from the drawing (so the drawing chooses the
  assembly branch) by Levenberg–Marquardt with minimum-norm steps (every step the
  least squares step of least weighted length), then Gauss–Newton projections onto the
  nearest point of the constraint manifold (``dy = -(I - J⁺J) (y - y⁰) - J⁺ r``, whose
  fixed points are the first-order optimality conditions), then a last polish.
  Written here rather than with optimistix: neither step is one of its least-squares
  solvers, and the problems are tiny (tens of unknowns); the Levenberg–Marquardt
  phases are :mod:`linkopt._engine.solvers.lm`'s loop with its minimum-norm step and
  the projections :mod:`linkopt._engine.solvers.projection`'s.
* A file whose loops cannot close is refused, never changed silently: the message
  names the loop (its joints and bodies, a fundamental cycle of the body graph through
  the joints that miss), the dimensions that cannot all hold at the closest assembly
  (the least squares minimum from the drawing), the gap, the sum of their misses in
  file units (for a single loop pulled straight that is the amount by which it fails
  to close) and the axes' miss in degrees, which of the loop's axes are held as
  written, where its prismatic and cylindrical joints slid and how far a sliding
  anchor stays off its axis line. Where the loops close only with the motors free, the
  message says so, with the motors' joints, the miss with them held (the motors' share
  apart) and where the nearest free assembly puts them.
* Points given by ``position`` move with their body. On a body given in its own
  frame the position is in that frame, like the body's anchors, and follows the
  assembled frame exactly; on a body given by world anchors it is a world position
  at rest, carried by the best-fit rigid motion of the body's anchors (a body whose
  anchors are collinear turns by the smallest rotation that aligns them).

Without ``assemble = true``, declared ``[[lengths]]`` are checked against the anchors
(to :data:`CHECK_TOL` reference lengths), so a hand-solved file can state them; a body
in its own frame needs ``assemble = true``. The assembled definition has world anchors
and axes only (no ``[[lengths]]``, frames or ``assemble``), so that it, and every design
written from it, is an ordinary file.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..fields import Reader
from .lines import check_rigid
from .problem import BODY_KEYS, Problem, frame_bodies, read_problem
from .refusal import CHECK_TOL, check_declared, check_held_axes, refuse
from .solve import CLOSE_TOL, solve, start
from .write import Move, Report, assembled_anchors, report, strip, written

__all__ = [
    "BODY_KEYS",
    "CHECK_TOL",
    "CLOSE_TOL",
    "NEAR_SINGULAR",
    "Assembled",
    "Move",
    "Problem",
    "Report",
    "assemble",
    "prepare",
    "read_problem",
    "requested",
]

#: σ_min (homogenised) of the FK Jacobian at an assembled rest pose below which
#: ``linkopt assemble`` warns that the pose is near a singularity; the loader refuses
#: below :data:`linkopt._engine.mobility.SINGULAR_TOL` (1e-7). The shipped files' rest
#: poses have σ_min of 0.03-0.3 (FK and BK), and f_sing is above 1000 below it.
NEAR_SINGULAR = 1e-3


@dataclass(frozen=True)
class Assembled:
    """The assembled definition (world anchors, an ordinary file) and its report."""

    data: dict
    report: Report


def requested(data: dict) -> bool:
    """``[mechanism].assemble = true``."""
    head = data.get("mechanism")
    return isinstance(head, dict) and head.get("assemble") is True


def prepare(data: dict, source: str) -> dict:
    """The loader's hook: the definition to read. Assembled on request, checked and
    stripped of ``[[lengths]]`` otherwise; unchanged when it declares nothing."""
    declares = "lengths" in data or (
        isinstance(data.get("mechanism"), dict) and "assemble" in data["mechanism"]
    )
    if not declares and not frame_bodies(data):
        return data
    rd = Reader(source)
    head = data.get("mechanism")
    if isinstance(head, dict) and "assemble" in head:
        rd.boolean(head, "assemble", "[mechanism]")
    if requested(data):
        return assemble(data, source).data
    if frame_bodies(data):
        k = frame_bodies(data)[0]
        raise rd.fail(
            f"bodies[{k}].anchors",
            "a body given in its own frame needs [mechanism].assemble = true",
        )
    problem = read_problem(data, source)
    check_declared(rd, problem)
    return strip(data)


def assemble(data: dict, source: str, motors=None) -> Assembled:
    """Assemble a parsed definition: the assembled definition and the report.

    ``motors`` (``(M,)``, rad or file units, optional) turns the motors by these values
    from the drawing first. :class:`MechanismFileError` for bad fields and for loops
    that do not close."""
    problem = read_problem(data, source, motors)
    check_rigid(Reader(source), problem)
    x0 = start(problem)
    x, residual, iterations = solve(problem, x0, problem.rows)
    if residual > CLOSE_TOL:
        refuse(Reader(source), problem, x0, x)
    check_held_axes(Reader(source), problem, assembled_anchors(problem, x))
    return Assembled(
        written(data, problem, x), report(problem, x, residual, iterations)
    )
