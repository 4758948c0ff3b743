"""linkopt: singularity-aware design of closed-loop spatial linkages.

The public API; everything else is internal. States are homogenised (positions divided
by ``Mechanism.length_scale``); motors, outputs, positions and designs are in file
units. Results and settings are frozen dataclasses, read by field name; those that JAX
traces (``Solution``, ``Evaluation``, ``DHTable``) are registered pytrees (the rule:
the documentation's Architecture page, Conventions).

Importing :mod:`linkopt` imports no JAX and changes nothing: names are imported on
first use. linkopt computes in float64, the one JAX option it sets itself, when the
first public name other than an error type is used (:mod:`linkopt._config`); :func:`use_cache` keeps
compiled programs in a bounded on-disk cache where the user asks (the command line
does).

The names of the serial-arm families and of the export formats are also grouped, under
shorter names, in the namespaces :mod:`linkopt.arms.codesign`, :mod:`linkopt.arms.dh`,
:mod:`linkopt.arms.trace` and :mod:`linkopt.export` (``linkopt.arms.dh.synthesize`` is
``linkopt.synthesize_dh``); the top-level names remain.
"""

import importlib
from typing import TYPE_CHECKING

# name → (module, attribute). Imported on first use (PEP 562), so that a process that
# needs one part (a worker evaluating designs, ``linkopt check``) does not pay for the
# rest (jax, pyswarms and scipy.spatial are most of the import time). The folders, in
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
    "ArmSolution": ("_arms.codesign.nlp", "ArmSolution"),
    "prepare_arm": ("_arms.codesign.nlp", "prepare"),
    "solve_arm": ("_arms.codesign.nlp", "solve"),
    "Arm": ("_arms.codesign.model", "Arm"),
    "ArmTask": ("_arms.codesign.task", "Task"),
    "load_arm_task": ("_arms.codesign.task", "load_task"),
    "loads_arm_task": ("_arms.codesign.task", "loads_task"),
    "DHTable": ("_arms.dh.table", "DHTable"),
    "dh_mechanism": ("_arms.dh.table", "to_mechanism"),
    "DHSynthesis": ("_arms.dh.synthesis", "DHSynthesis"),
    "DHSynthesisSettings": ("_arms.dh.settings", "DHSynthesisSettings"),
    "synthesize_dh": ("_arms.dh.synthesis", "synthesize_dh"),
    "eliminate": ("_arms.codesign.elimination", "eliminate"),
    "simplify": ("_arms.codesign.elimination", "simplify"),
    "manipulability": ("_engine.manipulability", "manipulability"),
    "point_jacobian": ("_engine.manipulability", "point_jacobian"),
    "static_torques": ("_engine.statics", "static_torques"),
    "DiscreteComparison": ("_arms.trace.discrete", "DiscreteComparison"),
    "compare_discretised": ("_arms.trace.discrete", "compare"),
    "discretised_design": ("_arms.trace.discrete", "discretised_design"),
    "TraceResult": ("_arms.trace.synthesis", "TraceResult"),
    "TraceSettings": ("_arms.trace.settings", "TraceSettings"),
    "synthesize_trace": ("_arms.trace.synthesis", "synthesize"),
    "TraceTask": ("_arms.trace.task", "TraceTask"),
    "load_trace_task": ("_arms.trace.task", "load_task"),
    "loads_trace_task": ("_arms.trace.task", "loads_task"),
    "PlanarArm": ("_arms.trace.verify", "PlanarArm"),
    "TraceVerification": ("_arms.trace.verify", "TraceVerification"),
    "verify_trace": ("_arms.trace.verify", "verify"),
    "export_mjcf": ("_export.mjcf", "export_mjcf"),
    "export_urdf": ("_export.urdf", "export_urdf"),
    "export_stl": ("_export.meshes", "export_stl"),
    "export_glb": ("_export.meshes", "export_glb"),
    "export_dxf": ("_export.sheet", "export_dxf"),
    "export_svg": ("_export.sheet", "export_svg"),
    "SynthesisTargets": ("_synth.targets", "Targets"),
    "load_synthesis_targets": ("_synth.targets", "load_targets"),
    "SynthesisResult": ("_synth.run", "SynthesisResult"),
    "synthesize": ("_synth.run", "synthesize"),
    "score_synthesis": ("_synth.run", "score_design"),
    "verify_synthesis": ("_synth.run", "verify"),
}


#: The public namespaces, imported on first use (:mod:`linkopt._namespace`).
_NAMESPACES = ("arms", "export", "synthesis")


def __getattr__(name: str):
    if name in _NAMESPACES:
        return importlib.import_module(f".{name}", __name__)
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
    from ._arms.codesign.elimination import eliminate, simplify
    from ._arms.codesign.model import Arm
    from ._arms.codesign.nlp import (
        ArmSolution,
    )
    from ._arms.codesign.nlp import (
        prepare as prepare_arm,
    )
    from ._arms.codesign.nlp import (
        solve as solve_arm,
    )
    from ._arms.codesign.task import (
        Task as ArmTask,
    )
    from ._arms.codesign.task import (
        load_task as load_arm_task,
    )
    from ._arms.codesign.task import (
        loads_task as loads_arm_task,
    )
    from ._arms.dh.settings import DHSynthesisSettings
    from ._arms.dh.synthesis import DHSynthesis, synthesize_dh
    from ._arms.dh.table import DHTable
    from ._arms.dh.table import to_mechanism as dh_mechanism
    from ._arms.trace.discrete import (
        DiscreteComparison,
        discretised_design,
    )
    from ._arms.trace.discrete import (
        compare as compare_discretised,
    )
    from ._arms.trace.settings import TraceSettings
    from ._arms.trace.synthesis import TraceResult
    from ._arms.trace.synthesis import (
        synthesize as synthesize_trace,
    )
    from ._arms.trace.task import (
        TraceTask,
    )
    from ._arms.trace.task import (
        load_task as load_trace_task,
    )
    from ._arms.trace.task import (
        loads_task as loads_trace_task,
    )
    from ._arms.trace.verify import PlanarArm, TraceVerification
    from ._arms.trace.verify import verify as verify_trace
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
    from ._export.meshes import export_glb, export_stl
    from ._export.mjcf import export_mjcf
    from ._export.sheet import export_dxf, export_svg
    from ._export.urdf import export_urdf
    from ._files.loader import load, loads
    from ._files.writer import write_design
    from ._synth.run import SynthesisResult, synthesize
    from ._synth.run import score_design as score_synthesis
    from ._synth.run import verify as verify_synthesis
    from ._synth.targets import Targets as SynthesisTargets
    from ._synth.targets import load_targets as load_synthesis_targets

__all__ = sorted(_EXPORTS)
