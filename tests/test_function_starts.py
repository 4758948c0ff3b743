"""Freudenstein starts of a planar four-bar function generation
(:mod:`linkopt._synth.function_starts`): the fits satisfy Freudenstein's equation at
the pairs, recover a known four-bar's lengths from more pairs than three, and carry
into a file's design space as a design whose closed-form rocker angles are the
targets' (numpy only: no sweep, no compilation)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._files.synthesis import build
from linkopt._synth import function_starts, starts

ROOT = Path(__file__).resolve().parents[1]
FILE = ROOT / "mechanisms" / "four_bar_path.toml"
#: A crank-rocker: crank 20, coupler 60, rocker 45, ground 55, crank at rest 0.7 rad.
A, B, C, D = 20.0, 60.0, 45.0, 55.0
PHI0 = 0.7


def rocker_angles(phi: np.ndarray) -> np.ndarray:
    """The rocker's angle from the ground line at crank angles ``phi`` (one branch:
    the pin ``C`` above the line ``B → D``), circle intersection."""
    pin = A * np.exp(1j * phi)
    gap = D - pin
    far = np.abs(gap)
    turn = np.arccos((B * B + far * far - C * C) / (2 * B * far))
    tip = pin + B * gap / far * np.exp(1j * turn)
    return np.angle(tip - D)


def pairs(count: int):
    phi = PHI0 + np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    psi = rocker_angles(phi)
    return phi - PHI0, psi - rocker_angles(np.array([PHI0]))[0], phi, psi


def equation(fit, phi, psi) -> np.ndarray:
    k1, k2, k3 = fit.k
    return k1 * np.cos(psi) - k2 * np.cos(phi) + k3 - np.cos(phi - psi)


def test_three_pairs_are_met_exactly():
    inputs, outputs, _, _ = pairs(3)
    best = function_starts.fits(inputs, outputs)[0]
    s1, s2 = best.signs
    phi = best.phi0 + s1 * np.r_[inputs, 0.0]
    psi = best.psi0 + s2 * np.r_[outputs, 0.0]
    assert np.max(np.abs(equation(best, phi, psi))) < 1e-9


def test_more_pairs_recover_the_four_bar():
    inputs, outputs, phi, psi = pairs(9)
    best = function_starts.fits(inputs, outputs)[0]
    assert best.residual < 1e-9
    assert best.lengths(D) == pytest.approx([A, B, C, D], rel=1e-6)
    if best.signs == (1.0, 1.0):  # else the mirror image, the same lengths
        assert [best.phi0, best.psi0] == pytest.approx([PHI0, psi[0]], abs=1e-7)
        assert np.max(np.abs(equation(best, phi, psi))) < 1e-9


def test_the_start_design_generates_the_function():
    """On a file whose pins and rocker pivot are free, the best start's rest
    four-bar (A fixed, the ground length the file's) turns the rocker as asked."""
    text = FILE.read_text().split("[[parameters]]")[0]
    for joint, values in (("B", (0.0, 20.0)), ("C", (63.3, 49.9)), ("D", (60.0, 0.0))):
        for axis, value in zip("xy", values):
            text += (
                f'[[parameters]]\nname = "{joint}_{axis}"\njoint = "{joint}"\n'
                f'coordinate = "{axis}"\nmin = {value - 80.0}\nmax = {value + 80.0}\n\n'
            )
    mech = linkopt.loads(text, str(FILE))
    inputs, outputs, _, _ = pairs(7)
    targets = build(str(FILE), "test", "function", "rocker", outputs,
                    inputs[:, None], False, 1e-3)  # fmt: skip
    assert function_starts.applies(mech, targets)
    found = function_starts.candidates(mech, targets)
    assert len(found) >= 1
    assert np.all((found >= mech.design.lower) & (found <= mech.design.upper))
    geom = linkopt.geometry(mech, found[0])
    anchors = np.asarray(geom.anchors)[:, :2] * mech.length_scale
    a, b0, c0, d = (anchors[mech.joint_names.index(n)] for n in "ABCD")
    assert np.linalg.norm(d - a) == pytest.approx(60.0, abs=1e-9)  # the file's d
    rest = np.stack([a, b0, c0, d, c0])[None]
    pins = starts.coupler_batch(rest, inputs[None])[0]  # C at each motor value
    swing = np.angle((pins - d) @ [1, 1j]) - np.angle((c0 - d) @ [1, 1j])
    swing = (swing + np.pi) % (2 * np.pi) - np.pi
    assert swing == pytest.approx(outputs, abs=1e-6)
