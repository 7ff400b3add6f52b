"""mjx_pick: physics-based pick-point evaluation for two-finger grippers on MuJoCo MJX.

Data flow: object -> gripper -> scene -> pick-points -> batched simulation -> metrics.
"""

import ctypes.util as _ctypes_util
import importlib.util as _importlib_util
import os as _os
import sys as _sys
from pathlib import Path as _Path

# Installed, kernels/ and assets/ are the subpackages mjx_pick.kernels and
# mjx_pick.assets (pyproject's package-dir). Run from a source checkout (python -m
# mjx_pick.cli in the repository root), they sit beside this folder: load them under
# the same names.
for _name in ("kernels", "assets"):
    _beside = _Path(__file__).resolve().parent.parent / _name
    if (
        not (_Path(__file__).resolve().parent / _name).is_dir()
        and (_beside / "__init__.py").is_file()
    ):
        _spec = _importlib_util.spec_from_file_location(
            f"mjx_pick.{_name}", _beside / "__init__.py", submodule_search_locations=[str(_beside)]
        )
        _module = _importlib_util.module_from_spec(_spec)
        _sys.modules[f"mjx_pick.{_name}"] = _module
        _spec.loader.exec_module(_module)

# MuJoCo picks its OpenGL back end when it is first imported; without a display, the
# offscreen renderer (animations) needs EGL. Set before mujoco is imported, never
# overriding a user's choice, and only where libEGL exists: with MUJOCO_GL=egl and no
# libEGL, `import mujoco` itself fails.
if (
    _sys.platform.startswith("linux")
    and not _os.environ.get("DISPLAY")
    and "MUJOCO_GL" not in _os.environ
    and _ctypes_util.find_library("EGL")
):
    _os.environ["MUJOCO_GL"] = "egl"

from mjx_pick import calibrate  # the calibration module: calibrate.calibrate, .Problem, ...
from mjx_pick.compare import compare, design_search
from mjx_pick.config import ConfigError
from mjx_pick.engine import Cancelled, Engine, Simulator
from mjx_pick.evaluate import Evaluation, evaluate
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
from mjx_pick.report import report
from mjx_pick.robustness import min_grip_force, robustness
from mjx_pick.scene import Scene, build_scene
from mjx_pick.simulate import Settings
from mjx_pick.sweep import ParamSpec, sweep

__version__ = "0.1.0"

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
    "PickBatch",
    "ParamSpec",
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
    "min_grasp_force_n",
    "optimize",
    "load_asset",
    "load_gripper",
    "load_object",
    "min_grip_force",
    "object_from_image",
    "object_from_mesh",
    "object_from_polygon",
    "preset_names",
    "report",
    "robustness",
    "sweep",
]
