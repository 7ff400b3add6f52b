"""What both backends share: batched inputs, per-pick overrides, backend choice.

A backend turns :class:`PickInputs` (N pick-points: initial joint positions, per-pick
controller parameters and contact-pair parameters) into per-pick results (the dict of
``mjx_pick.kernels.grasp.finalize``) and, on request, traces. MJX (GPU) and the MuJoCo
C engine (CPU) implement it; ``make_backend`` picks one.
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple, Protocol

import jax
import numpy as np

from mjx_pick.config import ConfigError
from mjx_pick.grasp import GraspConfig, broadcast_params
from mjx_pick.kernels import grasp as gk
from mjx_pick.pickpoints import PickBatch
from mjx_pick.scene import Scene

# per-pick contact overrides accepted by make_inputs (besides GraspParams' fields)
CONTACT_OVERRIDES = ("pad_friction", "table_friction", "pad_solref", "table_solref", "solimp")


class PickInputs(NamedTuple):
    """Everything N simulations need, batched along the first axis."""

    qpos0: np.ndarray  # (N, nq)
    params: gk.GraspParams  # fields (N,)
    pair_friction: np.ndarray  # (N, npair, 5)
    pair_solref: np.ndarray  # (N, npair, 2)
    pair_solimp: np.ndarray  # (N, npair, 5)

    def __len__(self) -> int:
        return len(self.qpos0)

    def take(self, index) -> PickInputs:
        return jax.tree.map(lambda a: a[index], self)

    def pad_to(self, n: int) -> PickInputs:
        """Pad to n entries with copies of the first (results of the copies are dropped)."""
        extra = n - len(self)
        if extra <= 0:
            return self
        return jax.tree.map(lambda a: np.concatenate([a, np.repeat(a[:1], extra, axis=0)]), self)


def addresses(scene: Scene) -> gk.Addresses:
    i = scene.index
    return gk.Addresses(
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
    )


def make_inputs(
    scene: Scene, grasp: GraspConfig, picks: PickBatch, overrides: dict | None = None
) -> PickInputs:
    """Batched inputs for picks; overrides maps a parameter to one value or (N,) values.

    Override names: GraspParams fields (SI: force_n, kp, ...) and CONTACT_OVERRIDES
    (pad_friction, table_friction, pad_solref (2,), table_solref (2,), solimp (5,)).
    """
    overrides = dict(overrides or {})
    n = len(picks)
    qpos0 = scene.initial_qpos(
        picks.x_mm * 1e-3, picks.y_mm * 1e-3, np.deg2rad(picks.yaw_deg), picks.opening_mm * 1e-3
    ).astype(np.float32)
    contact = {k: overrides.pop(k) for k in CONTACT_OVERRIDES if k in overrides}
    params = broadcast_params(grasp.params(scene.object), n, **overrides)
    m = scene.model
    friction = np.broadcast_to(m.pair_friction, (n, m.npair, 5)).astype(np.float32).copy()
    solref = np.broadcast_to(m.pair_solref, (n, m.npair, 2)).astype(np.float32).copy()
    solimp = np.broadcast_to(m.pair_solimp, (n, m.npair, 5)).astype(np.float32).copy()
    pads, table = list(scene.index.pad_pairs), list(scene.index.table_pairs)
    if "pad_friction" in contact:
        mu = np.broadcast_to(np.asarray(contact["pad_friction"], np.float32), (n,))
        friction[:, pads, 0] = mu[:, None]
        friction[:, pads, 1] = mu[:, None]
    if "table_friction" in contact:
        mu = np.broadcast_to(np.asarray(contact["table_friction"], np.float32), (n,))
        friction[:, table, 0] = mu[:, None]
        friction[:, table, 1] = mu[:, None]
    if "pad_solref" in contact:
        solref[:, pads] = np.broadcast_to(np.asarray(contact["pad_solref"], np.float32), (n, 2))[
            :, None
        ]
    if "table_solref" in contact:
        ref = np.broadcast_to(np.asarray(contact["table_solref"], np.float32), (n, 2))
        solref[:, table] = ref[:, None]
    if "solimp" in contact:
        solimp[:] = np.broadcast_to(np.asarray(contact["solimp"], np.float32), (n, 5))[:, None]
    if np.any(friction[..., 0] < 0) or np.any(~np.isfinite(friction)):
        raise ConfigError("friction overrides must be finite and >= 0")
    return PickInputs(qpos0, params, friction, solref, solimp)


@dataclasses.dataclass
class RunStats:
    """Timing of one backend call: compile time apart from run time."""

    compile_s: float = 0.0
    run_s: float = 0.0
    n: int = 0


class Backend(Protocol):
    name: str
    device: str
    stats: RunStats

    def run(self, inputs: PickInputs, record: bool = False) -> tuple[dict, np.ndarray | None]:
        """Per-pick results (numpy, (N,) each) and, with record, traces (N, T, F)."""
        ...


def has_accelerator() -> bool:
    return any(d.platform in ("gpu", "tpu", "cuda", "rocm") for d in jax.devices())


def make_backend(
    name: str,
    scene: Scene,
    grasp: GraspConfig,
    batch_size: int,
    nthread: int | None = None,
    devices=None,
) -> Backend:
    """'auto' (MJX when JAX sees a GPU or TPU, else the C engine), 'mjx' or 'mujoco'.

    devices: MJX shards each batch over these (default: every local device).
    """
    if name not in ("auto", "mjx", "mujoco"):
        raise ConfigError(f"backend = {name!r} is not allowed: choose 'auto', 'mjx' or 'mujoco'")
    if name == "auto":
        name = "mjx" if has_accelerator() else "mujoco"
    grasp.substeps(scene.solver)  # validates the control period against the time step
    if name == "mjx":
        from mjx_pick.backend_mjx import MjxBackend

        return MjxBackend(scene, grasp, batch_size, devices=devices)
    from mjx_pick.backend_mujoco import MujocoBackend

    return MujocoBackend(scene, grasp, batch_size, nthread=nthread)
