"""Command-line options that set fields of a settings dataclass.

An option's type and default are those of its field in the dataclass, read from an
instance when the parser is built, and the settings are built back from the parsed
options (:func:`settings_of`), so that no default is written twice. The settings
dataclasses the command line reads live in modules without JAX
(:mod:`linkopt._arms.dh.settings`, :mod:`linkopt._arms.trace.settings`).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass


@dataclass(frozen=True)
class Option:
    """``flag`` sets the settings field ``field``; ``help`` is shown with the
    default."""

    flag: str
    field: str
    help: str
    metavar: str | None = None

    @property
    def dest(self) -> str:
        """The attribute argparse gives the parsed value (``--best-of``: best_of)."""
        return self.flag.lstrip("-").replace("-", "_")


def add_options(
    parser: argparse.ArgumentParser, defaults, options: tuple[Option, ...]
) -> None:
    """One argument per option, of the type and default of its field in ``defaults``
    (an instance of the settings dataclass)."""
    for option in options:
        value = getattr(defaults, option.field)
        parser.add_argument(
            option.flag,
            type=type(value),
            default=value,
            metavar=option.metavar,
            help=f"{option.help} (default {value:g})",
        )


def settings_of(args: argparse.Namespace, settings: type, options: tuple[Option, ...]):
    """An instance of ``settings`` with the parsed options; its other fields keep their
    defaults."""
    return settings(**{o.field: getattr(args, o.dest) for o in options})
