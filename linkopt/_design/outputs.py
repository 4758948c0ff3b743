"""What a run folder's figures are drawn from, and the errors of its outputs.

The design layer writes a run folder (:mod:`linkopt._design.run`) and the drawing
layer, above it, draws its figures (:mod:`linkopt._draw.run_folder`): a
:class:`RunFigures` is what one call of the drawing gets, :data:`Figures` that
drawing's type, and :func:`writing` names the output an error was raised in
(:class:`OutputError`), in whichever process it was made.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism
from .._errors import LinkoptError
from .evaluation import Evaluation


@dataclass(frozen=True)
class RunFigures:
    """What one design's figures in a run folder are drawn from: ``mech`` is the file's
    mechanism, ``current`` the run's (with the verification rounds' targets),
    ``design`` the optimised design or None for the file's, ``evaluation`` that
    design's with ``current`` (for the file's design, None where the run did not hand
    it over: evaluate it with
    :func:`~linkopt._design.evaluation.evaluate_in_batch` in blocks of ``rows``, the
    swarm program's shape, if a figure needs it), ``history`` the run's records.
    ``optimized``: on a job with ``design`` None, the optimised design, for the
    figures that show both designs (the motions), which that job then draws instead
    of the file's design's own figures (its space plot)."""

    mech: Mechanism
    current: Mechanism
    out: Path
    design: np.ndarray | None
    evaluation: Evaluation | None
    rows: int
    history: tuple[dict, ...] = ()
    resolution: int | None = None
    progress: Callable[[dict], None] | None = None
    optimized: np.ndarray | None = None


#: The drawing of a run folder's figures (:mod:`linkopt._draw.run_folder`), called
#: once per design; it must pickle (a module-level function) to run in another
#: process. A call may return the drawings it left (zero-argument picklable calls,
#: each writing its files; None or empty: none), which then run in two processes at
#: once (:func:`linkopt._design.run.write_outputs`): the motions' call solves both
#: designs' motions, whose GIFs share a colour scale, and leaves one GIF each.
Figures = Callable[[RunFigures], "tuple[Callable[[], None], ...] | None"]


class OutputError(RuntimeError):
    """An output of a run folder that could not be written: the message names it and
    says what failed (an internal error, not the user's input, whatever process
    made the output)."""


@contextmanager
def writing(name: str) -> Iterator[None]:
    """Name the output ``name`` in an error raised while it is made
    (:class:`OutputError`; a :class:`~linkopt.LinkoptError` names its file already and
    passes unchanged)."""
    try:
        yield
    except (LinkoptError, OutputError):
        raise
    except Exception as err:
        text = " ".join(str(err).split())
        raise OutputError(f"{name}: {type(err).__name__}: {text}") from err
