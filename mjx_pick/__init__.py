"""mjx_pick: physics-based pick-point evaluation for two-finger grippers on MuJoCo MJX.

Data flow: object -> gripper -> scene -> pick-points -> batched simulation -> metrics.
"""

from mjx_pick.config import ConfigError
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
from mjx_pick.scene import Scene, build_scene

__version__ = "0.1.0"

__all__ = [
    "ConfigError",
    "ContactParams",
    "Evaluation",
    "FeasibilityChecker",
    "GraspConfig",
    "GripperSpec",
    "ObjectModel",
    "PickBatch",
    "PickConfig",
    "Scene",
    "SolverParams",
    "asset_names",
    "build_scene",
    "evaluate",
    "generate_grid",
    "generate_normal",
    "min_grasp_force_n",
    "optimize",
    "load_asset",
    "load_gripper",
    "load_object",
    "object_from_image",
    "object_from_mesh",
    "object_from_polygon",
    "preset_names",
]
