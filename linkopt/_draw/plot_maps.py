"""The maps a space plot draws (:mod:`linkopt._draw.space_plots`): their windows
around the target range and the design's samples, the motor- and end-effector-space
maps of two motors and outputs, and the 2-D sections of three (solved by
:mod:`linkopt._design.maps`)."""

from __future__ import annotations

import numpy as np

from .._design.evaluation import Evaluation
from .._design.maps import Map2D, motor_map, output_map, sections
from .._engine.geometry import rest_state
from .._engine.model import Mechanism
from .._engine.readout import output_values
from .._errors import InputError

PADDING = 0.35


def _window(points: np.ndarray, low, high, pad: float):
    low = np.minimum(np.min(points, axis=0), low)
    high = np.maximum(np.max(points, axis=0), high)
    span = np.maximum(high - low, 1e-9)
    return low - pad * span, high + pad * span


def plot_windows(mech: Mechanism, evaluation: Evaluation, rest, design):
    """The maps' motor window (the samples, the rest pose and the finite motor
    limits, at least ±0.3, padded) and output window (the target range and the rest
    outputs, padded 20 %), and the rest outputs."""
    samples = np.concatenate(
        [np.asarray(evaluation.ik_motors), np.asarray(evaluation.adv_motors)]
    )
    motors = _window(
        np.vstack([samples * mech.motor_scale, np.zeros((1, mech.num_motors))]),
        -0.3,
        0.3,
        PADDING,
    )
    if mech.motor_limited:  # the limits drawn in the maps lie inside them
        finite = [
            np.where(np.isfinite(v), v, 0.0) for v in (mech.motor_min, mech.motor_max)
        ]
        motors = _window(np.vstack([*motors, *finite]), -0.3, 0.3, 0.05)
    rest_out = np.asarray(output_values(mech, rest, design=design))
    outputs = _window(
        np.vstack([rest_out, mech.output_min, mech.output_max]),
        mech.output_min,
        mech.output_max,
        0.2,
    )
    return motors, outputs, rest_out


def space_maps(
    mech: Mechanism, evaluation: Evaluation, resolution: int, design=None, progress=None
) -> tuple[Map2D, Map2D]:
    """Continuation maps around the target range and the samples (two motors, two
    outputs)."""
    check_spaces(mech, (2,), "space maps")
    rest = rest_state(mech)
    (m_low, m_high), (o_low, o_high), rest_out = plot_windows(
        mech, evaluation, rest, design
    )
    motors = motor_map(
        mech,
        m_low,
        m_high,
        resolution,
        start_state=rest,
        start_motors=np.zeros(2),
        design=design,
        progress=progress,
    )
    outputs = output_map(
        mech,
        o_low,
        o_high,
        resolution,
        start_state=rest,
        start_outputs=rest_out,
        design=design,
        progress=progress,
    )
    return motors, outputs


#: Where the motor-space sections cut the third motor's range over the IK samples
#: (:func:`section_maps`).
SECTION_FRACTIONS = (0.25, 0.5, 0.75)


def section_maps(
    mech: Mechanism, evaluation: Evaluation, resolution: int, design=None, progress=None
):
    """Three motors and three outputs: 2-D sections of both spaces at three values of
    the third variable (output: the range's ends and middle; motor: a quarter, half and
    three quarters of the way between the smallest and largest third motor value of
    the IK samples, so that each motor section cuts the target range's image, whose
    third motor values span that interval, where its ends would only touch it).
    Returns
    ``[(motor_map, output_map, motor_cut, output_cut)]``, one per section."""
    check_spaces(mech, (3,), "sections")
    rest = rest_state(mech)
    ik_motors = np.asarray(evaluation.ik_motors) * mech.motor_scale
    (m_low, m_high), (o_low, o_high), rest_out = plot_windows(
        mech, evaluation, rest, design
    )
    b_cuts = [
        mech.output_min[2],
        0.5 * (mech.output_min[2] + mech.output_max[2]),
        mech.output_max[2],
    ]
    third = ik_motors[:, 2]
    a_cuts = [float(np.min(third) + f * np.ptp(third)) for f in SECTION_FRACTIONS]
    motors = sections(
        mech,
        "fk",
        m_low,
        m_high,
        resolution,
        a_cuts,
        start_state=rest,
        start_values=np.zeros(3),
        design=design,
        progress=progress,
    )
    outputs = sections(
        mech,
        "bk",
        o_low,
        o_high,
        resolution,
        b_cuts,
        start_state=rest,
        start_values=rest_out,
        design=design,
        progress=progress,
    )
    return list(zip(motors, outputs, a_cuts, b_cuts))


def check_spaces(mech: Mechanism, counts: tuple[int, ...], what: str) -> None:
    """:class:`InputError` unless the mechanism has ``counts`` motors and as many
    outputs."""
    if mech.num_motors != mech.num_outputs or mech.num_motors not in counts:
        expected = " or ".join(map(str, counts))
        raise InputError(
            f"{mech.source}: {what} need {expected} motors and as many outputs, the "
            f"file has {mech.num_motors} and {mech.num_outputs}"
        )
