"""mjx_pick: physics-based pick-point evaluation for two-finger grippers on MuJoCo.

Data flow: object -> gripper -> scene -> pick-points -> batched simulation -> metrics.

The public API is the table ``_PUBLIC`` (``__all__`` is its names); each name is
imported from its module on first use (PEP 562), so ``import mjx_pick`` loads neither
MuJoCo nor JAX and changes nothing in the process. Everything else is internal.
"""

from __future__ import annotations

import importlib
import warnings

__version__ = "0.1.0"

# public name -> the module that defines it
_PUBLIC = {
    # core: objects, grippers, physics, scenes, pick-points
    "ObjectModel": "core.objects",
    "asset_names": "core.objects",
    "load_asset": "core.objects",
    "load_object": "core.objects",
    "object_from_image": "core.objects",
    "object_from_mesh": "core.objects",
    "object_from_polygon": "core.objects",
    "GripperSpec": "core.gripper",
    "load_gripper": "core.gripper",
    "preset_names": "core.gripper",
    "ContactParams": "core.physics",
    "SolverParams": "core.physics",
    "GraspConfig": "core.procedure",
    "min_grasp_force_n": "core.procedure",
    "Scene": "core.scene",
    "build_scene": "core.scene",
    "FeasibilityChecker": "core.pickpoints",
    "GraspBatch": "core.pickpoints",
    "PickConfig": "core.pickpoints",
    "generate_grid": "core.pickpoints",
    "generate_normal": "core.pickpoints",
    "optimize": "core.pickpoints",
    "ConfigError": "core.config",
    # engine: the one simulation path
    "Cancelled": "engine.runner",
    "Runner": "engine.runner",
    "Engine": "engine.runner",  # deprecated: Runner's old name (_RENAMED)
    "Simulator": "engine.simulator",
    "Settings": "core.settings",
    # studies
    "Evaluation": "studies.evaluation",
    "EvaluateRequest": "studies.evaluation",
    "evaluate": "studies.evaluation",
    "Session": "studies.session",
    "ParamSpec": "studies.sweeps",
    "sweep": "studies.sweeps",
    "compare": "studies.comparison",
    "design_search": "studies.comparison",
    "DesignRequest": "studies.comparison",
    "robustness": "studies.robust",
    "min_grip_force": "studies.robust",
    "Perturbations": "studies.robust",
    "RobustBest": "studies.robust",
    "ForceSearch": "studies.robust",
    "calibrate": "studies.calibration",
    "FitRequest": "studies.calibration.fit",
    # outputs
    "report": "outputs.reporting",
    "export_labels": "outputs.exchange",
    "read_labels": "outputs.exchange",
    "use_offscreen_rendering": "outputs.display",
    "RunOptions": "studies.options",
}

# old public name -> its new name: kept, with a DeprecationWarning, for one release
_RENAMED = {"Engine": "Runner"}

__all__ = sorted(_PUBLIC)


def __getattr__(name: str):
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'mjx_pick' has no attribute {name!r}")
    if name in _RENAMED:  # not cached: each use of the old name says so
        new = _RENAMED[name]
        warnings.warn(
            f"mjx_pick.{name} is now mjx_pick.{new}; the old name goes in the next release",
            DeprecationWarning,
            stacklevel=2,
        )
        return __getattr__(new)
    value = getattr(importlib.import_module(f"mjx_pick.{module}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
