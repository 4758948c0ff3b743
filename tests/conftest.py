"""Shared fixtures. Mechanisms are loaded once per session (loading compiles a
kernel)."""

from pathlib import Path

import pytest

import linkopt

ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = ROOT / "mechanisms"


@pytest.fixture(scope="session")
def five_bar() -> linkopt.Mechanism:
    return linkopt.load(MECHANISMS / "five_bar.toml")


@pytest.fixture(scope="session")
def five_bar_evaluation(five_bar):
    from linkopt._design.evaluation import evaluate

    return evaluate(five_bar)
