"""The hot-path programs contain no LAPACK custom call, and the batched-LAPACK deadlock
of jaxlib (linkopt._config) cannot come back: ``jit(vmap(grad(f_sing ∘ FK)))`` finishes
in a process whose XLA thread pool has its default size."""

import os
import re
import subprocess
import sys
import textwrap

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt  # noqa: F401  (float64)
from linkopt._engine import kinematics, singularity
from linkopt._engine.geometry import design_vector, rest_state

CUSTOM_CALL = re.compile(r"custom_call @(\w+)")


def lapack_calls(lowered) -> set[str]:
    """LAPACK (and any other ``lapack_*``) custom-call targets in a lowered program."""
    return {t for t in CUSTOM_CALL.findall(lowered.as_text()) if "lapack" in t}


def test_the_check_sees_lapack_calls():
    """The pattern finds the targets jnp.linalg lowers to (so an empty set means
    none)."""
    lowered = jax.jit(
        lambda a: (
            jnp.linalg.cholesky(a),
            jnp.linalg.eigh(a)[0],
            jnp.linalg.solve(a, a),
        )
    ).lower(jnp.eye(3))
    assert lapack_calls(lowered) == {
        "lapack_dpotrf_ffi",
        "lapack_dsyevd_ffi",
        "lapack_dgetrf_ffi",
        "lapack_dtrsm_ffi",  # solve's triangular solves
    }


def _motors(mech, n):
    rng = np.random.default_rng(0)
    return rng.uniform(-0.05, 0.05, (n, mech.num_motors)) * mech.motor_scale


def test_kinematics_and_singularity_programs_have_no_lapack(five_bar):
    mech = five_bar
    motors = jnp.asarray(_motors(mech, 8))
    rest = rest_state(mech)
    states = jnp.broadcast_to(rest, (8,) + rest.shape)
    outputs = jnp.zeros((8, mech.num_outputs))
    programs = {
        "fk from rest": kinematics.solve_batch_from_rest.lower(
            mech, "fk", motors, None
        ),
        "fk warm": kinematics.solve_batch.lower(mech, "fk", motors, states, None),
        "bk warm": kinematics.solve_batch.lower(mech, "bk", outputs, states, None),
        "f_sing": singularity.sigma_pairs.lower(mech, states, None),
        "sensitivity": jax.jit(
            jax.vmap(
                jax.jacfwd(
                    lambda a, s: kinematics.solve_batch(mech, "fk", a, s, None).state
                )
            )
        ).lower(motors, states),
        "design sensitivity": jax.jit(
            jax.jacrev(
                lambda p: kinematics.solve_batch(
                    mech, "fk", motors, states, p
                ).state.sum()
            )
        ).lower(jnp.asarray(mech.design.p0)),
    }
    assert {k: lapack_calls(v) for k, v in programs.items()} == {
        k: set() for k in programs
    }


def _evaluation_programs(mech):
    from linkopt._design.evaluation import alpha_minus, evaluate_homogenised
    from linkopt._design.partial import gradients_homogenised

    designs = jnp.asarray(np.stack([design_vector(mech, None)] * 2))
    alpha = jnp.asarray(alpha_minus(mech))
    evaluate = jax.jit(lambda p, a: evaluate_homogenised(mech, p, a))
    gradient = jax.jit(lambda p, ev, a: gradients_homogenised(mech, p, ev, a))
    return evaluate, gradient, designs, alpha


def test_design_evaluation_has_no_lapack(five_bar):
    evaluate, _, designs, alpha = _evaluation_programs(five_bar)
    assert lapack_calls(evaluate.lower(designs, alpha)) == set()


def test_partial_gradient_has_no_lapack(five_bar):
    evaluate, gradient, designs, alpha = _evaluation_programs(five_bar)
    shapes = jax.eval_shape(evaluate, designs, alpha)
    assert lapack_calls(gradient.lower(designs, shapes, alpha)) == set()


DEADLOCK = """
import jax, jax.numpy as jnp, numpy as np, linkopt
from linkopt._engine.constraints import homogenised_motor_values
from linkopt._engine.geometry import design_vector, geometry, rest_state
from linkopt._engine.kinematics import solve_single
from linkopt._engine.singularity import f_sing_value
mech = linkopt.load({path!r})
geom = geometry(mech, design_vector(mech, None))
rest = rest_state(mech)
a0 = homogenised_motor_values(mech, geom, rest)
def f(a):
    return f_sing_value(mech, geom, solve_single(mech, "fk", geom, a, rest).state)
batch = a0 + np.random.default_rng(0).uniform(-0.02, 0.02, (256, a0.shape[0]))
for _ in range(5):
    out = np.asarray(jax.jit(jax.vmap(jax.grad(f)))(batch))
assert out.shape == batch.shape and np.all(np.isfinite(out))
print("ok")
"""


def test_batched_gradient_of_f_sing_does_not_deadlock(tmp_path):
    """Before linkopt._engine.dense this hung for ever on a 2-core machine without
    ``PJRT_NPROC=1``; the timeout turns a hang into a failure."""
    env = {k: v for k, v in os.environ.items() if k != "PJRT_NPROC"}
    code = textwrap.dedent(DEADLOCK.format(path=str(MECHANISMS / "five_bar.toml")))
    try:
        out = subprocess.run(
            [sys.executable, "-c", code],
            env=env,
            capture_output=True,
            text=True,
            timeout=180,
        )
    except subprocess.TimeoutExpired:
        pytest.fail("jit(vmap(grad(f_sing ∘ FK))) did not finish in 180 s (deadlock?)")
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.startswith("ok")


def test_linkopt_leaves_the_thread_pool_alone():
    env = {k: v for k, v in os.environ.items() if k != "PJRT_NPROC"}
    code = "import os, linkopt; print(os.environ.get('PJRT_NPROC'))"
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, capture_output=True, text=True
    )
    assert out.stdout.strip() == "None", out.stderr[-2000:]
