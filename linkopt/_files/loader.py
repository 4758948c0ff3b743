"""Mechanism definition files (TOML): parsing and validation, before any solving.

Every problem is reported as one :class:`MechanismFileError` naming the file, the
table/field and what was expected (through the shared
:class:`~linkopt._files.fields.Reader`). Nothing missing is silently replaced by a
default; the only optional fields are those documented in the mechanism-file reference
with their defaults (``reference_length``, ``[solver]``, ``axis`` of a fixed joint,
``[symmetry]``, ``[[parameters]]``, ``mirror``).

Every field is checked for its TOML type, and every number for being finite and of a
magnitude the solver can work with, before anything is computed from it
(:mod:`.bounds`). The parts are read in the order they depend on each other: the
bodies and joints (:mod:`.topology`) give the reference length, which bounds the named
points and motors (:mod:`.points`), the outputs (:mod:`.outputs`), the symmetry and
design parameters (:mod:`linkopt._files.design_space`) and the settings
(:mod:`.settings`); ``[collision]`` (:mod:`linkopt._engine.links`) is read last, from
the mechanism. Bodies joined by ``fixed`` joints are then merged into one body
(:mod:`linkopt._engine.welding`), before the mobility check. A ``[synthesis]`` table
is read by :mod:`.synthesis` (the checks that need no geometry; the targets are
built again where a synthesis asks for them).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from .._engine.welding import weld
from .bounds import check_position, position, reference_length
from .collision import read_collision
from .design_space import read_design
from .fields import Reader, parse_text, parse_toml
from .outputs import output_fields, read_outputs
from .points import idle_spins, motor_fields, point_fields, read_motors, read_points
from .settings import read_evaluation, read_solver
from .symmetry import read_symmetry
from .synthesis import read_synthesis, synthesis_names
from .topology import (
    body_fields,
    body_origins,
    check_band,
    check_size,
    joint_fields,
    read_bodies,
    read_joints,
)

TOP_LEVEL = {
    "mechanism",
    "bodies",
    "joints",
    "motors",
    "points",
    "outputs",
    "symmetry",
    "parameters",
    "solver",
    "evaluation",
    "collision",
    "synthesis",  # read by linkopt._files.synthesis
}


def load(path: str | Path) -> Mechanism:
    """Read, validate and assemble a mechanism definition file."""
    path = Path(path)
    return build(parse_text(path), str(path))


def loads(text: str, source: str = "<string>") -> Mechanism:
    """As :func:`load`, from the text of a file."""
    return build(parse_toml(text, source), source)


def build(data: dict, source: str, check: bool = True) -> Mechanism:
    """Validate a parsed definition and build the :class:`Mechanism`; ``check=False``
    skips the mobility/rest-singularity check (for test geometry only)."""
    # [mechanism].assemble, [[lengths]], body frames
    from .assembly import prepare

    rd = Reader(source)
    check_size(rd, data)
    data = prepare(data, source)
    mech = Mechanism(source=source, raw=data, **_read_fields(rd, data))
    collision = read_collision(rd, mech)  # [collision], bodies' radius and layer
    if collision is not None:
        mech = dataclasses.replace(mech, collision=collision)
    mech = weld(mech)  # bodies joined by fixed joints: one body
    if "synthesis" in data:  # checked here too, so that `linkopt check` sees it
        read_synthesis(source, data["synthesis"], synthesis_names(mech))
    if check:
        from .._engine.mobility import check_mobility  # needs JAX; not for parsing

        check_band(mech)
        check_mobility(mech)
    return mech


def _read_fields(rd: Reader, data: dict) -> dict:
    """The :class:`Mechanism` fields of a definition (all but ``[collision]``)."""
    head = _read_head(rd, data)
    bodies, body_index = read_bodies(rd, data)
    ground = rd.lookup(body_index, head["ground"], "[mechanism].ground", "body")
    joints = read_joints(rd, data, body_index)
    anchors = np.array([j["anchor"] for j in joints])
    scale = reference_length(rd, head, anchors)
    for k, joint in enumerate(joints):
        check_position(rd, f"joints[{k}].anchor", joint["anchor"], scale)
    origins = body_origins(rd, bodies, joints, ground, scale)
    fields = {
        "name": head["name"],
        "length_scale": scale,
        **body_fields(bodies, ground, origins),
        **joint_fields(joints, anchors),
    }
    return fields | _read_parts(rd, data, body_index, joints, ground, scale)


def _read_parts(
    rd: Reader,
    data: dict,
    body_index: dict[str, int],
    joints: list[dict],
    ground: int,
    scale: float,
) -> dict:
    """The fields of what lies on the bodies and joints: points, motors, outputs,
    symmetry, design parameters and settings (file order of dependence)."""
    anchors = np.array([j["anchor"] for j in joints])
    points = read_points(rd, data, body_index, joints, scale)
    motors = read_motors(rd, data, joints, scale)
    outputs, reported = read_outputs(rd, data, points, joints, scale)
    symmetry = read_symmetry(
        rd, data, lambda t, key, at: position(rd, t, key, at, scale)
    )
    design = read_design(
        rd, data, joints, body_index, symmetry, scale,
        lambda at, values: check_position(rd, at, values, scale), points, ground,
    )  # fmt: skip
    return {
        **point_fields(points, joints, anchors, scale),
        **motor_fields(motors),
        **output_fields(outputs, reported),
        "design": design,
        "solver": read_solver(rd, data),
        "evaluation": read_evaluation(rd, data, outputs, scale),
        "symmetry": symmetry,
        **idle_spins(
            joints, points, outputs + reported, ground, len(body_index), scale
        ),
    }


def _read_head(rd: Reader, data: dict) -> dict:
    """The known top-level tables and the ``[mechanism]`` table."""
    rd.top_level(data, TOP_LEVEL)
    if "mechanism" not in data:
        raise rd.fail("[mechanism]", "missing table")
    head = rd.table(
        data["mechanism"],
        "[mechanism]",
        {"name", "ground", "reference_length", "units"},
        {"name", "ground"},
    )
    rd.string(head, "name", "[mechanism]")
    if "units" in head:
        rd.string(head, "units", "[mechanism]")
    return head
