"""mjx_pick: physics-based pick-point evaluation for two-finger grippers on MuJoCo.

Data flow: object -> gripper -> scene -> pick-points -> batched simulation -> metrics.

The public API is the names in ``__all__``; each is imported from its module on first
use (PEP 562), so ``import mjx_pick`` loads neither MuJoCo nor JAX and changes nothing
in the process (no environment variables, no global JAX or matplotlib settings).
Everything else is internal and may change between versions.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

__version__ = "0.1.0"

# public name -> the module that defines it
_PUBLIC = {
    # core: objects, grippers, physics, scenes, pick-points
    "ObjectModel": "objects",
    "asset_names": "objects",
    "load_asset": "objects",
    "load_object": "objects",
    "object_from_image": "objects",
    "object_from_mesh": "objects",
    "object_from_polygon": "objects",
    "GripperSpec": "gripper",
    "load_gripper": "gripper",
    "preset_names": "gripper",
    "ContactParams": "physics",
    "SolverParams": "physics",
    "GraspConfig": "grasp",
    "min_grasp_force_n": "grasp",
    "Scene": "scene",
    "build_scene": "scene",
    "FeasibilityChecker": "pickpoints",
    "PickBatch": "pickpoints",
    "PickConfig": "pickpoints",
    "generate_grid": "pickpoints",
    "generate_normal": "pickpoints",
    "optimize": "pickpoints",
    "ConfigError": "config",
    # engine: the one simulation path
    "Cancelled": "engine",
    "Engine": "engine",
    "Simulator": "engine",
    "Settings": "simulate",
    # studies
    "Evaluation": "evaluation",
    "evaluate": "evaluation",
    "ParamSpec": "sweeps",
    "sweep": "sweeps",
    "compare": "comparison",
    "design_search": "comparison",
    "robustness": "robust",
    "min_grip_force": "robust",
    "calibrate": "calibration",
    # outputs
    "report": "reporting",
    "use_offscreen_rendering": "display",
}

__all__ = [
    "Cancelled",
    "ConfigError",
    "ContactParams",
    "Engine",
    "Evaluation",
    "FeasibilityChecker",
    "GraspConfig",
    "GripperSpec",
    "ObjectModel",
    "ParamSpec",
    "PickBatch",
    "PickConfig",
    "Scene",
    "Settings",
    "Simulator",
    "SolverParams",
    "asset_names",
    "build_scene",
    "calibrate",
    "compare",
    "design_search",
    "evaluate",
    "generate_grid",
    "generate_normal",
    "load_asset",
    "load_gripper",
    "load_object",
    "min_grasp_force_n",
    "min_grip_force",
    "object_from_image",
    "object_from_mesh",
    "object_from_polygon",
    "optimize",
    "preset_names",
    "report",
    "robustness",
    "sweep",
    "use_offscreen_rendering",
]

if TYPE_CHECKING:  # for type checkers and IDEs; at run time names load lazily
    from mjx_pick.calibration import calibrate
    from mjx_pick.comparison import compare, design_search
    from mjx_pick.config import ConfigError
    from mjx_pick.display import use_offscreen_rendering
    from mjx_pick.engine import Cancelled, Engine, Simulator
    from mjx_pick.evaluation import Evaluation, evaluate
    from mjx_pick.grasp import GraspConfig, min_grasp_force_n
    from mjx_pick.gripper import GripperSpec, load_gripper, preset_names
    from mjx_pick.objects import (
        ObjectModel,
        asset_names,
        load_asset,
        load_object,
        object_from_image,
        object_from_mesh,
        object_from_polygon,
    )
    from mjx_pick.physics import ContactParams, SolverParams
    from mjx_pick.pickpoints import (
        FeasibilityChecker,
        PickBatch,
        PickConfig,
        generate_grid,
        generate_normal,
        optimize,
    )
    from mjx_pick.reporting import report
    from mjx_pick.robust import min_grip_force, robustness
    from mjx_pick.scene import Scene, build_scene
    from mjx_pick.simulate import Settings
    from mjx_pick.sweeps import ParamSpec, sweep


def __getattr__(name: str):
    module = _PUBLIC.get(name)
    if module is None:
        raise AttributeError(f"module 'mjx_pick' has no attribute {name!r}")
    value = getattr(importlib.import_module(f"mjx_pick.{module}"), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted({*globals(), *__all__})
