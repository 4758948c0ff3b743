"""Building and guarding the compiled kernels (linkopt._kernels, dense.cc): an extension
built against a newer XLA FFI than the running jaxlib is refused with one warning and
every computation still runs (also when XLA itself refuses the registration), the
versions `linkopt cache info` reports, fast math refused at build time, no compiler
warning under -Wall -Wextra, no large stack frame outside the scratch's own function,
and empty operands returning at once."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
import sysconfig
from pathlib import Path

import jax
import jax.numpy as jnp
import pytest
from cxx import SOURCE, compile_cxx, compiler_or_skip, ffi_include, python_include

import linkopt  # noqa: F401  (float64)
import linkopt._kernels as kernels
from linkopt._engine import dense

BUILT = kernels.max_n() is not None


def test_the_ffi_api_version_is_read_from_a_header():
    text = "#define XLA_FFI_API_MAJOR 0\n// x\n#  define XLA_FFI_API_MINOR 12\n"
    assert kernels.header_ffi_api_version(text) == (0, 12)
    assert kernels.header_ffi_api_version("#define XLA_FFI_API_MAJOR 0\n") is None


@pytest.mark.parametrize(
    "built, running, ok",
    [
        ((0, 3), (0, 3), True),
        ((0, 2), (0, 3), True),
        ((0, 4), (0, 3), False),
        ((1, 0), (0, 3), False),
        ((0, 3), (1, 3), False),
        ((0, 4), None, True),
    ],
)
def test_a_build_is_compatible_with_the_same_major_and_no_newer_minor(
    built, running, ok
):
    assert kernels.ffi_compatible(built, running) is ok


def test_the_running_ffi_version_is_that_of_jax_ffi_include_dir():
    header = ffi_include() / "xla" / "ffi" / "api" / "c_api.h"
    expected = kernels.header_ffi_api_version(header.read_text())
    assert expected is not None
    assert kernels.running_ffi_api_version() == expected
    import jaxlib

    assert kernels.running_jaxlib_version() == jaxlib.__version__


@pytest.mark.skipif(not BUILT, reason="linkopt._kernels._dense is not built")
def test_info_reports_the_build_and_the_running_versions():
    info = kernels.info()
    import jaxlib

    assert info["available"] and info["path"] == "compiled kernels"
    assert tuple(info["ffi_api_version"]) == info["running_ffi_api_version"]
    assert info["built_jaxlib"] == jaxlib.__version__
    assert info["running_jaxlib"] == jaxlib.__version__


#: Run in a fresh process with the extension at argv[1] in place of linkopt's own;
#: argv[2] == "force" skips linkopt's version check, so that XLA's registration itself
#: refuses it. Checks every kind of computation against closed forms, and prints the
#: warnings, what dense registered and what `linkopt cache info` printed.
SCRIPT = r"""
import contextlib, importlib.util, io, json, sys, warnings
spec = importlib.util.spec_from_file_location("linkopt._kernels._dense", sys.argv[1])
module = importlib.util.module_from_spec(spec)
spec.loader.exec_module(module)
sys.modules["linkopt._kernels._dense"] = module
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    import linkopt._kernels as kernels
    if sys.argv[2] == "force":
        kernels.ffi_compatible = lambda built, running: True
    import jax, jax.numpy as jnp, numpy as np
    import linkopt
    from linkopt._engine import dense, singularity
    from linkopt._cli.main import main
    rng = np.random.default_rng(0)
    m = rng.standard_normal((3, 7, 7))
    a = jnp.asarray(m @ m.transpose(0, 2, 1) + np.eye(7))
    b = jnp.asarray(rng.standard_normal((3, 7)))
    lower = jax.jit(jax.vmap(dense.cholesky))(a)
    assert np.allclose(lower @ jnp.swapaxes(lower, 1, 2), a, atol=1e-12)
    x = jax.vmap(dense.solve_spd)(a, b)
    assert np.allclose(jnp.einsum("bij,bj->bi", a, x), b, atol=1e-10)
    y = jax.vmap(dense.damped_solve)(a, jnp.full(3, 0.5), b)
    assert np.allclose(jnp.einsum("bij,bj->bi", a + 0.5 * np.eye(7), y), b, atol=1e-10)
    inverse = jax.vmap(dense.lower_inverse)(lower)
    assert np.allclose(inverse @ lower, np.eye(7), atol=1e-10)
    grad = jax.grad(lambda a: dense.solve_spd(a, b[0]).sum())(a[0])
    assert np.isfinite(grad).all()
    jac = jnp.asarray(rng.standard_normal((4, 9, 7)))
    v = singularity.smallest_right_vectors(jac)
    expected = np.linalg.svd(np.asarray(jac))[2][:, -1]
    assert np.allclose(np.abs(np.einsum("bi,bi->b", v, expected)), 1.0, atol=1e-8)
    assert float(jnp.ones(3).sum()) == 3.0
    out = io.StringIO()
    with contextlib.redirect_stdout(out):
        assert main(["cache", "info"]) == 0
print(json.dumps({
    "warnings": [str(w.message) for w in caught
                 if issubclass(w.category, kernels.KernelsWarning)],
    "targets": dense.TARGETS,
    "info": out.getvalue(),
    "reason": kernels.reason,
}))
"""


@pytest.fixture(scope="module")
def newer_ffi_extension(tmp_path_factory) -> Path:
    """dense.cc built (at -O0: it is never run) against a copy of the installed FFI
    headers whose XLA_FFI_API_MINOR is one above the running jaxlib's."""
    compiler_or_skip()
    folder = tmp_path_factory.mktemp("newer_ffi")
    shutil.copytree(ffi_include() / "xla", folder / "include" / "xla")
    header = folder / "include" / "xla" / "ffi" / "api" / "c_api.h"
    major, minor = kernels.header_ffi_api_version(header.read_text())
    header.write_text(
        re.sub(
            r"#define XLA_FFI_API_MINOR \d+",
            f"#define XLA_FFI_API_MINOR {minor + 1}",
            header.read_text(),
        )
    )
    target = folder / f"_dense{sysconfig.get_config_var('EXT_SUFFIX')}"
    built = compile_cxx(
        [
            "-O0",
            "-shared",
            "-fPIC",
            "-isystem",
            str(folder / "include"),
            "-I",
            python_include(),
            '-DLK_JAXLIB_VERSION="99.0"',
            str(SOURCE),
            "-o",
            str(target),
        ]
    )
    assert built.returncode == 0, built.stderr[-3000:]
    return target


def _run(extension: Path, mode: str, monkeypatch) -> dict:
    monkeypatch.delenv(kernels.ENVIRONMENT, raising=False)
    done = subprocess.run(
        [sys.executable, "-c", SCRIPT, str(extension), mode],
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-4000:]
    return json.loads(done.stdout.strip().splitlines()[-1])


@pytest.mark.slow
def test_an_extension_built_against_a_newer_ffi_is_refused(
    newer_ffi_extension, monkeypatch
):
    """The version check refuses it before XLA sees it: one warning that names both
    versions and how to rebuild, nothing registered, every computation runs on the
    plain-JAX path, and `linkopt cache info` says so."""
    major, minor = kernels.running_ffi_api_version()
    result = _run(newer_ffi_extension, "check", monkeypatch)
    assert result["targets"] is None
    (warning,) = result["warnings"]
    assert f"XLA FFI API {major}.{minor + 1} (jaxlib 99.0)" in warning
    assert f"(XLA FFI API {major}.{minor})" in warning
    assert "--no-build-isolation" in warning and "build_ext --inplace" in warning
    assert "compiled kernels: not in use, plain JAX" in result["info"]
    assert (
        f"built against jaxlib 99.0, XLA FFI API {major}.{minor + 1}" in result["info"]
    )


@pytest.mark.slow
def test_a_registration_xla_refuses_leaves_jax_working(
    newer_ffi_extension, monkeypatch
):
    """With linkopt's check skipped, XLA refuses the handler at registration (made to
    happen at once, not when the CPU backend starts): caught, one warning, and JAX
    and linkopt compute as without the kernels."""
    result = _run(newer_ffi_extension, "force", monkeypatch)
    assert result["targets"] is None
    (warning,) = result["warnings"]
    assert "XLA refused to register them" in warning
    assert "incompatible" in warning
    assert "XLA refused to register them" in result["reason"]
    assert "compiled kernels: not in use, plain JAX" in result["info"]


def test_fast_math_is_refused_at_build_time():
    """dense.cc stops the build when fast math is on (the preprocessor is enough)."""
    for flag in ("-ffast-math", "-Ofast", "-ffinite-math-only"):
        done = compile_cxx(
            ["-E", flag, "-DLK_NO_PYTHON", "-isystem", str(ffi_include()), str(SOURCE)]
        )
        assert done.returncode != 0, flag
        assert "must not be built with fast math" in done.stderr, flag
    done = compile_cxx(
        ["-E", "-DLK_NO_PYTHON", "-isystem", str(ffi_include()), str(SOURCE)]
    )
    assert done.returncode == 0, done.stderr[-2000:]


#: The largest stack frame, in bytes, of any function of dense.cc but the one that
#: holds the stack scratch (Cholesky's 4 KiB pivot column and a few hundred bytes).
MAX_FRAME = 16384


@pytest.mark.slow
def test_dense_cc_builds_without_warnings_and_with_small_frames(tmp_path):
    """-O3 -Wall -Wextra -Werror with setup.py's flags; -fstack-usage: only
    stack_scratch holds the 128 KiB scratch array, so a handler whose scratch is on
    the heap (or that needs none) keeps a small frame."""
    compiler_or_skip()
    flags = ["-O3", "-Wall", "-Wextra", "-Werror", "-fPIC", "-fvisibility=hidden"]
    flags += ["-fno-fast-math", "-ffp-contract=off", "-fstack-usage"]
    if re.match(r"x86_64|amd64", sysconfig.get_platform().split("-")[-1]):
        flags.append("-march=x86-64-v2")
    done = compile_cxx(
        flags
        + ["-isystem", str(ffi_include()), "-I", python_include(), "-c", str(SOURCE)]
        + ["-o", str(tmp_path / "dense.o")]
    )
    assert done.returncode == 0, done.stderr[-4000:]
    assert "warning" not in done.stderr, done.stderr[-4000:]
    usage = (tmp_path / "dense.su").read_text().splitlines()
    frames = {line.split("\t")[0]: int(line.split("\t")[1]) for line in usage}
    scratch = {k: v for k, v in frames.items() if "stack_scratch" in k}
    others = {k: v for k, v in frames.items() if "stack_scratch" not in k}
    assert scratch and min(scratch.values()) >= 16384 * 8
    assert max(others.values()) <= MAX_FRAME, max(others.items(), key=lambda kv: kv[1])


@pytest.mark.skipif(dense.TARGETS is None, reason="the kernels are not in use")
@pytest.mark.parametrize("shape", [(10**4, 0, 0), (0, 40, 40), (0, 0), (3, 0, 0)])
def test_empty_operands_return_at_once(shape):
    """Empty operands (no matrix, or matrices of order 0) give empty results, never
    an error, through XLA (tests/kernels_harness.cc calls the handlers themselves on
    empty buffers with null data)."""
    empty = jnp.zeros(shape)
    rhs = jnp.zeros(shape[:-1])

    def each(fn, *args):
        return (jax.jit(jax.vmap(fn)) if len(shape) == 3 else jax.jit(fn))(*args)

    for fn in (dense.cholesky, dense.lower_inverse):
        assert each(fn, empty).shape == shape
    for fn in (dense.solve_lower, dense.solve_lower_transpose, dense.cho_solve):
        assert each(fn, empty, rhs).shape == rhs.shape
        assert each(fn, empty, rhs[..., None]).shape == rhs.shape + (1,)
    damping = jnp.zeros(shape[:-2])
    assert each(dense.damped_solve, empty, damping, rhs).shape == rhs.shape
