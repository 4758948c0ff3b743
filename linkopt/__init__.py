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

# Serial arms on the same engine: co-design (paper 000), DH synthesis (004), path tracing (002)
from ._arm_design import ArmSolution, prepare as prepare_arm, solve as solve_arm
from ._arm_model import Arm
from ._arm_task import Task as ArmTask, load_task as load_arm_task, loads_task as loads_arm_task
from ._dh import DHTable, to_mechanism as dh_mechanism
from ._dh_synthesis import DHSynthesis, DHSynthesisSettings, synthesize_dh
from ._elimination import eliminate, simplify
from ._manipulability import manipulability, point_jacobian
from ._statics import static_torques
from ._trace_discrete import DiscreteComparison, compare as compare_discretised, discretised_design
from ._trace_synthesis import TraceResult, TraceSettings, synthesize as synthesize_trace
from ._trace_task import TraceTask, load_task as load_trace_task, loads_task as loads_trace_task
from ._trace_verify import PlanarArm, TraceVerification, verify as verify_trace

__all__ = [
    "Arm",
    "ArmSolution",
    "ArmTask",
    "DHSynthesis",
    "DHSynthesisSettings",
    "DHTable",
    "DiscreteComparison",
    "Evaluation",
    "InputError",
    "LinkoptError",
    "Mechanism",
    "MechanismFileError",
    "OptimizerSettings",
    "PlanarArm",
    "Solution",
    "TraceResult",
    "TraceSettings",
    "TraceTask",
    "TraceVerification",
    "Verification",
    "compare_discretised",
    "constraint_rows",
    "dh_mechanism",
    "discretised_design",
    "eliminate",
    "evaluate",
    "f_sing",
    "geometry",
    "joint_positions",
    "load",
    "load_arm_task",
    "load_trace_task",
    "loads",
    "loads_arm_task",
    "loads_trace_task",
    "manipulability",
    "mobility",
    "motor_values",
    "optimize",
    "output_values",
    "partial_gradient",
    "point_jacobian",
    "point_positions",
    "prepare_arm",
    "rest_state",
    "sensitivity",
    "simplify",
    "singular_values",
    "solve_arm",
    "solve_bk",
    "solve_bk_path",
    "solve_fk",
    "solve_fk_path",
    "static_torques",
    "synthesize_dh",
    "synthesize_trace",
    "verify",
    "verify_trace",
    "write_design",
    "write_outputs",
]
