"""The collision columns of an optimisation's record (issue 30): ``summary.json``'s
``collision`` entry and ``history.csv``'s ``collision`` and ``min_clearance`` columns
exist exactly for a file with ``[collision]`` enabled, and hold the collision part of
``f_design`` and the least clearance over the design's sample states (the numbers
``linkopt evaluate`` reports). The columns written by a run are checked in
``tests/test_collision_objective.py`` (the small optimisation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._cli.evaluation import evaluation_payload
from linkopt._design.checkpoint import HISTORY_FIELDS
from linkopt._design.collision import (
    COLLISION_COLUMNS,
    history_columns,
    history_fields,
    summary_entry,
)
from linkopt._design.evaluation import evaluate

ROOT = Path(__file__).resolve().parents[1]
COLLIDING = ROOT / "mechanisms" / "four_bar_collision.toml"


def test_only_a_file_with_collision_gets_the_columns():
    four_bar = linkopt.load(ROOT / "mechanisms" / "four_bar.toml")
    assert history_fields(four_bar, HISTORY_FIELDS) == HISTORY_FIELDS
    colliding = linkopt.load(COLLIDING)
    fields = history_fields(colliding, HISTORY_FIELDS)
    assert fields == [*HISTORY_FIELDS, *COLLISION_COLUMNS]
    off = linkopt.loads(
        COLLIDING.read_text().replace("enable = true", "enable = false"), "off.toml"
    )
    assert history_fields(off, HISTORY_FIELDS) == HISTORY_FIELDS
    assert summary_entry(off, None, None, {}) == {}


def test_summary_and_history_hold_what_evaluate_reports():
    mech = linkopt.load(COLLIDING)
    ev = evaluate(mech)
    checks = {"initial": {"min_clearance": -3.0}, "optimized": {"min_clearance": 2.0}}
    entry = summary_entry(mech, ev, mech.design.p0, checks)["collision"]
    reported = evaluation_payload(mech, ev)["collision"]
    assert entry["share"] == pytest.approx(reported["share"], rel=1e-9)
    assert entry["min_clearance"] == pytest.approx(reported["min_clearance"], rel=1e-12)
    assert entry["pair"] == reported["pair"] == ["ground", "coupler"]
    assert entry["min_clearance"] < 0.0  # the coupler passes through the ground link
    assert entry["verified_min_clearance"] == 2.0
    assert entry["initial_verified_min_clearance"] == -3.0
    # a batch of four designs (the batch of test_collision_objective.py's four
    # particles, whose evaluation program this structure shares): the columns of
    # each are its own evaluation's
    designs = np.stack([mech.design.p0] * 4)
    batch = evaluate(mech, designs)
    columns = history_columns(mech, batch, designs, 1)
    assert columns["collision"] == pytest.approx(entry["share"], rel=1e-9)
    assert columns["min_clearance"] == pytest.approx(entry["min_clearance"], rel=1e-9)
