"""linkopt: singularity-aware design of closed-loop spatial linkages.

The public API; everything else is internal. States are homogenised (positions divided
by ``Mechanism.length_scale``); motors, outputs, positions and designs are in file units.
"""

from typing import TYPE_CHECKING

from . import _config  # noqa: F401  (float64 and the compilation cache, before any array)

# name → (module, attribute). Imported on first use (PEP 562), so that a process that
# needs one part (a worker evaluating designs, ``linkopt check``) does not pay for the
# rest: importing everything took 0.93 s, of which jax is 0.47 s and pyswarms (with
# scipy.spatial) 0.22 s. Serial arms on the same engine: co-design (paper 000), DH
# synthesis (004), path tracing (002) are the ``_arm``, ``_dh``, ``_elimination``,
# ``_manipulability``, ``_statics`` and ``_trace`` modules.
_EXPORTS = {
    "constraint_rows": ("_constraints", "constraint_rows"),
    "InputError": ("_errors", "InputError"),
    "LinkoptError": ("_errors", "LinkoptError"),
    "MechanismFileError": ("_errors", "MechanismFileError"),
    "Evaluation": ("_evaluation", "Evaluation"),
    "evaluate": ("_evaluation", "evaluate"),
    "geometry": ("_geometry", "geometry"),
    "rest_state": ("_geometry", "rest_state"),
    "Solution": ("_kinematics", "Solution"),
    "sensitivity": ("_kinematics", "sensitivity"),
    "solve_bk": ("_kinematics", "solve_bk"),
    "solve_bk_path": ("_kinematics", "solve_bk_path"),
    "solve_fk": ("_kinematics", "solve_fk"),
    "solve_fk_path": ("_kinematics", "solve_fk_path"),
    "load": ("_loader", "load"),
    "loads": ("_loader", "loads"),
    "mobility": ("_mobility", "mobility"),
    "Mechanism": ("_model", "Mechanism"),
    "OptimizerSettings": ("_optimizer", "OptimizerSettings"),
    "partial_gradient": ("_partial", "partial_gradient"),
    "joint_positions": ("_readout", "joint_positions"),
    "motor_values": ("_readout", "motor_values"),
    "output_values": ("_readout", "output_values"),
    "point_positions": ("_readout", "point_positions"),
    "optimize": ("_run", "optimize"),
    "write_outputs": ("_run", "write_outputs"),
    "f_sing": ("_singularity", "f_sing"),
    "singular_values": ("_singularity", "singular_values"),
    "Verification": ("_verify", "Verification"),
    "verify": ("_verify", "verify"),
    "write_design": ("_writer", "write_design"),
    "ArmSolution": ("_arm_design", "ArmSolution"),
    "prepare_arm": ("_arm_design", "prepare"),
    "solve_arm": ("_arm_design", "solve"),
    "Arm": ("_arm_model", "Arm"),
    "ArmTask": ("_arm_task", "Task"),
    "load_arm_task": ("_arm_task", "load_task"),
    "loads_arm_task": ("_arm_task", "loads_task"),
    "DHTable": ("_dh", "DHTable"),
    "dh_mechanism": ("_dh", "to_mechanism"),
    "DHSynthesis": ("_dh_synthesis", "DHSynthesis"),
    "DHSynthesisSettings": ("_dh_synthesis", "DHSynthesisSettings"),
    "synthesize_dh": ("_dh_synthesis", "synthesize_dh"),
    "eliminate": ("_elimination", "eliminate"),
    "simplify": ("_elimination", "simplify"),
    "manipulability": ("_manipulability", "manipulability"),
    "point_jacobian": ("_manipulability", "point_jacobian"),
    "static_torques": ("_statics", "static_torques"),
    "DiscreteComparison": ("_trace_discrete", "DiscreteComparison"),
    "compare_discretised": ("_trace_discrete", "compare"),
    "discretised_design": ("_trace_discrete", "discretised_design"),
    "TraceResult": ("_trace_synthesis", "TraceResult"),
    "TraceSettings": ("_trace_synthesis", "TraceSettings"),
    "synthesize_trace": ("_trace_synthesis", "synthesize"),
    "TraceTask": ("_trace_task", "TraceTask"),
    "load_trace_task": ("_trace_task", "load_task"),
    "loads_trace_task": ("_trace_task", "loads_task"),
    "PlanarArm": ("_trace_verify", "PlanarArm"),
    "TraceVerification": ("_trace_verify", "TraceVerification"),
    "verify_trace": ("_trace_verify", "verify"),
}


def __getattr__(name: str):
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'linkopt' has no attribute {name!r}") from None
    import importlib

    value = getattr(importlib.import_module(f".{module}", __name__), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))


if TYPE_CHECKING:  # the eager imports, for type checkers and editors
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

__all__ = sorted(_EXPORTS)
