"""Building ``linkopt/_kernels/dense.cc`` inside a test: the machine's C++ compiler,
the include folders, and one compile command (tests/test_kernel_build.py,
tests/test_kernel_sanitizers.py)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sysconfig
from pathlib import Path

import pytest

KERNELS = Path(__file__).parents[1] / "linkopt" / "_kernels"
SOURCE = KERNELS / "dense.cc"
HARNESS = Path(__file__).with_name("kernels_harness.cc")


def compiler() -> str | None:
    """The C++ compiler: ``$CXX``, else ``c++``, ``g++`` or ``clang++`` on the PATH
    (None where there is none)."""
    for name in filter(None, (os.environ.get("CXX"), "c++", "g++", "clang++")):
        found = shutil.which(name)
        if found:
            return found
    return None


def compiler_or_skip() -> str:
    """:func:`compiler`, or skip the test, saying why."""
    found = compiler()
    if found is None:
        pytest.skip("no C++ compiler on this machine ($CXX, c++, g++, clang++)")
    return found


def ffi_include() -> Path:
    """The XLA FFI headers of the installed jaxlib."""
    import jax

    return Path(jax.ffi.include_dir())


def python_include() -> str:
    return sysconfig.get_paths()["include"]


def compile_cxx(args: list[str], timeout: float = 300) -> subprocess.CompletedProcess:
    """Run the compiler with ``args`` (C++17); its output captured."""
    return subprocess.run(
        [compiler_or_skip(), "-std=c++17", *args],
        capture_output=True,
        text=True,
        timeout=timeout,
    )
