"""Write ``reference_values.json``: FK states, output values and σ_min of every shipped
mechanism at a few motor rows, and the five-bar's evaluation, as a given linkopt
computes them. ``tests/test_reference_values.py`` holds later code to them.

Run from the repository root: ``.venv/bin/python tests/data/make_reference_values.py``
(the shipped file was written at commit 0fa6ec3, before the mechanism's numbers
became program arguments, when every program baked them in as constants;
``strandbeest_12`` was added later, its FK states solved with ``[solver] factor =
"dense"`` so that the shipped default, the arrowhead factor, is held to the dense one).
"""

import json
from pathlib import Path

import numpy as np

import linkopt

ROOT = Path(__file__).resolve().parents[2]


def motor_rows(mech) -> np.ndarray:
    """Rest and two small moves of every motor (0.05 rad, or 1 % of the reference
    length for a linear motor), alternating in sign."""
    signs = np.where(np.arange(mech.num_motors) % 2 == 0, 1.0, -1.0)
    step = np.where(mech.motor_linear, 0.01 * mech.length_scale, 0.05)
    return np.stack([0.0 * step, signs * step, -0.6 * signs * step])


def record(mech) -> dict:
    motors = motor_rows(mech)
    solution = linkopt.solve_fk(mech, motors)
    return {
        "motors": motors.tolist(),
        "converged": np.asarray(solution.converged).tolist(),
        "states": np.asarray(solution.state).tolist(),
        "outputs": np.asarray(linkopt.output_values(mech, solution.state)).tolist(),
        "sigmas": np.asarray(linkopt.singular_values(mech, solution.state)).tolist(),
    }


def main() -> None:
    values = {}
    for path in sorted((ROOT / "mechanisms").glob("*.toml")):
        values[path.stem] = record(linkopt.load(path))
    five_bar = linkopt.load(ROOT / "mechanisms" / "five_bar.toml")
    ev = linkopt.evaluate(five_bar)
    values["five_bar_evaluation"] = {
        "f_design": float(ev.f_design),
        "ik_f_sing": np.asarray(ev.ik_f_sing).tolist(),
        "adv_f_sing": np.asarray(ev.adv_f_sing).tolist(),
    }
    out = Path(__file__).with_name("reference_values.json")
    out.write_text(json.dumps(values) + "\n")


if __name__ == "__main__":
    main()
