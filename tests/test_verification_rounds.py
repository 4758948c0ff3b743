"""Verification in the loop (issue 17.2): a run verifies its design before it stops,
and where verification fails the failing places become IK targets and the run goes on.

The five-bar's initial design fails verification (corners out of reach, a forward
singularity across the box), so a run that calls it feasible (a huge ``tolerance``)
exercises the whole loop in one or two iterations.
"""

import dataclasses
import json

import numpy as np
import pytest

from linkopt import InputError
from linkopt._cli.optimize import round_line
from linkopt._design.checkpoint import HISTORY_FIELDS, decode, encode
from linkopt._design.evaluation import capped, evaluate, targets
from linkopt._design.optimizer import OptimizerSettings, start
from linkopt._design.rounds import (
    failing_places,
    verification_round,
    wants_round,
    with_targets,
)
from linkopt._design.run import CHECKPOINT, optimize
from linkopt._design.verify import verify

#: Every design counts as feasible, so the first finished iteration is verified; the
#: one particle starts at p0, so the run adds the targets that the tests below add to
#: the initial design, and they share its compiled evaluation.
LAX = OptimizerSettings(particles=1, iterations=1, tolerance=1e6, verify_rounds=1)


@pytest.fixture(scope="module")
def initial_check(five_bar):
    return verify(five_bar)


def _finished_at_p0(mech, settings):
    run = start(mech, settings)
    return dataclasses.replace(
        run,
        iteration=1,
        finished=True,
        result_pos=mech.design.p0.copy(),
        result_total=0.0,
        result_feasible=True,
        history=(dict.fromkeys(HISTORY_FIELDS, 0.0),),
    )


def test_failing_places_are_an_unreached_cell_and_the_worst_cell(
    five_bar, initial_check
):
    assert not initial_check.passed and initial_check.coverage < 1
    places = failing_places(five_bar, initial_check)
    np.testing.assert_array_equal(places[0], initial_check.unreached_example)
    np.testing.assert_array_equal(places[1], initial_check.worst_outputs)
    # places that are targets already are not added again
    again = with_targets(five_bar, places)
    assert failing_places(again, initial_check) == []
    assert len(targets(again)) == len(targets(five_bar)) + 2


def test_added_targets_make_the_failure_count_in_f_design(five_bar, initial_check):
    """The initial design's f_design rises by the added targets' share: the unreached
    cell adds reach, the worst cell (f_sing far above α₋) adds singularity."""
    places = failing_places(five_bar, initial_check)
    before = evaluate(five_bar)
    after = evaluate(with_targets(five_bar, places))
    count = len(targets(five_bar))
    assert after.ik_reach.shape == (count + 2,)
    np.testing.assert_allclose(after.ik_reach[:count], before.ik_reach, atol=1e-9)
    assert after.ik_reach[count] > 1e-6  # the unreached cell is not reached
    assert after.adv_culled[count + 1] > 0  # the worst cell is above α₋
    assert float(after.f_design) * (count + 2) > float(before.f_design) * count


def test_a_failed_round_adds_targets_and_reopens_the_run(five_bar):
    settings = dataclasses.replace(LAX, iterations=5, verify_rounds=2)
    run = _finished_at_p0(five_bar, settings)
    assert wants_round(run, settings)
    reopened = verification_round(five_bar, run, settings)
    (record,) = reopened.rounds
    assert not record["passed"] and len(record["added_targets"]) == 2
    assert record["design"] == five_bar.design.p0.tolist()
    assert not reopened.finished and reopened.limit == 1 + settings.iterations
    assert np.all(np.isinf(reopened.pbest_cost)) and not reopened.result_feasible
    assert reopened.added_targets == tuple(map(tuple, record["added_targets"]))
    # no budget left: the round is recorded, nothing added, the run stays finished
    spent = dataclasses.replace(settings, verify_rounds=0)
    last = verification_round(five_bar, run, spent)
    assert last.finished and last.rounds[-1]["added_targets"] == []
    assert not wants_round(last, spent)


def test_a_run_goes_on_after_a_failed_verification_and_records_its_rounds(
    five_bar, tmp_path
):
    seen = []
    run = optimize(five_bar, tmp_path / "run", LAX, progress=seen.append)
    first, second = run.rounds
    assert first["design"] == five_bar.design.p0.tolist()
    assert not first["passed"] and len(first["added_targets"]) == 2
    assert first["iteration"] == 1 and second["iteration"] == 2
    assert second["added_targets"] == []  # the budget of one round is spent
    assert run.iteration == 2 and run.finished
    assert [r["round"] for r in seen if "passed" in r] == [0, 1]
    # one numbering (issue 44): the progress line's round and iteration count are
    # those of the record that summary.json lists
    for record in (first, second):
        assert round_line(record).startswith(
            f"verification round {record['round']} after {record['iteration']} "
            "iterations: "
        )
    assert round_line(second).endswith("failed; " + second["stopped"])
    # the checkpoint holds the rounds, and a resume of the finished run keeps them
    data = json.loads((tmp_path / "run" / CHECKPOINT).read_text())
    assert len(data["rounds"]) == 2
    resumed = optimize(five_bar, tmp_path / "run", LAX, resume=True)
    assert resumed.rounds == run.rounds and resumed.iteration == run.iteration


def test_rounds_survive_the_checkpoint_and_bad_ones_are_refused(five_bar, tmp_path):
    settings = dataclasses.replace(LAX, verify_rounds=2)
    run = verification_round(five_bar, _finished_at_p0(five_bar, settings), settings)
    data = json.loads(json.dumps(encode(run, five_bar, settings), allow_nan=True))
    path = tmp_path / CHECKPOINT
    back = decode(path, data, five_bar, settings)
    assert back.rounds == run.rounds and back.limit == run.limit
    spoiled = [
        ("rounds", {"a": 1}),
        ("rounds", [1]),
        ("rounds", [{**run.rounds[0], "round": 3}]),
        ("rounds", [{**run.rounds[0], "iteration": 7}]),
        ("rounds", [{**run.rounds[0], "design": [1.0]}]),
        ("rounds", [{**run.rounds[0], "added_targets": [[1.0, float("nan")]]}]),
        ("limit", -1),
        ("limit", 0),
    ]
    for key, value in spoiled:
        with pytest.raises(InputError, match=str(path)):
            decode(path, {**data, key: value}, five_bar, settings)


def test_capped_counts_the_minimisations_that_ran_to_their_cap(five_bar):
    ev = evaluate(five_bar)
    ik, adversarial = capped(five_bar, ev)
    cap = five_bar.evaluation.adversarial_iterations
    assert adversarial == int(np.sum(np.asarray(ev.adv_iterations) == cap))
    assert 0 <= ik <= len(targets(five_bar)) and adversarial >= 1
    assert np.all(np.asarray(ev.adv_iterations) <= cap)


def test_an_optimised_file_keeps_the_added_targets(five_bar, tmp_path):
    from linkopt import load
    from linkopt._files.writer import write_design

    added = with_targets(five_bar, [[-40.0, 75.125], [0.0, 32.875]])
    path = write_design(added, five_bar.design.p0, 24.0, tmp_path / "optimized.toml")
    back = load(path)
    assert back.evaluation.targets == added.evaluation.targets
    np.testing.assert_array_equal(targets(back), targets(added))


def test_reached_sigmas_are_those_of_the_reached_cells(five_bar):
    """Verification's singular values come from one batch of the grid's shape (the
    unreached cells hold copies): they are the reached cells' own, in grid order."""
    import linkopt
    from linkopt._design.verify import reached_sigmas

    solved = linkopt.solve_bk(five_bar, [[0.0, 40.0], [10.0, 50.0], [-10.0, 35.0]])
    states = np.asarray(solved.state)
    grid = np.stack([states[0], np.full_like(states[0], np.nan), states[1], states[2]])
    feasible = np.array([[True, False], [True, True]])
    got = reached_sigmas(five_bar, grid.reshape(2, 2, -1), feasible, None)
    want = np.asarray(linkopt.singular_values(five_bar, states))
    np.testing.assert_allclose(got, want, rtol=1e-12)


def test_the_last_round_serves_the_default_resolution_asked_for(five_bar):
    """The optimised design's verification is the last round's when the outputs ask
    for the resolution the rounds use, given or not; another one is verified anew."""
    from types import SimpleNamespace

    from linkopt._design.run import last_round_verification
    from linkopt._design.verify import default_resolution

    design = five_bar.design.p0
    run = SimpleNamespace(rounds=({"design": design.tolist(), "verification": {}},))
    default = default_resolution(five_bar)
    assert last_round_verification(five_bar, run, design, None) == {}
    assert last_round_verification(five_bar, run, design, default) == {}
    assert last_round_verification(five_bar, run, design, default + 2) is None
    assert last_round_verification(five_bar, run, design + 1.0, None) is None


def test_an_infeasible_design_whose_samples_see_no_singularity_gets_a_round(
    five_bar,
):
    """Regression (issue 44): rounds ran only once a design was feasible, so a design
    whose samples read no singularity while the grid held one never had the grid's
    worst cells added. A finished, infeasible run whose returned design's samples show
    no singularity is verified, and the failing places join the targets."""
    settings = dataclasses.replace(LAX, tolerance=1e-12, iterations=4, verify_rounds=1)
    run = dataclasses.replace(
        _finished_at_p0(five_bar, settings), result_feasible=False, result_total=0.3
    )
    clear = {**run.history[-1], "best_f_design": 0.3, "reach": 0.3}
    run = dataclasses.replace(run, history=(clear,))
    assert wants_round(run, settings)
    reopened = verification_round(five_bar, run, settings)
    (record,) = reopened.rounds
    assert record["feasible"] is False and not record["passed"]
    assert len(record["added_targets"]) == 2 and not reopened.finished
    assert reopened.limit == run.iteration + settings.iterations
    # samples that show the singularity already: no round before feasibility
    seen = {**clear, "singularity": 2.0, "best_f_design": 2.3}
    assert not wants_round(dataclasses.replace(run, history=(seen,)), settings)


def test_a_round_that_stops_says_why(five_bar):
    """A failed round that does not go on records why, and the progress line says it:
    its places are targets already, or no rounds are left."""
    settings = dataclasses.replace(LAX, verify_rounds=1)
    run = _finished_at_p0(five_bar, settings)
    known = with_targets(five_bar, failing_places(five_bar, verify(five_bar)))
    stuck = verification_round(known, run, settings).rounds[-1]
    assert stuck["added_targets"] == [] and "IK targets already" in stuck["stopped"]
    assert round_line(stuck).endswith("score the same targets")
    spent = dataclasses.replace(settings, verify_rounds=0)
    last = verification_round(five_bar, run, spent).rounds[-1]
    assert last["stopped"] == "no verification rounds left (--verify-rounds 0)"
