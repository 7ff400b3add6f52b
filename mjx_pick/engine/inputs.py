"""What the simulations take, and the one conversion of settings into it.

Like MuJoCo Warp's ``io.put_model``: :func:`scene_of` compiles an object under
``Settings``; :func:`pick_inputs` gives each pick-point its start pose, controller
parameters and contact-pair parameters. Contact values take one route into the pair
arrays: ``physics.mujoco_contact`` (:func:`scene_contact`), then :func:`set_contact`.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.physics import ContactParams, MujocoContact, SolverParams, mujoco_contact
from mjx_pick.core.procedure import GraspConfig, broadcast_params
from mjx_pick.core.scene import Scene, build_scene
from mjx_pick.core.settings import Settings
from mjx_pick.kernels import types as kt

# the contact values a pick-point may carry (besides GraspParams' fields)
CONTACT_OVERRIDES = (
    "pad_friction",
    "pad_torsion",
    "table_friction",
    "pad_solref",
    "table_solref",
    "pad_solimp",
    "table_solimp",
)


class PickInputs(NamedTuple):
    """Everything N simulations need, batched along the first axis."""

    qpos0: np.ndarray  # (N, nq)
    params: kt.GraspParams  # fields (N,)
    pair_friction: np.ndarray  # (N, npair, 5)
    pair_solref: np.ndarray  # (N, npair, 2)
    pair_solimp: np.ndarray  # (N, npair, 5)
    # per-simulation model fields, MjModel name -> (N, *field shape) float64: the values
    # of a gripper variant that shares the backend's compiled program
    # (``engine.variants``); empty: the backend's own model for every pick
    model: dict = {}  # noqa: RUF012 (never mutated: replaced whole)

    def __len__(self) -> int:
        return len(self.qpos0)

    def replace(self, **fields) -> PickInputs:
        """A copy with some fields replaced (NamedTuple's _replace relies on len()
        counting the fields, which __len__ redefines)."""
        return PickInputs(**{**self._asdict(), **fields})

    def take(self, index) -> PickInputs:
        return tree_map(lambda a: a[index], self)

    def pad_to(self, n: int) -> PickInputs:
        """Pad to n entries with copies of the first (results of the copies are dropped)."""
        extra = n - len(self)
        if extra <= 0:
            return self
        return tree_map(lambda a: np.concatenate([a, np.repeat(a[:1], extra, axis=0)]), self)

    @staticmethod
    def concat(parts: list[PickInputs]) -> PickInputs:
        """One batch of several, in order (every part with the same model fields)."""
        return tree_map(lambda *a: np.concatenate(a), *parts)

    def leaves(self) -> list[np.ndarray]:
        """Every array, in ``jax.tree.leaves``' order (fields in order, dict keys sorted)."""
        return tree_leaves(self)


def tree_map(fn, *trees):
    """fn over the arrays of trees of one structure (NamedTuples, tuples and dicts of
    arrays), as ``jax.tree.map``: a backend's host side needs no JAX."""
    first = trees[0]
    if isinstance(first, dict):
        return {k: tree_map(fn, *(t[k] for t in trees)) for k in first}
    if isinstance(first, tuple):
        items = [tree_map(fn, *parts) for parts in zip(*trees, strict=True)]
        return type(first)(*items) if hasattr(first, "_fields") else tuple(items)
    return fn(*trees)


def tree_leaves(tree) -> list:
    """The arrays of a tree (as :func:`tree_map` sees it), in ``jax.tree.leaves``' order."""
    if isinstance(tree, dict):
        return [leaf for k in sorted(tree) for leaf in tree_leaves(tree[k])]
    if isinstance(tree, tuple):
        return [leaf for item in tree for leaf in tree_leaves(item)]
    return [tree]


def addresses(scene: Scene) -> kt.Addresses:
    i = scene.index
    return kt.Addresses(
        object_qpos=i.object_qpos,
        lift_qpos=i.lift_qpos,
        finger_left_qpos=i.finger_left_qpos,
        finger_right_qpos=i.finger_right_qpos,
        object_body=i.object_body,
        finger_left_body=i.finger_left_body,
        finger_right_body=i.finger_right_body,
        lift_actuator=i.lift_actuator,
        finger_left_actuator=i.finger_left_actuator,
        finger_right_actuator=i.finger_right_actuator,
        nu=scene.model.nu,
        drive=i.drive,
    )


def scene_of(obj: ObjectModel, settings: Settings) -> Scene:
    """The compiled scene of obj under settings."""
    s = settings
    return build_scene(obj, s.gripper, s.contact, s.solver, s.grasp)


def pick_inputs(
    scene: Scene, settings: Settings, picks: GraspBatch, overrides: dict | None = None
) -> PickInputs:
    """picks' inputs under settings, on a scene of settings' structure
    (``Settings.structure``): the contact and controller values are settings' own, the
    model fields the scene's. overrides: as :func:`make_inputs`'."""
    mjc = scene_contact(scene, settings.contact, settings.solver)
    params = settings.grasp.params(scene.object, settings.gripper)
    return _inputs(scene, params, mjc, picks, overrides)


def make_inputs(
    scene: Scene, grasp: GraspConfig, picks: GraspBatch, overrides: dict | None = None
) -> PickInputs:
    """picks' inputs on scene with its own contact values and grasp's controller;
    overrides maps a parameter to one value or (N,) values.

    Override names: GraspParams fields (SI: grip_force_n, kp, ...) and CONTACT_OVERRIDES
    (pad_friction, pad_torsion [m], table_friction, pad_solref (2,), table_solref (2,),
    pad_solimp (5,), table_solimp (5,)). A pad_friction override scales the torsional
    friction with it (both come from the same Coulomb coefficient) unless pad_torsion
    is given too.
    """
    return _inputs(
        scene, grasp.params(scene.object, scene.gripper), scene.contact, picks, overrides
    )


def scene_contact(scene: Scene, contact: ContactParams, solver: SolverParams) -> MujocoContact:
    """contact and solver as MuJoCo pair values for the scene's object and pads."""
    patch = scene.pad_patch_mm
    return mujoco_contact(contact, solver, scene.object.mass_kg, patch, pad_box=scene.box_pads)


def contact_values(mjc: MujocoContact) -> dict:
    """The pair values of mjc by CONTACT_OVERRIDES name (float32), for :func:`set_contact`."""
    f32 = np.float32
    return {
        "pad_friction": f32(mjc.pad_friction),
        "pad_torsion": f32(mjc.pad_torsion_m),
        "table_friction": f32(mjc.table_friction),
        "pad_solref": np.asarray(mjc.pad_solref, f32),
        "table_solref": np.asarray(mjc.table_solref, f32),
        "pad_solimp": np.asarray(mjc.pad_solimp, f32),
        "table_solimp": np.asarray(mjc.table_solimp, f32),
    }


def _inputs(scene: Scene, params, mjc: MujocoContact, picks: GraspBatch, overrides) -> PickInputs:
    """The one conversion: picks' start poses, params broadcast with overrides, and
    mjc's contact values (with overrides) written into the scene's pair arrays."""
    overrides = dict(overrides or {})
    n = len(picks)
    start = scene.placement(picks)
    qpos0 = start.qpos.astype(np.float32)
    if start.model:  # grasps that are not vertical: the kernels measure along their axis
        for k, name in enumerate(("closing_axis_x", "closing_axis_y", "closing_axis_z")):
            overrides.setdefault(name, start.closing_axis[:, k])
    given = {k: overrides.pop(k) for k in CONTACT_OVERRIDES if k in overrides}
    contact = contact_values(mjc)
    if "pad_friction" in given and "pad_torsion" not in given:
        per_mu = np.float32(mjc.torsion_per_friction_m)
        given["pad_torsion"] = np.asarray(given["pad_friction"], np.float32) * per_mu
    contact.update(given)
    m = scene.model
    friction, solref, solimp = set_contact(
        scene,
        np.broadcast_to(m.pair_friction, (n, m.npair, 5)).astype(np.float32),
        np.broadcast_to(m.pair_solref, (n, m.npair, 2)).astype(np.float32),
        np.broadcast_to(m.pair_solimp, (n, m.npair, 5)).astype(np.float32),
        contact,
    )
    if np.any(friction[..., 0] < 0) or np.any(~np.isfinite(friction)):
        raise ConfigError("friction overrides must be finite and >= 0")
    params = broadcast_params(params, n, **overrides)
    return PickInputs(qpos0, params, friction, solref, solimp, dict(start.model))


def set_contact(scene: Scene, friction, solref, solimp, values: dict, xp=np):
    """The contact-pair arrays with named contact values written into the scene's pad
    and table pairs: the one mapping from contact values to MuJoCo pair parameters
    (evaluate's overrides in numpy, calibration's differentiable fit in ``jax.numpy``).

    Args:
      scene: names the pad and table pairs.
      friction, solref, solimp: (N, npair, 5), (N, npair, 2), (N, npair, 5) base arrays.
      values: CONTACT_OVERRIDES names; the frictions and pad_torsion (m) a scalar or (N,),
        the solrefs (2,) or (N, 2), the solimps (5,) or (N, 5). A pad_friction without
        a pad_torsion scales the scene's torsional friction with it (both come from the
        same Coulomb coefficient).
      xp: numpy or jax.numpy (differentiable in the values).

    Returns:
      (friction, solref, solimp), new arrays of the inputs' shapes and dtypes.
    """
    # an MJCF gripper's link contacts take the pads' values, as in the scene's XML
    pads = [*scene.index.pad_pairs, *scene.index.link_pairs]
    table = list(scene.index.table_pairs)
    values = dict(values)
    if "pad_friction" in values and "pad_torsion" not in values:
        per_mu = np.float32(scene.contact.torsion_per_friction_m)
        values["pad_torsion"] = xp.asarray(values["pad_friction"], friction.dtype) * per_mu
    # (array, pairs, columns, vector): where each value goes
    targets = {
        "pad_friction": ("friction", pads, (0, 1), False),
        "pad_torsion": ("friction", pads, (2,), False),
        "table_friction": ("friction", table, (0, 1), False),
        "pad_solref": ("solref", pads, (0, 1), True),
        "table_solref": ("solref", table, (0, 1), True),
        "pad_solimp": ("solimp", pads, (0, 1, 2, 3, 4), True),
        "table_solimp": ("solimp", table, (0, 1, 2, 3, 4), True),
    }
    arrays = {"friction": friction, "solref": solref, "solimp": solimp}
    for name, (which, pairs, cols, vector) in targets.items():
        if name in values:
            arrays[which] = _set_pairs(arrays[which], pairs, cols, values[name], vector, xp)
    return arrays["friction"], arrays["solref"], arrays["solimp"]


def _set_pairs(arr, pairs, cols, value, vector: bool, xp):
    """arr (N, npair, C) with arr[:, pairs, cols] = value; value: a scalar or (N,) when
    not vector (the same in every column), else (len(cols),) or (N, len(cols))."""
    n, npair, width = arr.shape
    v = xp.asarray(value, arr.dtype)
    # (1 or N, k): one row for every simulation, or a row each; a scalar fills k columns
    v = v.reshape((-1, len(cols))) if vector else v.reshape((-1, 1))
    v = xp.broadcast_to(v, (n, len(cols)))
    zero = xp.zeros((n,), arr.dtype)
    full = xp.stack([v[:, cols.index(c)] if c in cols else zero for c in range(width)], axis=-1)
    mask = np.zeros((npair, width), bool)
    mask[np.ix_(pairs, cols)] = True
    return xp.where(mask[None], full[:, None, :], arr)
