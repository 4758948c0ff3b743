"""The compiled kernels (linkopt._kernels, called by linkopt._engine.dense) against the
plain-JAX code they replace: a fresh process with ``LINKOPT_KERNELS=0`` computes the
same things, and the two must agree to round-off, for the dense routines (values,
vmapped batches, derivatives) and for what users see (forward kinematics, σ_min, a
design evaluation). Both processes use the test processes' compilation caches, as the
command line does: a program's key holds the kernels' digest or "plain"
(:func:`linkopt._engine.programs.kernels_digest`), so neither loads the other's."""

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine import dense

pytestmark = pytest.mark.skipif(
    dense.TARGETS is None,
    reason="the compiled extension is not built here (linkopt._kernels)",
)

#: Computed in both processes: JSON of lists, from the same seeds.
SCRIPT = """
import json, sys
import jax, jax.numpy as jnp, numpy as np
import linkopt
from linkopt._engine import dense
linkopt.use_cache()  # the test processes' caches: programs other tests compiled load
rng = np.random.default_rng(0)
m = rng.standard_normal((6, 35, 35))
a = jnp.asarray(m @ np.swapaxes(m, 1, 2) + 35 * np.eye(35))
b = jnp.asarray(rng.standard_normal((6, 35, 3)))
v = jnp.asarray(rng.standard_normal((6, 35)))
lower = jax.vmap(dense.cholesky)(a)
out = {
    "kernels": dense.TARGETS is not None,
    "cholesky": lower,
    "cho_solve": jax.vmap(dense.cho_solve)(lower, b),
    "cho_solve_vector": jax.vmap(dense.cho_solve)(lower, v),
    "solve_lower": jax.vmap(dense.solve_lower)(lower, b),
    "solve_lower_transpose": jax.vmap(dense.solve_lower_transpose)(lower, v),
    "lower_inverse": jax.vmap(dense.lower_inverse)(lower),
    "damped_solve": jax.vmap(dense.damped_solve)(a, jnp.linspace(0.0, 1.0, 6), v),
    "solve_spd_grad": jax.grad(lambda x: jnp.sum(dense.solve_spd(a[0] * x, v[0]) ** 2))(
        1.3
    ),
    "cholesky_jvp": jax.jvp(dense.cholesky, (a[0],), (a[1],))[1],
}
mech = linkopt.load(sys.argv[1])
motors = 0.3 * (2 * rng.random((40, mech.num_motors)) - 1)
fk = linkopt.solve_fk(mech, motors)
out["fk_state"] = fk.state
out["fk_converged"] = fk.converged
out["sigmas"] = linkopt.singular_values(mech, fk.state)
out["f_design"] = linkopt.evaluate(mech).f_design
print(json.dumps({k: np.asarray(v).tolist() for k, v in out.items()}))
"""


def _computed(env: dict) -> dict:
    run = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(MECHANISMS / "five_bar.toml")],
        env={**os.environ, **env},
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return {k: np.asarray(v) for k, v in json.loads(run.stdout).items()}


@pytest.fixture(scope="module")
def both():
    return _computed({}), _computed({"LINKOPT_KERNELS": "0"})


def test_each_process_took_the_path_asked(both):
    kernels, plain = both
    assert kernels["kernels"] and not plain["kernels"]


@pytest.mark.parametrize(
    "name",
    [
        "cholesky",
        "cho_solve",
        "cho_solve_vector",
        "solve_lower",
        "solve_lower_transpose",
        "lower_inverse",
        "damped_solve",
        "solve_spd_grad",
        "cholesky_jvp",
    ],
)
def test_dense_routines_agree_with_the_plain_code(both, name):
    kernels, plain = both
    np.testing.assert_allclose(kernels[name], plain[name], rtol=1e-12, atol=1e-14)


def test_forward_kinematics_sigma_and_evaluation_agree(both):
    kernels, plain = both
    np.testing.assert_array_equal(kernels["fk_converged"], plain["fk_converged"])
    np.testing.assert_allclose(kernels["fk_state"], plain["fk_state"], atol=1e-12)
    np.testing.assert_allclose(kernels["sigmas"], plain["sigmas"], rtol=1e-9)
    np.testing.assert_allclose(kernels["f_design"], plain["f_design"], rtol=1e-9)


def test_the_kernels_vmap_and_nest_in_this_process():
    """A nested vmap and a shared right-hand side (broadcast) give the single
    results."""
    rng = np.random.default_rng(1)
    m = rng.standard_normal((2, 3, 7, 7))
    a = jnp.asarray(m @ np.swapaxes(m, -1, -2) + 7 * np.eye(7))
    lower = jax.vmap(jax.vmap(dense.cholesky))(a)
    np.testing.assert_allclose(lower[1, 2], np.linalg.cholesky(a[1, 2]), atol=1e-12)
    b = jnp.asarray(rng.standard_normal(7))
    x = jax.vmap(jax.vmap(dense.cho_solve, (0, None)), (0, None))(lower, b)
    np.testing.assert_allclose(x[0, 1], np.linalg.solve(a[0, 1], b), rtol=1e-10)


def test_a_failed_factor_is_nan_from_its_pivot():
    a = np.eye(5)
    a[3, 3] = -1.0
    lower = np.asarray(jax.jit(dense.cholesky)(jnp.asarray(a)))
    np.testing.assert_array_equal(lower[:3, :3], np.eye(3))
    assert np.isnan(lower[3, 3]) and np.isnan(lower[4, 4])


def test_programs_that_call_the_kernels_export_and_run_again(tmp_path):
    """A serialised program calls the kernels by name: deserialised, it runs."""
    exported = jax.export.export(
        jax.jit(lambda a: dense.cholesky(a)), disabled_checks=dense.EXPORT_CHECKS
    )(jax.ShapeDtypeStruct((4, 4), jnp.float64))
    again = jax.export.deserialize(exported.serialize())
    a = 2.0 * np.eye(4) + 0.5
    np.testing.assert_allclose(again.call(a), np.linalg.cholesky(a), atol=1e-14)
    assert linkopt  # float64 on


def test_a_matrix_larger_than_the_kernels_take_runs_the_plain_code():
    """An order above the kernels' limit (a mechanism of more than 73 bodies) is not
    refused: the plain-JAX code factors it."""
    n = dense.KERNEL_MAX_N + 1
    a = np.eye(n) * 4.0 + 0.01
    lower = np.asarray(jax.jit(dense.cholesky)(jnp.asarray(a)))
    np.testing.assert_allclose(lower @ lower.T, a, atol=1e-12)
    x = np.asarray(jax.jit(dense.cho_solve)(lower, jnp.ones(n)))
    np.testing.assert_allclose(a @ x, np.ones(n), atol=1e-10)
