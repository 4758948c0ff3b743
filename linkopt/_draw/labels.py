"""Units on figure axes: a motor's or an output's value is in radians (revolute
motors; angle, orientation and other rotary outputs) or in the file's length unit
(linear motors; position and displacement outputs), named by ``[mechanism].units``
(``"length units"`` when the file names none)."""

from __future__ import annotations

from .._engine.model import Mechanism

#: Output kinds whose values are lengths; every other kind is an angle (rad).
LENGTH_OUTPUTS = frozenset({"position", "displacement"})


def length_unit(mech: Mechanism) -> str:
    """The file's ``[mechanism].units``, or ``""`` when it gives none."""
    unit = mech.raw.get("mechanism", {}).get("units", "")
    return unit if isinstance(unit, str) else ""


def motor_unit(mech: Mechanism, k: int) -> str:
    """The unit of motor ``k``'s value."""
    if not mech.motor_linear[k]:
        return "rad"
    return length_unit(mech) or "length units"


def output_unit(mech: Mechanism, k: int) -> str:
    """The unit of output ``k``'s value."""
    if mech.output_kinds[k] not in LENGTH_OUTPUTS:
        return "rad"
    return length_unit(mech) or "length units"


def motor_labels(mech: Mechanism) -> list[str]:
    """``motor NAME (UNIT)`` for each motor."""
    return [
        f"motor {n} ({motor_unit(mech, k)})" for k, n in enumerate(mech.motor_names)
    ]


def output_labels(mech: Mechanism) -> list[str]:
    """``output NAME (UNIT)`` for each output."""
    return [
        f"output {n} ({output_unit(mech, k)})" for k, n in enumerate(mech.output_names)
    ]
