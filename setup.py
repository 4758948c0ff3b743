"""The compiled part of linkopt: ``linkopt._kernels._dense``, XLA FFI handlers for
batched dense linear algebra (``linkopt/_kernels/dense.cc``).

Everything else about the package is in ``pyproject.toml``; setuptools reads both. The
extension is optional: without a C++17 compiler, or without JAX's FFI headers (from
``jax.ffi.include_dir()``; ``[build-system] requires`` installs jax and jaxlib), the
build leaves it out with a warning and linkopt installs without it
(:func:`linkopt._kernels.handlers` then returns None and linkopt uses its plain-JAX
code).
"""

import hashlib
import platform
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext
from setuptools.errors import CompileError

SOURCE = "linkopt/_kernels/dense.cc"
#: x86-64 only: the baseline every x86-64 CPU since about 2009 has (SSE4.2, POPCNT);
#: never -march=native, which would tie the build to the building machine's CPU
X86_64_FLAGS = ["-march=x86-64-v2"]
#: IEEE arithmetic, stated rather than assumed (a user's CFLAGS, or a compiler whose
#: default is fast math, icx): no fused multiply-adds (-ffp-contract=off), so the
#: handlers round as the plain-JAX code's steps do and the paths that factor several
#: matrices at once as the one-matrix path; NaN and Inf kept (std::isnan and
#: !(d > 0) not folded away); no reassociation or reciprocals
IEEE_FLAGS = [
    "-fno-fast-math",
    "-fno-unsafe-math-optimizations",
    "-fno-finite-math-only",
    "-ffp-contract=off",
]
MSVC_IEEE_FLAGS = ["/fp:precise"]


def _jaxlib_version() -> str:
    """The version of the jaxlib whose FFI headers build the extension ("" if none)."""
    try:
        import jaxlib

        return jaxlib.__version__
    except Exception:
        return ""


def _include_dir() -> str | None:
    try:
        import jax

        ffi = getattr(jax, "ffi", None)
        if ffi is None:  # jax < 0.4.38
            import jax.extend.ffi as ffi
        return ffi.include_dir()
    except Exception as exc:  # no jax, or one without the FFI headers
        print(
            f"linkopt: building without linkopt._kernels._dense ({exc!r}: no XLA FFI "
            "headers)",
            file=sys.stderr,
        )
        return None


class BuildExt(build_ext):
    """Compiler-specific flags; on x86-64, retried without :data:`X86_64_FLAGS` if
    the compiler refuses them (an older GCC or Clang, or a universal2 macOS build)."""

    def build_extension(self, ext):
        if self.compiler.compiler_type == "msvc":
            ext.extra_compile_args = ["/std:c++17", "/O2", "/EHsc", *MSVC_IEEE_FLAGS]
            return super().build_extension(ext)
        # -g0: no debug information (Python's own flags add -g); IEEE_FLAGS last, so
        # they override fast math from $CFLAGS (dense.cc also refuses __FAST_MATH__)
        base = ["-std=c++17", "-O3", "-g0", "-fvisibility=hidden", *IEEE_FLAGS]
        # XLA's FFI headers as system headers: their own warnings are not dense.cc's
        # (which builds without one under -Wall -Wextra)
        base += [f"-isystem{path}" for path in ext.include_dirs]
        ext.include_dirs = []
        machine = platform.machine().lower()
        arch = X86_64_FLAGS if machine in ("x86_64", "amd64") else []
        ext.extra_compile_args = base + arch
        try:
            return super().build_extension(ext)
        except CompileError:
            if not arch:
                raise
            self.warn(f"building {ext.name} again without {' '.join(arch)}")
            ext.extra_compile_args = base
            return super().build_extension(ext)


def _extensions() -> list[Extension]:
    include = _include_dir()
    if include is None:
        return []
    digest = hashlib.sha256((Path(__file__).parent / SOURCE).read_bytes()).hexdigest()
    return [
        Extension(
            "linkopt._kernels._dense",
            sources=[SOURCE],
            include_dirs=[include],
            define_macros=[
                ("LK_SOURCE_SHA256", f'"{digest}"'),
                ("LK_JAXLIB_VERSION", f'"{_jaxlib_version()}"'),
            ],
            language="c++",
            optional=True,
        )
    ]


setup(ext_modules=_extensions(), cmdclass={"build_ext": BuildExt})
