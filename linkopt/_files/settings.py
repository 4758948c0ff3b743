"""The settings tables of a mechanism file, ``[solver]`` and ``[evaluation]``, read by
one reader into their frozen dataclasses.

Each table is optional and so is each of its keys: an absent one keeps the dataclass's
default. A key is read as the type of its default (a flag, an integer or a number) and
must lie in :data:`SETTING_RANGES`; keys outside those, and the ones a table reads
itself (``[evaluation].targets``), are unknown fields. A target grid has at most
:data:`MAX_TARGETS` targets.
"""

from __future__ import annotations

import functools
from collections.abc import Callable

from .._engine.model import EvaluationSettings, SolverSettings
from .bounds import check_value
from .fields import Reader, is_number_list, shown

#: ``[solver]`` and ``[evaluation]`` numbers: (smallest, largest). The LM tolerance is
#: on max |C| in homogenised units (float64 resolves ~1e-16 of a reference length); the
#: LM gives up at a damping of 1e12; a trust radius of 10 rad or reference lengths is
#: already past any single step.
SETTING_RANGES: dict[str, tuple[float, float]] = {
    "max_iterations": (1, 10_000),
    "tolerance": (1e-16, 1e-2),
    "initial_damping": (1e-16, 1e6),
    "samples_per_dimension": (2, 100),
    "alpha_factor": (1e-6, 1e6),
    "motion_weight": (1e-12, 1e6),
    "range_weight": (1e-12, 1e6),
    "regularizer_weight": (1e-12, 1e6),
    "max_step": (1e-9, 10.0),
    "ik_iterations": (1, 10_000),
    "adversarial_iterations": (1, 10_000),
    "alpha_minus": (1e-12, 1e12),
}
#: Most IK targets of an evaluation (the grid's and ``[evaluation].targets``).
MAX_TARGETS = 100_000


def read_settings(
    rd: Reader,
    data: dict,
    name: str,
    settings: type,
    special: dict[str, Callable] | None = None,
):
    """The table ``[name]`` of ``data`` as an instance of the frozen dataclass
    ``settings`` (its defaults where the table or a key is absent). ``special`` maps
    a key that is not a plain setting to the function that reads its value; those
    are read after the plain ones."""
    defaults = settings()
    if name not in data:
        return defaults
    special = special or {}
    where = f"[{name}]"
    table = rd.table(data[name], where, _known(defaults) | set(special), set())
    values = {
        key: _setting(rd, table, key, where, getattr(defaults, key))
        for key in table
        if key not in special
    }
    values |= {key: special[key](table[key]) for key in table if key in special}
    return settings(**values)


def _setting(rd: Reader, table: dict, key: str, where: str, default):
    """One value of the type of its ``default``, in :data:`SETTING_RANGES`."""
    if isinstance(default, bool):
        return rd.boolean(table, key, where)
    low, high = SETTING_RANGES[key]
    if isinstance(default, int):
        return rd.integer(table, key, where, int(low), int(high))
    return rd.bounded(table, key, where, low, high)


def _known(defaults) -> set[str]:
    """The plain settings of a table: flags and the numbers it has a range for."""
    return {
        key
        for key in defaults.__dataclass_fields__
        if key in SETTING_RANGES or isinstance(getattr(defaults, key), bool)
    }


def read_solver(rd: Reader, data: dict) -> SolverSettings:
    """``[solver]``: the Levenberg–Marquardt settings."""
    return read_settings(rd, data, "solver", SolverSettings)


def read_evaluation(
    rd: Reader, data: dict, outputs: list[dict], scale: float
) -> EvaluationSettings:
    """``[evaluation]``: the settings of f_design and its IK targets, at most
    :data:`MAX_TARGETS` of them with the grid's."""
    targets = functools.partial(_read_targets, rd, outputs=outputs, scale=scale)
    settings = read_settings(
        rd, data, "evaluation", EvaluationSettings, {"targets": targets}
    )
    grid = settings.samples_per_dimension ** len(outputs)
    if grid + len(settings.targets) > MAX_TARGETS:
        raise rd.fail(
            "[evaluation].samples_per_dimension",
            f"{settings.samples_per_dimension} per output for {len(outputs)} outputs "
            f"makes {_count(grid)} targets; expected at most {MAX_TARGETS} in all",
        )
    return settings


def _count(n: int) -> str:
    """``n`` in digits, or as a power of ten past twelve digits (a grid of many
    outputs: 3 per output for 1000 outputs is a 478-digit count)."""
    digits = str(n)
    if len(digits) <= 12:
        return digits
    return f"about {digits[0]}.{digits[1]}e{len(digits) - 1}"


def _read_targets(
    rd: Reader, value, outputs: list[dict], scale: float
) -> tuple[tuple[float, ...], ...]:
    """``[evaluation].targets``: lists of one value per output (file units), each
    inside the outputs' ranges (the adversarial samples search the range)."""
    where = "[evaluation].targets"
    if not isinstance(value, list) or len(value) > MAX_TARGETS:
        raise rd.fail(
            where,
            f"expected a list of at most {MAX_TARGETS} targets, got {shown(value)}",
        )
    return tuple(
        _read_target(rd, f"{where}[{k}]", target, outputs, scale)
        for k, target in enumerate(value)
    )


def _read_target(
    rd: Reader, where: str, target, outputs: list[dict], scale: float
) -> tuple[float, ...]:
    """One target: a value per output, inside its range."""
    if not is_number_list(target, len(outputs)):
        raise rd.fail(
            where,
            f"expected a list of {len(outputs)} finite numbers (one per output), "
            f"got {shown(target)}",
        )
    for output, v in zip(outputs, target):
        check_value(rd, where, [v], output["kind"], scale)
        if not output["min"] <= v <= output["max"]:
            raise rd.fail(
                where,
                f"expected a target inside the output range: {output['name']} "
                f"in [{output['min']:g}, {output['max']:g}], got {v:g}",
            )
    return tuple(float(v) for v in target)
