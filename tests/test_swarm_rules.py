"""linkopt's swarm rules (:mod:`linkopt._design.swarm`) against pyswarms' backend,
the reference they copy: bitwise equal on random swarms, ties and out-of-bound moves.

pyswarms is imported in a child process whose working directory is a temporary
folder, since its objects write ``report.log`` into the working directory."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from linkopt._design import swarm as ours

_REFERENCE = r"""
import json, sys
import numpy as np
from pyswarms.backend import operators as ops
from pyswarms.backend.handlers import BoundaryHandler
from pyswarms.backend.swarms import Swarm
from pyswarms.backend.topology import Star
cases = json.load(sys.stdin)
out = []
for c in cases:
    s = Swarm(np.array(c["position"]), np.array(c["velocity"]))
    s.pbest_pos = np.array(c["pbest_pos"]); s.pbest_cost = np.array(c["pbest_cost"])
    s.current_cost = np.array(c["current_cost"])
    s.best_pos = np.array(c["best_pos"]); s.best_cost = c["best_cost"]
    pos, cost = ops.compute_pbest(s)
    s.pbest_pos, s.pbest_cost = pos, cost
    gpos, gcost = Star().compute_gbest(s)
    bounds = (np.array(c["lower"]), np.array(c["upper"]))
    moved = ops.compute_position(s, bounds, BoundaryHandler(strategy="nearest"))
    out.append({"pbest_pos": pos.tolist(), "pbest_cost": cost.tolist(),
                "best_pos": np.asarray(gpos).tolist(), "best_cost": float(gcost),
                "moved": moved.tolist()})
json.dump(out, sys.stdout)
"""


def _cases(seed: int, count: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    cases = []
    for k in range(count):
        n, d = int(rng.integers(1, 9)), int(rng.integers(1, 6))
        pbest_cost = rng.uniform(0, 1, n)
        current = rng.uniform(0, 1, n)
        if k % 3 == 0:  # ties: equal costs, and a global best equal to the lowest
            current[: n // 2 + 1] = pbest_cost[: n // 2 + 1]
        best_cost = float(np.min(pbest_cost)) if k % 2 else float(rng.uniform(0, 1))
        cases.append(
            {
                "position": rng.uniform(-2, 2, (n, d)).tolist(),
                "velocity": rng.uniform(-1, 1, (n, d)).tolist(),
                "pbest_pos": rng.uniform(-1, 1, (n, d)).tolist(),
                "pbest_cost": pbest_cost.tolist(),
                "current_cost": current.tolist(),
                "best_pos": rng.uniform(-1, 1, d).tolist(),
                "best_cost": best_cost,
                "lower": (-np.ones(d)).tolist(),
                "upper": np.ones(d).tolist(),
            }
        )
    return cases


def _ours(c: dict) -> dict:
    s = ours.Swarm(np.array(c["position"]), np.array(c["velocity"]))
    s.pbest_pos, s.pbest_cost = np.array(c["pbest_pos"]), np.array(c["pbest_cost"])
    s.current_cost = np.array(c["current_cost"])
    s.best_pos, s.best_cost = np.array(c["best_pos"]), c["best_cost"]
    pos, cost = ours.compute_pbest(s)
    s.pbest_pos, s.pbest_cost = pos, cost
    gpos, gcost = ours.Star.compute_gbest(s)
    bounds = (np.array(c["lower"]), np.array(c["upper"]))
    moved = ours.compute_position(s, bounds, ours.BoundaryHandler("nearest"))
    return {
        "pbest_pos": pos.tolist(),
        "pbest_cost": cost.tolist(),
        "best_pos": np.asarray(gpos).tolist(),
        "best_cost": float(gcost),
        "moved": moved.tolist(),
    }


def test_the_swarm_rules_are_pyswarms_bitwise(tmp_path):
    cases = _cases(seed=3, count=60)
    done = subprocess.run(
        [sys.executable, "-c", _REFERENCE],
        input=json.dumps(cases),
        capture_output=True,
        text=True,
        cwd=tmp_path,
        check=True,
    )
    reference = json.loads(done.stdout)
    assert [_ours(c) for c in cases] == reference
    moved = np.array(reference[0]["moved"])
    assert np.all(np.abs(moved) <= 1.0)  # the bound rule did act on these cases


def test_only_the_nearest_boundary_rule_is_offered():
    with pytest.raises(ValueError, match="nearest"):
        ours.BoundaryHandler("periodic")
