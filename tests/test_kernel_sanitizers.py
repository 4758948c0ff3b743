"""dense.cc under AddressSanitizer and UndefinedBehaviorSanitizer: the harness
tests/kernels_harness.cc (no JAX, no Python) calls every handler on orders 0-513,
batches 0-9, singular, indefinite, NaN, Inf, huge and tiny matrices, misaligned and
empty operands, results over their operands and six threads at once, and checks that
a batch's matrices get bitwise the results they get alone. Any sanitizer report ends it
with a failure. The dense.cc of commit b3fad56 (before this harness) failed it at its
memset of a null pointer for an empty operand."""

from __future__ import annotations

import os
import re
import subprocess
import sysconfig

import pytest
from cxx import HARNESS, KERNELS, compile_cxx, compiler_or_skip, ffi_include

SANITIZERS = ["-fsanitize=address,undefined", "-fno-sanitize-recover=all"]


@pytest.mark.slow
def test_every_handler_runs_clean_under_the_sanitizers(tmp_path):
    compiler_or_skip()
    flags = ["-O1", "-g", "-fno-omit-frame-pointer", "-pthread", *SANITIZERS]
    flags += ["-fno-fast-math", "-ffp-contract=off"]
    if re.match(r"x86_64|amd64", sysconfig.get_platform().split("-")[-1]):
        flags.append("-march=x86-64-v2")
    binary = tmp_path / "harness"
    built = compile_cxx(
        flags
        + ["-isystem", str(ffi_include()), "-I", str(KERNELS), str(HARNESS)]
        + ["-o", str(binary)]
    )
    if built.returncode != 0 and "sanitizer" in built.stderr.lower():
        pytest.skip(f"this compiler cannot build with the sanitizers: {built.stderr}")
    assert built.returncode == 0, built.stderr[-4000:]
    env = dict(os.environ)
    env["ASAN_OPTIONS"] = "detect_leaks=1:abort_on_error=0:halt_on_error=1"
    env["UBSAN_OPTIONS"] = "print_stacktrace=1:halt_on_error=1"
    done = subprocess.run(
        [str(binary)], capture_output=True, text=True, timeout=600, env=env
    )
    report = done.stdout[-2000:] + done.stderr[-6000:]
    assert done.returncode == 0, report
    assert "runtime error" not in done.stderr and "Sanitizer" not in done.stderr, report
    assert re.search(r"^\d+ cases, 0 failures$", done.stdout, re.M), report
