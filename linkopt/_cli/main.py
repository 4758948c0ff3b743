"""Command line: ``linkopt check | fk | bk | evaluate | plot | verify | optimize |
sweep | synthesize | arm | cache``; a thin layer over the public API.

Each command family lives in its own module with a ``register(subparsers)``:
:mod:`.mechanism` (check, fk, bk), :mod:`.evaluation` (evaluate, plot), :mod:`.verify`,
:mod:`.optimize`, :mod:`.sweep`, :mod:`.synthesize`, and under ``arm`` :mod:`.arm`
(design, simplify), :mod:`.manipulability` and :mod:`.trace`. This module assembles
the parser and handles what every command shares.

Building the parser imports no part of the engine (nor JAX): the command modules import
it inside their handlers, and the defaults and limits the help shows come from the
JAX-free settings modules (:mod:`linkopt._design.settings`,
:mod:`linkopt._arms.dh.settings`, :mod:`linkopt._arms.trace.settings`). A handler
checks first what needs neither the file nor the engine, then reads the file
(:func:`.values.load`: an unreadable or malformed file is refused before the engine is
imported), and imports the engine only then, so that ``--help``, a usage error and a
bad flag or file answer at once.

The command line asks for linkopt's on-disk caches (:func:`linkopt.use_cache`), which a
library user may or may not: :func:`main` records the request without importing JAX,
and :mod:`linkopt._config` applies it when a command first sets JAX up.

Bad input exits with status 2 and one line on stderr (argparse's own errors too: the
usage text is left to ``--help``); a failed solve exits with 1.

The command line's own process (:func:`main` without ``argv``: the ``linkopt`` script,
``python -m linkopt``) ends as soon as its command returns and its output is flushed
(:func:`_exit_now`), without the interpreter's teardown of JAX and the loaded modules,
which took about 0.5 s after the main job's last line: every file a command writes is
closed by then, and its worker processes are ended.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import NoReturn

from .. import _cache
from .._errors import LinkoptError
from . import animate as animate_commands
from . import arm as arm_commands
from . import assemble as assemble_commands
from . import cache as cache_commands
from . import evaluation as evaluation_commands
from . import export as export_commands
from . import manipulability as manipulability_commands
from . import mechanism as mechanism_commands
from . import optimize as optimize_commands
from . import sweep as sweep_commands
from . import synthesize as synthesize_commands
from . import trace as trace_commands
from . import verify as verify_commands
from . import view as view_commands

# options whose values may start with "-" (negative numbers)
_VALUE_OPTIONS = ("--motors", "--outputs", "--design")


class _UsageError(Exception):
    """A command line argparse rejects: ``prog`` and argparse's message."""

    def __init__(self, prog: str, message: str):
        super().__init__(f"{prog}: error: {message}")


class _Parser(argparse.ArgumentParser):
    """An argument parser whose errors are one line (no usage text) and exit 2 through
    :func:`main`; its sub-command parsers are of the same class."""

    def error(self, message: str):
        raise _UsageError(self.prog, " ".join(message.split()))

    def _get_values(self, action, arg_strings):
        """As argparse's, but an option whose one value is ``--`` (``--out=--``, or
        ``--motors --`` joined by :func:`_join_value_options`) is refused: argparse
        strips the ``--`` and would hand the command an empty list for a value."""
        if action.option_strings and action.nargs is None and arg_strings == ["--"]:
            self.error(f"argument {action.option_strings[0]}: expected one argument")
        return super()._get_values(action, arg_strings)


def build_parser() -> argparse.ArgumentParser:
    """The ``linkopt`` argument parser, with every command."""
    parser = _Parser(
        prog="linkopt",
        description="Singularity-aware design of closed-loop spatial linkages.",
    )
    parser.add_argument(
        "--debug",
        action="store_true",
        help="show the Python traceback of an internal error",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    for family in (
        mechanism_commands,
        assemble_commands,
        evaluation_commands,
        verify_commands,
        optimize_commands,
        sweep_commands,
        synthesize_commands,
        export_commands,
        view_commands,
        animate_commands,
        cache_commands,
    ):
        family.register(sub)
    _add_arm_commands(sub)
    return parser


def _add_arm_commands(sub) -> None:
    arm = sub.add_parser("arm", help="serial-arm synthesis and co-design")
    arm_sub = arm.add_subparsers(dest="arm_command", required=True)
    for family in (arm_commands, manipulability_commands, trace_commands):
        family.register(arm_sub)


def _join_value_options(argv: list[str]) -> list[str]:
    """``--motors -0.1,0.2`` -> ``--motors=-0.1,0.2`` so negative values are not
    options."""
    joined: list[str] = []
    pending = False
    for token in argv:
        if pending and token.startswith("-"):
            joined[-1] = f"{joined[-1]}={token}"
        else:
            joined.append(token)
        pending = token in _VALUE_OPTIONS
    return joined


def _use_cache() -> None:
    """The caches on (module docstring): at once where JAX is set up for linkopt
    already (``main`` called in a Python process), else when it is."""
    _cache.request()
    config = sys.modules.get(f"{__package__.rpartition('.')[0]}._config")
    if config is not None:
        config.use_cache()


def main(argv: list[str] | None = None) -> int:
    """Run the command ``argv`` (default: this process's arguments) and return its exit
    status; without ``argv`` the process ends with it (:func:`_exit_now`)."""
    if argv is not None:
        return _main(argv)
    _exit_now(_main(sys.argv[1:]))


def _exit_now(status: int) -> NoReturn:
    """End this process with ``status`` once stdout and stderr are flushed, skipping
    the interpreter's teardown (module docstring)."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a reader that left, a closed stream
            pass
    os._exit(status)


def _main(argv: list[str]) -> int:
    try:
        args = build_parser().parse_args(_join_value_options(list(argv)))
    except _UsageError as err:
        print(err, file=sys.stderr)
        return 2
    _use_cache()
    try:
        return args.run(args)
    except LinkoptError as err:
        print(f"linkopt: error: {err}", file=sys.stderr)
        return 2
    except BrokenPipeError:
        # `linkopt check ... | head`: the reader left, nothing to report
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as err:  # a bug, not the user's input: one line, exit 3
        if args.debug:
            raise
        text = " ".join(str(err).split())
        print(
            f"linkopt: internal error: {type(err).__name__}: {text} (rerun with "
            "--debug for the traceback)",
            file=sys.stderr,
        )
        return 3


if __name__ == "__main__":
    sys.exit(main())
