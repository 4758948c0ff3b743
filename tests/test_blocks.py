"""Batched calls in fixed blocks (linkopt._engine.blocks): the same numbers as one call
on the whole batch, and one compiled program for every batch size (issue 19, part 2:
a first run compiled the warm-started solve once per wave size)."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from linkopt._engine.blocks import BLOCK, in_blocks, path_rows
from linkopt._engine.kinematics import solve_fk, solve_fk_path
from linkopt._engine.readout import motor_values, output_values
from linkopt._engine.singularity import f_sing

COMPILED: list[str] = []
LISTENING = []


def _listener(event, duration, **kwargs):
    if LISTENING and event.endswith("backend_compile_duration"):
        COMPILED.append(kwargs.get("fun_name"))


monitoring.register_event_duration_secs_listener(_listener)


def compilations(fn):
    """The names of the programs compiled while ``fn()`` runs."""
    COMPILED.clear()
    LISTENING.append(True)
    try:
        fn()
    finally:
        LISTENING.clear()
    return list(COMPILED)


@pytest.mark.parametrize("count", [1, BLOCK - 1, BLOCK, BLOCK + 1, 3 * BLOCK + 5])
def test_blocks_equal_one_call_and_see_only_full_blocks(count):
    rows = np.random.default_rng(count).normal(size=(count, 3))
    seen = []

    def fn(x, y):
        seen.append(len(x))
        return {"sum": x + y, "norm": jnp.linalg.norm(x, axis=1)}

    out = in_blocks(fn, (rows, 2 * rows))
    assert set(seen) == {BLOCK}
    np.testing.assert_array_equal(np.asarray(out["sum"]), 3 * rows)
    np.testing.assert_allclose(out["norm"], np.linalg.norm(rows, axis=1), rtol=1e-15)
    assert isinstance(out["sum"], jax.Array) and out["sum"].shape == (count, 3)


def test_blocks_on_threads_equal_blocks_one_after_another(five_bar, monkeypatch):
    """A batch of several blocks runs them on threads (blocks.THREADS); the numbers
    are those of one block after another, and the first block runs before the
    others start (a program new to the process compiles once)."""
    from linkopt._engine import blocks

    motors = 0.3 * (2 * np.random.default_rng(3).random((3 * BLOCK + 7, 2)) - 1)
    monkeypatch.setattr(blocks, "THREADS", 1)
    serial = solve_fk(five_bar, motors)
    monkeypatch.setattr(blocks, "THREADS", 2)
    threaded = solve_fk(five_bar, motors)
    for a, b in zip(jax.tree.leaves(serial), jax.tree.leaves(threaded)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    order = []

    def fn(x):
        order.append(float(x[0, 0]))
        return {"x": x}

    rows = np.arange(4.0 * BLOCK)[:, None]
    out = in_blocks(fn, (rows,))
    np.testing.assert_array_equal(np.asarray(out["x"]), rows)
    assert order[0] == 0.0 and sorted(order) == [0.0, 64.0, 128.0, 192.0]


def test_one_row_runs_the_single_row_program():
    rows = np.arange(6.0).reshape(2, 3)
    seen = []

    def fn(x):
        seen.append(("block", x.shape))
        return {"twice": 2 * x}

    def one(x):
        seen.append(("one", x.shape))
        return {"twice": 2 * x}

    out = in_blocks(fn, (rows[:1],), one=one)
    assert seen == [("one", (3,))]
    assert isinstance(out["twice"], jax.Array)
    np.testing.assert_array_equal(np.asarray(out["twice"]), 2 * rows[:1])
    in_blocks(fn, (rows,), one=one)
    assert seen[-1] == ("block", (BLOCK, 3))


def test_path_rows_are_few_lengths_at_most_twice_the_path():
    lengths = {path_rows(n) for n in range(1, 600)}
    assert lengths == {16, 32, 64, 128, 256, 512, 1024}
    assert all(n <= path_rows(n) < max(2 * n, 17) for n in range(1, 600))


def _motors(count, seed=0):
    return np.random.default_rng(seed).uniform(-0.3, 0.3, size=(count, 2))


def test_one_warm_program_serves_every_batch_size(five_bar):
    rest = solve_fk(five_bar, np.zeros(2)).state
    solve_fk(five_bar, _motors(3), start=rest)  # compiled here (or earlier)

    def more_sizes():
        for count in (1, 5, BLOCK + 3, 2 * BLOCK + 7):
            solve_fk(five_bar, _motors(count, count), start=rest)
            solve_fk(five_bar, _motors(count, count), start=rest, design=None)

    assert "jit(solve_fk)" not in compilations(more_sizes)


def test_blocked_solves_equal_single_solves(five_bar):
    design = np.asarray(five_bar.design.p0) + 0.5
    motors = _motors(BLOCK + 9, 7)
    batch = solve_fk(five_bar, motors, design=design)
    assert batch.state.shape == (BLOCK + 9, five_bar.state_size)
    for k in (0, BLOCK - 1, BLOCK, BLOCK + 8):
        one = solve_fk(five_bar, motors[k], design=design)
        assert bool(one.converged) == bool(batch.converged[k])
        np.testing.assert_allclose(batch.state[k], one.state, atol=1e-12)
    got = motor_values(five_bar, batch.state, design=design)
    np.testing.assert_allclose(
        np.asarray(got)[batch.converged], motors[batch.converged], atol=1e-9
    )


def test_read_outs_and_sigmas_of_any_batch_share_programs(five_bar):
    states = np.asarray(solve_fk(five_bar, _motors(2 * BLOCK + 1, 3)).state)
    f_sing(five_bar, states[:2])
    output_values(five_bar, states[:2])
    f_sing(five_bar, states[0])  # and one row's programs
    output_values(five_bar, states[0])

    def more_sizes():
        for count in (1, 7, BLOCK, 2 * BLOCK + 1):
            f_sing(five_bar, states[:count])
            output_values(five_bar, states[:count])

    compiled = compilations(more_sizes)
    assert "jit(sigmas)" not in compiled and "jit(read_outputs)" not in compiled
    whole = np.asarray(f_sing(five_bar, states))
    for k in (0, BLOCK, 2 * BLOCK):
        assert whole[k] == pytest.approx(float(f_sing(five_bar, states[k])), rel=1e-12)


def test_padded_paths_equal_their_rows_and_share_a_program(five_bar):
    path = np.linspace([0.0, 0.0], [0.4, -0.3], 9)
    short = solve_fk_path(five_bar, path)
    assert short.state.shape == (9, five_bar.state_size) and bool(
        np.all(short.converged)
    )
    longer = solve_fk_path(five_bar, np.concatenate([path, path[::-1]]))
    np.testing.assert_allclose(longer.state[:9], short.state, atol=1e-12)
    np.testing.assert_allclose(
        longer.state[-1], solve_fk(five_bar, path[0]).state, atol=1e-9
    )
    compiled = compilations(lambda: solve_fk_path(five_bar, path[:5]))
    assert "jit(path_fk)" not in compiled  # 5, 9 and 18 rows: 16 and 32


def test_traced_calls_are_not_blocked(five_bar):
    rest = solve_fk(five_bar, np.zeros(2)).state

    def total(motors):
        return jnp.sum(solve_fk(five_bar, motors, start=rest).state)

    motors = _motors(3)
    grad = jax.grad(total)(jnp.asarray(motors))
    assert grad.shape == (3, 2) and np.all(np.isfinite(grad))
    step = 1e-6
    bumped = motors.copy()
    bumped[1, 0] += step
    numeric = (total(bumped) - total(motors)) / step
    assert float(grad[1, 0]) == pytest.approx(float(numeric), rel=1e-4, abs=1e-6)


def test_a_new_process_reads_the_solves_traces_from_disk(five_bar, monkeypatch):
    """The blocked solves, σ_min and read-outs keep their traces on disk
    (linkopt._engine.programs): with this process's programs forgotten, as in a new
    process, none of them is traced again, and the numbers are the same."""
    from linkopt._engine import programs

    motors = _motors(BLOCK + 2, 5)
    first = solve_fk(five_bar, motors)
    sigmas = f_sing(five_bar, first.state)
    outputs = output_values(five_bar, first.state)
    path = solve_fk_path(five_bar, motors[:4])
    monkeypatch.setattr(programs, "PROGRAMS", {})
    traced = []
    real_export = programs.export.export

    def recording(fn, *args, **kwargs):
        traced.append(getattr(fn, "__name__", fn))
        return real_export(fn, *args, **kwargs)

    monkeypatch.setattr(programs.export, "export", recording)
    again = solve_fk(five_bar, motors)
    np.testing.assert_array_equal(np.asarray(again.state), np.asarray(first.state))
    np.testing.assert_array_equal(f_sing(five_bar, again.state), sigmas)
    np.testing.assert_array_equal(output_values(five_bar, again.state), outputs)
    np.testing.assert_array_equal(solve_fk_path(five_bar, motors[:4]).state, path.state)
    assert traced == []
    assert {name for name, *_ in programs.PROGRAMS} >= {
        "from_rest_fk",
        "sigmas",
        "read_outputs",
        "path_fk",
    }
