"""linkopt: singularity-aware design of closed-loop spatial linkages.

The public API; everything else is internal. States are homogenised (positions divided
by ``Mechanism.length_scale``); motors, outputs, positions and designs are in file units.
"""

from . import _config  # noqa: F401  (float64 and the compilation cache, before any array)
from ._constraints import constraint_rows
from ._errors import InputError, LinkoptError, MechanismFileError
from ._evaluation import Evaluation, evaluate
from ._geometry import geometry, rest_state
from ._kinematics import Solution, sensitivity, solve_bk, solve_bk_path, solve_fk, solve_fk_path
from ._loader import load, loads
from ._mobility import mobility
from ._model import Mechanism
from ._optimizer import OptimizerSettings
from ._partial import partial_gradient
from ._readout import joint_positions, motor_values, output_values, point_positions
from ._run import optimize, write_outputs
from ._singularity import f_sing, singular_values
from ._verify import Verification, verify
from ._writer import write_design

__all__ = [
    "Evaluation",
    "InputError",
    "LinkoptError",
    "Mechanism",
    "MechanismFileError",
    "OptimizerSettings",
    "Solution",
    "Verification",
    "constraint_rows",
    "evaluate",
    "f_sing",
    "geometry",
    "joint_positions",
    "load",
    "loads",
    "mobility",
    "motor_values",
    "optimize",
    "output_values",
    "partial_gradient",
    "point_positions",
    "rest_state",
    "sensitivity",
    "singular_values",
    "solve_bk",
    "solve_bk_path",
    "solve_fk",
    "solve_fk_path",
    "verify",
    "write_design",
    "write_outputs",
]
