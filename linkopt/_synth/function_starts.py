"""Start designs of a planar four-bar function generation, from Freudenstein's
equation (numpy, before any sweep).

A function target pairs motor values ``m_i`` (the crank's turn from rest) with output
values ``o_i`` (the rocker's turn from rest at its ground pivot). Measured from the
ground line ``A → D``, the crank is at ``φ_i = φ₀ + s₁ m_i`` and the rocker at
``ψ_i = ψ₀ + s₂ o_i`` (``φ₀``, ``ψ₀`` the rest angles, ``s`` the senses of the joints
against the plane's normal), and a four-bar generates the pairs when
Freudenstein's equation ``K1 cos ψ − K2 cos φ + K3 = cos(φ − ψ)`` holds at each
(:func:`.fourbar.freudenstein`; ``K1 = d/a``, ``K2 = d/c``,
``K3 = (a² − b² + c² + d²)/2ac``). For given rest angles the equation is linear in
``K``: three pairs are met exactly, more in the least-squares sense. The rest pose
(``m = 0``, ``o = 0``) is one more row, weighted ``REST_WEIGHT``: the design's rest
pose must be a pose of the fitted four-bar.

:func:`fits` tries a grid of rest angles for each pair of senses, solves for ``K``,
and refines the best rest angles with ``K`` by nonlinear least squares (scipy);
:func:`candidates` places each four-bar on the file's ground line (its ``A`` and the
ground length ``d`` kept) and carries it into the design space by least squares on
the anchors of ``A``-``D``, as the path starts are (:mod:`.starts`); the synthesis run
scores them with the whole cycle and seeds its swarm with the best (:mod:`.run`).

Applies to a function target of a one-motor planar four-bar
(:func:`.fourbar.four_bar_joints`) whose output is the angle at the rocker's ground
pivot ``D``, with a linear design map; :func:`applies` says whether.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._engine.model import Mechanism
from .._errors import InputError
from . import fourbar
from .targets import Targets

#: Rest angles tried per axis (each sense pair), and fits refined and kept.
GRID = 24
KEEP = 12
#: Weight of the rest pose's row (it must be a pose of the fitted four-bar).
REST_WEIGHT = 30.0


@dataclass(frozen=True)
class FunctionFit:
    """One four-bar fitted to the pairs: rest angles ``phi0``, ``psi0`` (rad, from
    the ground line), the senses ``signs`` of motor and output, Freudenstein's ``k``
    ``(3,)``, and the root-mean-square residual of the equation at the pairs."""

    phi0: float
    psi0: float
    signs: tuple[float, float]
    k: np.ndarray
    residual: float

    def lengths(self, ground: float) -> np.ndarray | None:
        """``(a, b, c, d)`` for ground length ``ground``; None where the fit has no
        real coupler or a link of negative length."""
        if self.k[0] <= 0 or self.k[1] <= 0:
            return None
        a, c = ground / self.k[0], ground / self.k[1]
        squared = a * a + c * c + ground * ground - 2 * a * c * self.k[2]
        return None if squared <= 0 else np.array([a, np.sqrt(squared), c, ground])


def _rows(x, inputs, outputs, signs) -> np.ndarray:
    """Freudenstein's equation's rows ``(k + 1, 3)`` and right sides at rest angles
    ``x = (φ₀, ψ₀)``: the pairs, then the weighted rest pose."""
    phi = x[0] + signs[0] * np.r_[inputs, 0.0]
    psi = x[1] + signs[1] * np.r_[outputs, 0.0]
    weight = np.r_[np.ones(len(inputs)), REST_WEIGHT][:, None]
    system = np.stack([np.cos(psi), -np.cos(phi), np.ones_like(phi)], 1)
    return weight * system, weight[:, 0] * np.cos(phi - psi)


def _solve(x, inputs, outputs, signs) -> tuple[np.ndarray, np.ndarray]:
    system, right = _rows(x, inputs, outputs, signs)
    k = np.linalg.lstsq(system, right, rcond=None)[0]
    return k, system @ k - right


def _positive(phi0: float, psi0: float, k: np.ndarray):
    """The same four-bar with positive crank and rocker: a negative ``a`` (``K1 <
    0``) is the crank turned by π (``K1, K3`` change sign), likewise ``c`` with
    ``K2`` and the rocker; angles wrapped to (-π, π]."""
    if k[0] < 0:
        k[0], k[2], phi0 = -k[0], -k[2], phi0 + np.pi
    if k[1] < 0:
        k[1], k[2], psi0 = -k[1], -k[2], psi0 + np.pi
    wrap = lambda a: float(np.angle(np.exp(1j * a)))  # noqa: E731
    return wrap(phi0), wrap(psi0), k


def fits(inputs, outputs) -> list[FunctionFit]:
    """Four-bars generating the pairs ``(inputs[i], outputs[i])`` (rad, from rest),
    best first (module docstring); at least three pairs."""
    from scipy.optimize import least_squares

    inputs, outputs = np.asarray(inputs, float), np.asarray(outputs, float)
    if inputs.shape != outputs.shape or inputs.ndim != 1 or len(inputs) < 3:
        raise InputError(f"expected three or more pairs, got {inputs.shape}")
    grid = np.linspace(-np.pi, np.pi, GRID, endpoint=False)
    tried = []
    for signs in ((1.0, 1.0), (1.0, -1.0), (-1.0, 1.0), (-1.0, -1.0)):
        for phi0 in grid:
            for psi0 in grid:
                _, r = _solve((phi0, psi0), inputs, outputs, signs)
                tried.append((float(r @ r), phi0, psi0, signs))
    tried.sort(key=lambda t: t[0])
    out = []
    for _, phi0, psi0, signs in tried[: 4 * KEEP]:
        k0, _ = _solve((phi0, psi0), inputs, outputs, signs)

        def residual(x, signs=signs):
            system, right = _rows(x[:2], inputs, outputs, signs)
            return system @ x[2:] - right

        x = least_squares(residual, np.r_[phi0, psi0, k0], xtol=1e-15, ftol=1e-15).x
        r = residual(x)[:-1]
        phi0, psi0, k = _positive(x[0], x[1], x[2:].copy())
        out.append(FunctionFit(phi0, psi0, signs, k, float(np.sqrt(np.mean(r**2)))))
    out.sort(key=lambda f: f.residual)
    return out[:KEEP]


def applies(mech: Mechanism, targets: Targets) -> bool:
    """Whether Freudenstein starts apply (module docstring)."""
    if targets.kind != "function" or targets.motors is None:
        return False
    if mech.design.turns is not None or mech.design.size == 0:
        return False
    try:
        joints = fourbar.four_bar_joints(mech)
    except InputError:
        return False
    k = mech.output_names.index(targets.name)
    return mech.output_kinds[k] == "angle" and int(mech.output_joints[k]) == joints.D


def candidates(mech: Mechanism, targets: Targets) -> np.ndarray:
    """``(C, n_p)`` start designs: each fit of :func:`fits` placed on the file's
    ground line and carried into the design space (clipped to the box), the best
    fit first; empty where no fit is a real four-bar."""
    placed = fourbar.read_four_bar(mech)
    joints = fourbar.four_bar_joints(mech)
    ground_line = placed.D - placed.A
    d = float(np.linalg.norm(ground_line))
    theta = float(np.arctan2(ground_line[1], ground_line[0]))
    rows = [
        3 * i + m for i in (joints.A, joints.B, joints.C, joints.D) for m in range(3)
    ]
    matrix = np.asarray(mech.design.matrix)[rows]
    flat0 = np.ravel(mech.anchors)[rows]
    out = []
    outputs = np.asarray(targets.values, dtype=float).reshape(targets.count, -1)
    for fit in fits(np.asarray(targets.motors)[:, 0], outputs[:, 0]):
        lengths = fit.lengths(d)
        if lengths is None:
            continue
        a, _, c, _ = lengths
        pin = placed.A + a * np.array(
            [np.cos(theta + fit.phi0), np.sin(theta + fit.phi0)]
        )
        tip = placed.D + c * np.array(
            [np.cos(theta + fit.psi0), np.sin(theta + fit.psi0)]
        )
        world = [placed.world(x) for x in (placed.A, pin, tip, placed.D)]
        change = np.linalg.lstsq(matrix, np.concatenate(world) - flat0, rcond=None)[0]
        out.append(mech.design.p0 + change)
    if not out:
        return np.zeros((0, mech.design.size))
    return np.clip(np.array(out), mech.design.lower, mech.design.upper)
