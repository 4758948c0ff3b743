"""The closed-form block Jacobians against jax.jacfwd of the residuals, for every joint
family, motor kind and output kind, at perturbed (off-manifold) states and designs."""

import tomllib
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS, ROOT

import linkopt
from linkopt._engine import dense
from linkopt._engine.constraints import bk_residual, fk_residual
from linkopt._engine.jacobian import (
    linearise,
    normal_equations,
    normal_system,
    state_jacobian,
)
from linkopt._files.loader import build

FILES = [
    MECHANISMS / "five_bar.toml",
    MECHANISMS / "jansen_1dof.toml",
    ROOT / "tests/data/all_families.toml",
]


def _tait_bryan_variant(data: dict) -> dict:
    """The all-families file with its joint-angle outputs moved onto the spherical joint
    (third angle, in a frame given to it) and the universal joint (first angle)."""
    joint = next(j for j in data["joints"] if j["name"] == "s1")
    joint.update(axis=[0.3, 1.0, 0.1], axis2=[1.0, -0.3, 0.0])
    data["outputs"][0].update(joint="s1", angle=3)
    data["outputs"][2].update(joint="u1", angle=1)
    return data


VARIANTS = [(path, None) for path in FILES] + [
    (FILES[-1], _tait_bryan_variant),
    (FILES[-1], "parts"),
]


@pytest.mark.parametrize(
    "path, variant",
    VARIANTS,
    ids=[p.stem for p in FILES] + ["tait_bryan_outputs", "fixed_joint_unwelded"],
)
def test_linearise_matches_jacfwd(path, variant):
    # the all-families file is arbitrary geometry, not an assemblable linkage: no
    # mobility check. Loaded, its fixed joint's bodies are one
    # (linkopt._engine.welding); "parts" checks the fixed joint's own rows, on the
    # file's bodies.
    data = tomllib.loads(path.read_text())
    if variant == "parts":
        mech = build(data, str(path), check=False).welds.parts
        assert "fixed" in mech.joint_types
    else:
        mech = build(variant(data) if variant else data, str(path), check=False)
    rng = np.random.default_rng(3)
    design = mech.design.p0 + rng.normal(0, 0.01, mech.design.size) * (
        mech.design.upper - mech.design.lower
    )
    geom = linkopt.geometry(mech, design)
    kinds = (
        ("fk", fk_residual, mech.num_motors),
        ("bk", bk_residual, mech.num_outputs),
    )
    # one program per kind, as the solvers run it (jitted), for the three states: op
    # by op, each of the Jacobian's thousand small operations compiled on its own
    # costs more than the whole program's compile
    compared = {kind: _linearised_and_reference(mech, kind, r) for kind, r, _ in kinds}
    for _ in range(3):
        state = linkopt.rest_state(mech) + rng.normal(0, 0.05, mech.state_size)
        for kind, _residual, size in kinds:
            values = jnp.asarray(rng.normal(0, 0.1, size))
            (value, jac), reference, (c, jtj, jtc) = compared[kind](geom, values, state)
            np.testing.assert_allclose(value, reference[0], atol=1e-13)
            np.testing.assert_allclose(jac, reference[1], atol=1e-12)
            np.testing.assert_allclose(jtj, jac.T @ jac, atol=1e-11)
            np.testing.assert_allclose(jtc, jac.T @ value, atol=1e-11)


def _linearised_and_reference(mech, kind, residual):
    """``(geom, values, state)`` -> linearise's ``(value, jac)``, the residual and
    its ``jacfwd``, and ``normal_equations``, in one jitted program."""

    def both(geom, values, state):
        reference = (
            residual(mech, geom, values, state),
            jax.jacfwd(partial(residual, mech, geom, values))(state),
        )
        return (
            linearise(mech, geom, kind, values, state),
            reference,
            normal_equations(mech, geom, kind, values, state),
        )

    return jax.jit(both)


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.stem)
@pytest.mark.parametrize("kind", ["fk", "bk"])
def test_normal_equations_paths_agree(path, kind, monkeypatch):
    """The compiled kernel's assembly (where built) and the plain-JAX block sums (the
    fallback) give the same normal equations, at an off-manifold state."""
    mech = build(tomllib.loads(path.read_text()), str(path), check=False)
    geom = linkopt.geometry(mech, None)
    rng = np.random.default_rng(7)
    state = np.asarray(linkopt.rest_state(mech))
    state = state + 0.05 * rng.normal(size=state.shape)
    values = 0.1 * rng.normal(
        size=(mech.num_motors if kind == "fk" else mech.num_outputs)
    )

    def program():
        fn = jax.jit(lambda s: normal_system(mech, geom, kind, values, s))
        return fn(state), str(jax.make_jaxpr(fn)(state))

    served = dense.serves_block_normal(jnp.zeros((1, 14)), mech.state_size)
    kernel, kernel_jaxpr = program()
    monkeypatch.setattr(dense, "serves_block_normal", lambda *a: False)
    plain, plain_jaxpr = program()
    for a, b in zip(kernel, plain, strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12)
    assert "normal_equations" not in plain_jaxpr
    assert ("normal_equations" in kernel_jaxpr) == served


def test_jacobian_is_differentiable_in_design():
    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    state = linkopt.solve_fk(mech, np.array([0.2, -0.1])).state

    def probe(p):
        return jnp.sum(
            state_jacobian(mech, linkopt.geometry(mech, p), "fk", state) ** 2
        )

    def reference(p):
        geom = linkopt.geometry(mech, p)
        motors = jnp.zeros(2)
        return jnp.sum(
            jax.jacfwd(lambda s: fk_residual(mech, geom, motors, s))(state) ** 2
        )

    p0 = jnp.asarray(mech.design.p0)
    np.testing.assert_allclose(jax.grad(probe)(p0), jax.grad(reference)(p0), rtol=1e-10)
