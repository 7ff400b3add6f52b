"""What every backend shares: batched inputs, per-pick overrides, the Backend protocol
and backend choice.

A backend turns :class:`PickInputs` (N pick-points: initial joint positions, per-pick
controller parameters and contact-pair parameters) into per-pick results (the dict of
``mjx_pick.kernels.grasp.finalize``) and, on request, traces. MuJoCo Warp and MJX's JAX
physics (GPU) and the MuJoCo C engine (CPU) implement it; ``make_backend`` picks one.
Callers do not run backends themselves: ``mjx_pick.engine.runner`` does (chunks, progress,
cancellation, timing).
"""

from __future__ import annotations

import dataclasses
from typing import NamedTuple, Protocol

import jax
import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.physics import ContactParams, SolverParams, mujoco_contact
from mjx_pick.core.pickpoints import PickBatch
from mjx_pick.core.procedure import GraspConfig, broadcast_params
from mjx_pick.core.scene import Scene
from mjx_pick.engine import registry
from mjx_pick.kernels import types as kt

# per-pick contact overrides accepted by make_inputs (besides GraspParams' fields)
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
        return jax.tree.map(lambda a: a[index], self)

    def pad_to(self, n: int) -> PickInputs:
        """Pad to n entries with copies of the first (results of the copies are dropped)."""
        extra = n - len(self)
        if extra <= 0:
            return self
        return jax.tree.map(lambda a: np.concatenate([a, np.repeat(a[:1], extra, axis=0)]), self)


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


def make_inputs(
    scene: Scene, grasp: GraspConfig, picks: PickBatch, overrides: dict | None = None
) -> PickInputs:
    """Batched inputs for picks; overrides maps a parameter to one value or (N,) values.

    Override names: GraspParams fields (SI: grip_force_n, kp, ...) and CONTACT_OVERRIDES
    (pad_friction, pad_torsion [m], table_friction, pad_solref (2,), table_solref (2,),
    pad_solimp (5,), table_solimp (5,)). A pad_friction override scales the scene's
    torsional friction with it (both come from the same Coulomb coefficient) unless
    pad_torsion is given too.
    """
    overrides = dict(overrides or {})
    n = len(picks)
    # the gap the pads close to (the object's width between them): the MJCF linkage's
    # height compensation
    grasp_gap_m = picks.grasp_gap_mm * 1e-3
    qpos0 = scene.initial_qpos(
        picks.x_mm * 1e-3,
        picks.y_mm * 1e-3,
        np.deg2rad(picks.yaw_deg),
        picks.opening_mm * 1e-3,
        grasp_gap_m,
    ).astype(np.float32)
    contact = {k: overrides.pop(k) for k in CONTACT_OVERRIDES if k in overrides}
    params = broadcast_params(grasp.params(scene.object, scene.gripper), n, **overrides)
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
    return PickInputs(qpos0, params, friction, solref, solimp)


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
    pads, table = list(scene.index.pad_pairs), list(scene.index.table_pairs)
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


@dataclasses.dataclass
class RunStats:
    """Timing of one backend call: compile time apart from run time."""

    compile_s: float = 0.0
    run_s: float = 0.0
    n: int = 0


class Backend(Protocol):
    """What the engine needs of a backend (one module implements it; ``engine.registry``).

    A backend simulates every pick-point on its own: a pick's result must not depend on
    which other pick-points share its call, so the engine may split a run into chunks
    (whole numbers of batches: the same compiled programs, hence the same rounding).
    A device backend may also have ``devices`` (a list of JAX devices) and
    ``device_bytes_per_pick()``: the engine then sizes chunks from free device memory.
    """

    name: str  # its registry name
    device: str  # what it runs on, in words ("cpu:2 threads", "gpu:NVIDIA H100 x2")
    stats: RunStats  # compile time apart from run time, summed over calls
    scene: Scene
    batch_size: int  # simulations per device program (slots of a refilled pool)

    def run(self, inputs: PickInputs, record: bool = False) -> tuple[dict, np.ndarray | None]:
        """Per-pick results (numpy, (N,) each: ``kernels.grasp.finalize``'s fields) and,
        with record, traces (N, T, F) at the control rate (``kernels.grasp.TRACE_FIELDS``)."""
        ...


def make_backend(
    name: str,
    scene: Scene,
    grasp: GraspConfig,
    batch_size: int,
    nthread: int | None = None,
    devices=None,
    **options,
) -> Backend:
    """A backend by name: 'auto' or one of ``registry.ENTRIES`` (its factory).

    devices: the devices a device backend shards each batch over (default: its own
    choice); nthread: a CPU backend's threads. options: the entry's options.
    """
    entry = registry.entry(name)
    grasp.substeps(scene.solver)  # validates the control period against the time step
    allowed = {o.name for o in entry.options}
    unknown = sorted(k for k in options if k not in allowed)
    if unknown:
        raise ConfigError(f"backend {entry.name!r} takes no options {unknown}")
    # devices and nthread are hints: a CPU backend runs threads, a device backend
    # shards over devices; neither is given the other's
    hint = ("nthread", nthread) if entry.device is registry.Device.CPU else ("devices", devices)
    if hint[1] is not None:
        options[hint[0]] = hint[1]
    return registry.load(entry.factory)(scene, grasp, batch_size, **options)


@dataclasses.dataclass(frozen=True)
class Settings:
    """Every physical setting of one simulated variant: gripper, contact, solver, grasp.

    Sweeps, gripper comparisons, design searches, robustness and calibration all run
    lists of (Settings, PickBatch) jobs through one ``engine.Simulator``.
    """

    gripper: GripperSpec = dataclasses.field(default_factory=GripperSpec)
    contact: ContactParams = dataclasses.field(default_factory=ContactParams)
    solver: SolverParams = dataclasses.field(default_factory=SolverParams)
    grasp: GraspConfig = dataclasses.field(default_factory=GraspConfig)

    def structure(self) -> tuple:
        """What fixes the compiled scene: gripper, solver, scan length, grasp height and
        the contact settings that shape the model (the pads' collision geoms and
        margin). Everything else (the other contact numbers, controller, phases) is
        per-pick data; scenes of one model structure also share a compiled program,
        their differing model fields carried per pick (``engine.variants.program_key``)."""
        return (
            self.gripper,
            self.solver,
            self.contact.pad_collision,
            self.contact.pad_margin_mm,
            self.grasp.n_ticks(),
            self.grasp.substeps(self.solver),
            self.grasp.grasp_height,
            self.grasp.fingertip_clearance_mm,
        )

    def overrides(self, scene: Scene, n: int) -> dict:
        """Per-pick overrides for make_inputs that give n pick-points these settings.

        scene: the compiled scene of these settings' structure (its object and pad
        patch are these settings' too: the patch depends on gripper and grasp height).
        """
        obj = scene.object
        mjc = mujoco_contact(
            self.contact,
            self.solver,
            obj.mass_kg,
            scene.pad_patch_mm,
            pad_box=scene.gripper.mjcf is None,
        )
        params = self.grasp.params(obj, self.gripper)._asdict()
        out = {name: np.full(n, v, np.float32) for name, v in params.items()}
        out["pad_friction"] = np.full(n, mjc.pad_friction, np.float32)
        out["pad_torsion"] = np.full(n, mjc.pad_torsion_m, np.float32)
        out["table_friction"] = np.full(n, mjc.table_friction, np.float32)
        out["pad_solref"] = np.tile(np.asarray(mjc.pad_solref, np.float32), (n, 1))
        out["table_solref"] = np.tile(np.asarray(mjc.table_solref, np.float32), (n, 1))
        out["pad_solimp"] = np.tile(np.asarray(mjc.pad_solimp, np.float32), (n, 1))
        out["table_solimp"] = np.tile(np.asarray(mjc.table_solimp, np.float32), (n, 1))
        return out
