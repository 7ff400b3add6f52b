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
import importlib
import inspect
from typing import NamedTuple, Protocol

import jax
import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.physics import ContactParams, SolverParams, mujoco_contact
from mjx_pick.core.pickpoints import PickBatch
from mjx_pick.core.procedure import GraspConfig, broadcast_params
from mjx_pick.core.scene import Scene
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
    """What the engine needs of a backend (one module implements it; see FACTORIES).

    A backend simulates every pick-point on its own: a pick's result must not depend on
    which other pick-points share its call, so the engine may split a run into chunks
    (whole numbers of batches: the same compiled programs, hence the same rounding).
    A device backend may also have ``devices`` (a list of JAX devices) and
    ``device_bytes_per_pick()``: the engine then sizes chunks from free device memory.
    """

    name: str  # as in FACTORIES
    device: str  # what it runs on, in words ("cpu:2 threads", "gpu:NVIDIA H100 x2")
    stats: RunStats  # compile time apart from run time, summed over calls
    scene: Scene
    batch_size: int  # simulations per device program (slots of a refilled pool)

    def run(self, inputs: PickInputs, record: bool = False) -> tuple[dict, np.ndarray | None]:
        """Per-pick results (numpy, (N,) each: ``kernels.grasp.finalize``'s fields) and,
        with record, traces (N, T, F) at the control rate (``kernels.grasp.TRACE_FIELDS``)."""
        ...


def has_accelerator() -> bool:
    """Whether JAX sees a GPU or TPU (device batches are sized for it)."""
    return any(d.platform in ("gpu", "tpu", "cuda", "rocm") for d in jax.devices())


# The backends: name -> "module:factory", imported only when chosen. A factory is called
# as factory(scene, grasp, batch_size, **options) and returns a Backend; its keyword
# parameters are the options it takes. A new backend is one module with such a factory
# (a class implementing Backend is one), added here.
FACTORIES = {
    "warp": "mjx_pick.engine.warp_backend:make_warp_backend",
    "mjx": "mjx_pick.engine.mjx_backend:MjxBackend",
    "mujoco": "mjx_pick.engine.c_backend:MujocoBackend",
}
BACKENDS = ("auto", *FACTORIES)


def make_backend(
    name: str,
    scene: Scene,
    grasp: GraspConfig,
    batch_size: int,
    nthread: int | None = None,
    devices=None,
    **options,
) -> Backend:
    """A backend by name: 'warp', 'mjx', 'mujoco' or 'auto'.

    'warp': MJX with MuJoCo Warp physics on an NVIDIA GPU (needs warp-lang, the gpu
    extra; a ConfigError says what is missing). 'mjx': MJX's JAX physics on JAX's
    devices (forward-mode derivatives). 'mujoco': the C engine on CPU threads. 'auto':
    'warp' where it can run (an NVIDIA GPU and warp-lang), else 'mujoco' -- on a GPU
    without warp-lang the C engine's threads beat MJX's JAX physics.

    devices: MJX/Warp shard each batch over these (default: every local device; Warp:
    every CUDA device). nthread: the C engine's threads. options: passed to the MJX or
    Warp backend (refill, ticks_per_call, shrink_levels; Warp: buffers, graph_mode).
    """
    name = resolve_backend(name)
    grasp.substeps(scene.solver)  # validates the control period against the time step
    module, _, attr = FACTORIES[name].partition(":")
    factory = getattr(importlib.import_module(module), attr)
    takes = inspect.signature(factory).parameters
    # a factory with **options checks them itself (Warp passes them on per device)
    open_ended = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in takes.values())
    unknown = [] if open_ended else sorted(k for k in options if k not in takes)
    if unknown:
        raise ConfigError(f"backend {name!r} takes no options {unknown}")
    # devices and nthread are hints for the backends that have them (MJX/Warp shard over
    # devices, the C engine runs threads); another backend ignores them
    for key, value in (("devices", devices), ("nthread", nthread)):
        if value is not None and key in takes:
            options[key] = value
    return factory(scene, grasp, batch_size, **options)


def resolve_backend(name: str) -> str:
    """The backend a name runs: 'auto' becomes 'warp' where it can run, else 'mujoco'."""
    if name not in BACKENDS:
        allowed = ", ".join(repr(b) for b in BACKENDS)
        raise ConfigError(f"backend = {name!r} is not allowed: choose one of {allowed}")
    if name == "auto":
        from mjx_pick.engine.devices import warp_problem

        return "mujoco" if warp_problem() else "warp"
    return name


def default_batch_size(backend_name: str) -> int:
    """Simulations per backend call (slots of Warp's refilled pool): measured best."""
    name = resolve_backend(backend_name)
    if name == "mujoco":
        return 1024  # a batch per call amortises the per-tick kernel's dispatch
    if name == "warp":
        # slots per GPU (every GPU runs its own pool): the largest pool that fits an
        # H100 with room for the contact buffers; the throughput benchmark chose it
        from mjx_pick.engine.devices import nvidia_gpus

        return 32768 * max(len(nvidia_gpus()), 1)
    return 8192 if has_accelerator() else 64


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
