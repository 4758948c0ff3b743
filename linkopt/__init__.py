"""linkopt: singularity-aware design of closed-loop spatial linkages.

The public API; everything else is internal. States are homogenised (positions divided
by ``Mechanism.length_scale``); motors, outputs, positions and designs are in file
units. Results and settings are frozen dataclasses, read by field name; those that JAX
traces (``Solution``, ``Evaluation``, ``DHTable``) are registered pytrees (the rule:
the documentation's Architecture page, Conventions).

Importing :mod:`linkopt` imports no JAX and changes nothing: names are imported on
first use. linkopt computes in float64, the one JAX option it sets itself, when the
first public name other than an error type is used (:mod:`linkopt._config`);
:func:`use_cache` keeps compiled programs in a bounded on-disk cache where the user asks
(the command line does).

The top level keeps the core (mechanisms, kinematics, read-outs, singularities, design
evaluation, optimisation and verification, motion); the serial-arm families, the export
formats and synthesis have one home each, the namespaces :mod:`linkopt.arms.codesign`,
:mod:`linkopt.arms.dh`, :mod:`linkopt.arms.trace`, :mod:`linkopt.export` and
:mod:`linkopt.synthesis`. Their old top-level names (``linkopt.synthesize_dh``, ...)
warn until the next release (:data:`_MOVED`).
"""

import importlib
import warnings
from typing import TYPE_CHECKING

# name → (module, attribute). Imported on first use (PEP 562), so that a process that
# needs one part (a worker evaluating designs, ``linkopt check``) does not pay for the
# rest (jax and scipy.spatial are most of the import time). The folders, in
# pipeline order: ``_engine`` (the constraint engine), ``_files`` (mechanism files),
# ``_export``, ``_design`` (design optimisation), ``_arms`` (serial arms: ``codesign``,
# ``dh``, ``trace``), ``_synth`` (synthesis), ``_cli``.
_EXPORTS = {
    "constraint_rows": ("_engine.constraints", "constraint_rows"),
    "Clearance": ("_engine.collision", "Clearance"),
    "clearance": ("_engine.collision", "clearance"),
    "InputError": ("_errors", "InputError"),
    "LinkoptError": ("_errors", "LinkoptError"),
    "MechanismFileError": ("_errors", "MechanismFileError"),
    "Evaluation": ("_design.evaluation", "Evaluation"),
    "evaluate": ("_design.evaluation", "evaluate"),
    "geometry": ("_engine.geometry", "geometry"),
    "rest_state": ("_engine.geometry", "rest_state"),
    "Solution": ("_engine.kinematics", "Solution"),
    "sensitivity": ("_engine.kinematics", "sensitivity"),
    "solve_bk": ("_engine.kinematics", "solve_bk"),
    "solve_bk_path": ("_engine.kinematics", "solve_bk_path"),
    "solve_fk": ("_engine.kinematics", "solve_fk"),
    "solve_fk_path": ("_engine.kinematics", "solve_fk_path"),
    "load": ("_files.loader", "load"),
    "loads": ("_files.loader", "loads"),
    "mobility": ("_engine.mobility", "mobility"),
    "Mechanism": ("_engine.model", "Mechanism"),
    "OptimizerSettings": ("_design.settings", "OptimizerSettings"),
    "partial_gradient": ("_design.partial", "partial_gradient"),
    "joint_positions": ("_engine.readout", "joint_positions"),
    "motor_values": ("_engine.readout", "motor_values"),
    "output_values": ("_engine.readout", "output_values"),
    "point_positions": ("_engine.readout", "point_positions"),
    "named_points": ("_engine.readout", "named_points"),
    "reported_values": ("_engine.readout", "reported_values"),
    "optimize": ("_design.run", "optimize"),
    "write_outputs": ("_draw.run_folder", "write_outputs"),
    "animate": ("_draw.animation", "animate"),
    "motion": ("_design.motion", "motion"),
    "Motion": ("_design.motion", "Motion"),
    "PathNotReached": ("_design.motion", "PathNotReached"),
    "f_sing": ("_engine.singularity", "f_sing"),
    "singular_values": ("_engine.singularity", "singular_values"),
    "Verification": ("_design.verify", "Verification"),
    "verify": ("_design.verify", "verify"),
    "write_design": ("_files.writer", "write_design"),
    "use_cache": ("_config", "use_cache"),
    "manipulability": ("_engine.manipulability", "manipulability"),
    "point_jacobian": ("_engine.manipulability", "point_jacobian"),
    "static_torques": ("_engine.statics", "static_torques"),
}


#: The old top-level names of the namespaces' objects -> (namespace, name); each
#: warns (``DeprecationWarning``) until the next release.
_MOVED = {
    "ArmTask": ("arms.codesign", "ArmTask"),
    "load_arm_task": ("arms.codesign", "load_task"),
    "loads_arm_task": ("arms.codesign", "loads_task"),
    "Arm": ("arms.codesign", "Arm"),
    "ArmSolution": ("arms.codesign", "ArmSolution"),
    "prepare_arm": ("arms.codesign", "prepare"),
    "solve_arm": ("arms.codesign", "solve"),
    "eliminate": ("arms.codesign", "eliminate"),
    "simplify": ("arms.codesign", "simplify"),
    "DHTable": ("arms.dh", "DHTable"),
    "dh_mechanism": ("arms.dh", "to_mechanism"),
    "DHSynthesis": ("arms.dh", "DHSynthesis"),
    "DHSynthesisSettings": ("arms.dh", "DHSynthesisSettings"),
    "synthesize_dh": ("arms.dh", "synthesize"),
    "TraceTask": ("arms.trace", "TraceTask"),
    "load_trace_task": ("arms.trace", "load_task"),
    "loads_trace_task": ("arms.trace", "loads_task"),
    "TraceSettings": ("arms.trace", "TraceSettings"),
    "TraceResult": ("arms.trace", "TraceResult"),
    "synthesize_trace": ("arms.trace", "synthesize"),
    "PlanarArm": ("arms.trace", "PlanarArm"),
    "TraceVerification": ("arms.trace", "TraceVerification"),
    "verify_trace": ("arms.trace", "verify"),
    "DiscreteComparison": ("arms.trace", "DiscreteComparison"),
    "compare_discretised": ("arms.trace", "compare_discretised"),
    "discretised_design": ("arms.trace", "discretised_design"),
    "export_mjcf": ("export", "mjcf"),
    "export_urdf": ("export", "urdf"),
    "export_stl": ("export", "stl"),
    "export_glb": ("export", "glb"),
    "export_dxf": ("export", "dxf"),
    "export_svg": ("export", "svg"),
    "SynthesisTargets": ("synthesis", "Targets"),
    "load_synthesis_targets": ("synthesis", "load_targets"),
    "SynthesisResult": ("synthesis", "SynthesisResult"),
    "synthesize": ("synthesis", "synthesize"),
    "score_synthesis": ("synthesis", "score"),
    "verify_synthesis": ("synthesis", "verify"),
}

#: The public namespaces, imported on first use (:mod:`linkopt._namespace`).
_NAMESPACES = ("arms", "export", "synthesis")


def __getattr__(name: str):
    if name in _NAMESPACES:
        return importlib.import_module(f".{name}", __name__)
    if name in _MOVED:
        space, new = _MOVED[name]
        warnings.warn(
            f"linkopt.{name} is deprecated and goes in the next release; use "
            f"linkopt.{space}.{new}",
            DeprecationWarning,
            stacklevel=2,
        )
        return getattr(importlib.import_module(f".{space}", __name__), new)
    try:
        module, attribute = _EXPORTS[name]
    except KeyError:
        raise AttributeError(f"module 'linkopt' has no attribute {name!r}") from None
    if module != "_errors":  # float64 on before any public name that computes is used
        importlib.import_module("._config", __name__)
    value = getattr(importlib.import_module(f".{module}", __name__), attribute)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS) | set(_NAMESPACES))


if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from ._config import use_cache
    from ._design.evaluation import Evaluation, evaluate
    from ._design.motion import Motion, PathNotReached, motion
    from ._design.partial import partial_gradient
    from ._design.run import optimize
    from ._design.settings import OptimizerSettings
    from ._design.verify import Verification, verify
    from ._draw.animation import animate
    from ._draw.run_folder import write_outputs
    from ._engine.collision import Clearance, clearance
    from ._engine.constraints import constraint_rows
    from ._engine.geometry import geometry, rest_state
    from ._engine.kinematics import (
        Solution,
        sensitivity,
        solve_bk,
        solve_bk_path,
        solve_fk,
        solve_fk_path,
    )
    from ._engine.manipulability import manipulability, point_jacobian
    from ._engine.mobility import mobility
    from ._engine.model import Mechanism
    from ._engine.readout import (
        joint_positions,
        motor_values,
        named_points,
        output_values,
        point_positions,
        reported_values,
    )
    from ._engine.singularity import f_sing, singular_values
    from ._engine.statics import static_torques
    from ._errors import InputError, LinkoptError, MechanismFileError
    from ._files.loader import load, loads
    from ._files.writer import write_design

__all__ = sorted(_EXPORTS)
