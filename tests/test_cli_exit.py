"""The command line's own process ends once its command returns and its output is
flushed, without the interpreter's teardown (:func:`linkopt._cli.main._exit_now`): the
same exit status and the whole output as the command run in-process."""

import os
import subprocess
import sys
from pathlib import Path

from linkopt._cli.main import main

ROOT = Path(__file__).resolve().parent.parent


def _command(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run(
        [sys.executable, "-m", "linkopt._cli.main", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )


def test_the_process_ends_with_the_status_and_whole_output(capsys, tmp_path):
    """A command that succeeds (``check``: its whole report on stdout, piped, so
    block-buffered until the flush) and one refused (status 2, its line on stderr)
    end their process as they return in-process."""
    file = str(ROOT / "mechanisms/five_bar.toml")
    assert main(["check", file]) == 0
    expected = capsys.readouterr().out
    done = _command("check", file)
    assert done.returncode == 0 and done.stdout == expected and expected
    missing = str(tmp_path / "none.toml")
    assert main(["check", missing]) == 2
    expected_err = capsys.readouterr().err
    refused = _command("check", missing)
    assert refused.returncode == 2 and refused.stderr == expected_err


def test_a_reader_that_leaves_early_is_no_error():
    """``linkopt check FILE | head -1``: the reader closes the pipe; the process
    still ends with status 0 and no traceback."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "linkopt._cli.main",
            "check",
            "mechanisms/five_bar.toml",
        ],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    proc.stdout.close()  # the reader left before reading anything
    assert proc.wait(timeout=600) == 0
    assert b"Traceback" not in proc.stderr.read()
