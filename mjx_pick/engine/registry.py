"""The backends: one entry each, and the one place where 'auto' is resolved.

Everything that offers a choice of backend (the CLI, the GUI, the cluster, variants,
throughput) reads :data:`ENTRIES`. Adding a backend is one module with a factory and one
entry here (docs/architecture.md). Importing this module imports no engine.
"""

from __future__ import annotations

import dataclasses
import enum
import importlib
from collections.abc import Callable

from mjx_pick.core.config import ConfigError
from mjx_pick.core.physics import differentiable_physics

AUTO = "auto"  # the choice this module resolves (:func:`resolve`)


class Impl(enum.StrEnum):
    """The shipped backends, by the name a user chooses."""

    WARP = "warp"
    MJX_WARP = "mjx-warp"
    MJX = "mjx"
    MUJOCO = "mujoco"


class Device(enum.Enum):
    """What a backend needs to run on."""

    NVIDIA_GPU = "an NVIDIA GPU"
    JAX = "any JAX device"
    CPU = "CPU threads"


class Jax(enum.Enum):
    """Where a backend runs JAX programs (``devices.keep_jax_on_cpu`` says why it matters)."""

    NONE = "no JAX program"  # JAX's host-side users in its process are kept on the CPU
    CPU = "JAX programs on the CPU"  # the C engine's per-tick controller
    DEVICES = "JAX programs on JAX's devices"


@dataclasses.dataclass(frozen=True)
class BatchRule:
    """A backend's default simulations per call.

    cpu: without a GPU or TPU; accelerator: with one (None: as cpu); per_gpu: times the
    NVIDIA GPUs it runs on (each runs a pool of its own).
    """

    cpu: int
    accelerator: int | None = None
    per_gpu: bool = False

    def size(self, gpus: int, accelerator: bool) -> int:
        """The batch size on `gpus` NVIDIA GPUs, with or without an accelerator."""
        size = self.accelerator if accelerator and self.accelerator else self.cpu
        return size * max(gpus, 1) if self.per_gpu else size

    def describe(self) -> str:
        """In words, for help texts: '1024', '32768 per GPU', '8192 on an accelerator
        (64 without)'."""
        if self.per_gpu:
            return f"{self.accelerator or self.cpu} per GPU"
        if self.accelerator and self.accelerator != self.cpu:
            return f"{self.accelerator} on an accelerator ({self.cpu} without)"
        return str(self.cpu)


@dataclasses.dataclass(frozen=True)
class Rate:
    """What one pick-point costs a backend, measured: wall seconds on one unit (a CPU
    thread, a GPU, a JAX device) per second the pick simulates, at the default time
    step (``studies.duration`` estimates a run's time from it).

    source: where and when it was measured. full_length: every pick runs the
    procedure's whole length (no pick ends early). gpu_per_sim_s: a JAX backend's
    figure on an NVIDIA GPU (per_sim_s: on the CPU)."""

    per_sim_s: float
    source: str
    full_length: bool = False
    gpu_per_sim_s: float | None = None


@dataclasses.dataclass(frozen=True)
class Option:
    """A keyword option of a backend's factory.

    parse: reads it from text (a benchmark's ``key=value``); None: library callers only.
    """

    name: str
    parse: Callable[[str], object] | None
    meaning: str


def _flag(text: str) -> bool:
    return text.lower() in ("1", "true", "yes")


@dataclasses.dataclass(frozen=True)
class BackendEntry:
    """One backend.

    Attributes:
      name: what users choose (an :class:`Impl` for the shipped ones).
      factory: "module:attr", imported only when the backend is chosen; called as
        ``factory(scene, grasp, batch_size, **options)`` and returns a
        ``backend.Backend``. A CPU backend is also given ``nthread``, a device backend
        ``devices``, when the caller has them.
      device: what it needs to run on.
      batch: its default batch size.
      description: one line for help texts.
      options: the keyword options its factory takes (besides nthread/devices).
      auto_rank: 'auto' takes the lowest-ranked backend that can run (None: never).
      problem: "module:attr" of ``() -> str | None``: why it cannot run on this machine
        (None: nothing is checked beyond its device need).
      model_fields: "module:attr" of ``(fields: frozenset[str]) -> frozenset[str]``:
        those of the MjModel fields it can take per simulation (``engine.variants``);
        None: it takes none, and each gripper variant gets a program of its own.
      program_reads: model values its compiled program reads that no simulation can
        carry ('stat.meaninertia'): scenes share its program only where they are equal.
      jax: where it runs JAX programs (:class:`Jax`); JAX's compiled programs are kept on
        disk (``engine.compiled``) for those that run any.
      differentiable: its rollouts have forward-mode derivatives (calibration's jvp).
      reference: the engine whose labels the others' are compared with (throughput).
      stops_finished: a call simulates each pick only until it ends (its physics steps
        are not counted from the batch).
      cuda_devices: its devices are CUDA ordinals ('cuda:0', ...), not JAX devices.
      note: said when a user chooses it by name (a limit to know).
      rate: its measured cost per pick-point (:class:`Rate`), from which a run's time
        is estimated before it starts; None: not measured (no estimate is given).
    """

    name: str
    factory: str
    device: Device
    batch: BatchRule
    description: str
    options: tuple[Option, ...] = ()
    auto_rank: int | None = None
    problem: str | None = None
    model_fields: str | None = None
    program_reads: tuple[str, ...] = ()
    jax: Jax = Jax.NONE
    differentiable: bool = False
    reference: bool = False
    stops_finished: bool = False
    cuda_devices: bool = False
    note: str = ""
    rate: Rate | None = None

    def __post_init__(self):
        object.__setattr__(self, "name", str(self.name))  # an Impl as its plain name


_POOL_OPTIONS = (
    Option("refill", _flag, "refill the slots of finished picks on the device"),
    Option("ticks_per_call", int, "control ticks per device call of a refilled pool"),
    Option("shrink_levels", int, "how often a draining pool may halve its slots"),
)

ENTRIES: dict[str, BackendEntry] = {
    e.name: e
    for e in (
        BackendEntry(
            Impl.WARP,
            "mjx_pick.engine.warp_direct:make_backend",
            Device.NVIDIA_GPU,
            # slots per GPU: the largest pool that fits one with room for the contact
            # buffers (benchmarks/throughput.py)
            BatchRule(cpu=32768, per_gpu=True),
            "MuJoCo Warp on NVIDIA GPUs, driven directly (pip install '.[gpu]')",
            options=(
                Option("ticks_per_call", int, "control ticks between refills of the pool"),
                Option("buffers", None, "contact and constraint buffer sizes (BufferSizes)"),
                Option("deterministic", _flag, "MuJoCo Warp's deterministic mode"),
                Option("shrink_levels", int, "how often a draining pool may halve its slots"),
            ),
            auto_rank=0,
            problem="mjx_pick.engine.warp_direct:warp_problem",
            model_fields="mjx_pick.engine.warp_direct:model_fields",
            cuda_devices=True,
            # 1,569-1,611 door-opener picks/s on one H100 at the default procedure (1.6
            # simulated s a pick, duration.expected_pick_s): 1 / (1,590 x 1.6)
            rate=Rate(3.93e-4, "benchmarks/RESULTS.md, throughput.py, H100, 2026-11-27"),
        ),
        BackendEntry(
            Impl.MJX_WARP,
            "mjx_pick.engine.warp_backend:make_warp_backend",
            Device.NVIDIA_GPU,
            BatchRule(cpu=32768, per_gpu=True),
            "MuJoCo Warp through MJX's JAX bridge (the MJX program on Warp's kernels)",
            options=(
                *_POOL_OPTIONS,
                Option("buffers", None, "contact and constraint buffer sizes (BufferSizes)"),
                Option("graph_mode", str, "how Warp captures its CUDA graphs"),
            ),
            # not for 'auto': the same physics as 'warp' with JAX's costs on top
            problem="mjx_pick.engine.devices:warp_problem",
            model_fields="mjx_pick.engine.variants:mjx_warp_fields",
            jax=Jax.DEVICES,
            # 1,546 door-opener picks/s on one H100 (1.6 simulated s a pick)
            rate=Rate(4.04e-4, "benchmarks/RESULTS.md, throughput.py, H100, 2026-11-27"),
        ),
        BackendEntry(
            Impl.MJX,
            "mjx_pick.engine.mjx_backend:MjxBackend",
            Device.JAX,
            BatchRule(cpu=64, accelerator=8192),
            "MJX's JAX physics, for derivatives; runs the differentiable physics only",
            options=_POOL_OPTIONS,
            # not for 'auto': where Warp cannot run, the C engine's threads beat it
            model_fields="mjx_pick.engine.variants:mjx_fields",
            jax=Jax.DEVICES,
            differentiable=True,
            # every pick its full 2.63 simulated s: 0.85-2.86 s a pick on a 2-core CPU
            # at the differentiable physics (mean 1.74 / 2.63); on an H100 110 picks/s
            # (the old pyramidal physics, 10 iterations: the differentiable one's 20 cost
            # more, so the GPU figure is a floor)
            rate=Rate(
                0.66,
                "benchmarks/RESULTS.md, mjx_physics.py (2-core CPU, 2026-11-27) and "
                "throughput.py (H100, 2026-11-22)",
                full_length=True,
                gpu_per_sim_s=3.5e-3,
            ),
            note="MJX's JAX physics, kept for derivatives: it runs the differentiable "
            f"physics alone ({differentiable_physics()}) and refuses other settings, saying "
            "what to pass; its labels are not MuJoCo C's at the default physics: for labels "
            "use --backend mujoco or warp (auto)",
        ),
        BackendEntry(
            Impl.MUJOCO,
            "mjx_pick.engine.c_backend:MujocoBackend",
            Device.CPU,
            BatchRule(cpu=1024),  # amortises the per-tick kernel's dispatch
            "the C engine on CPU threads",
            auto_rank=2,
            model_fields="mjx_pick.engine.variants:batch_fields",
            program_reads=("stat.meaninertia",),
            jax=Jax.CPU,
            reference=True,
            stops_finished=True,
            # 0.030 CPU s per simulated s of a pick (the block and the door opener,
            # default and short procedure, benchmarks/duration_rates.py on the 2-core dev
            # machine, 2026-11-28), at 0.55 of each thread busy (157-166 door-opener
            # picks/s on 16 threads of an H100 host, RESULTS.md: 0.055 CPU s a pick):
            # 0.030 / 0.55 wall s per thread
            rate=Rate(
                0.054,
                "benchmarks/duration_rates.py (2-core CPU, 2026-11-28) and RESULTS.md "
                "throughput.py (16 threads, 2026-11-27)",
            ),
        ),
    )
}


def load(ref: str):
    """The object a "module:attr" reference names (imported now)."""
    module, _, attr = ref.partition(":")
    return getattr(importlib.import_module(module), attr)


def names() -> tuple[str, ...]:
    """The backends, in the table's order."""
    return tuple(ENTRIES)


def choices() -> tuple[str, ...]:
    """What a user may choose: 'auto' and every backend."""
    return (AUTO, *ENTRIES)


def auto_order() -> tuple[BackendEntry, ...]:
    """The backends 'auto' may pick, first choice first."""
    ranked = [e for e in ENTRIES.values() if e.auto_rank is not None]
    return tuple(sorted(ranked, key=lambda e: e.auto_rank))


def check(name: str) -> str:
    """name, if it is 'auto' or a backend; else a ConfigError listing the choices."""
    if name not in choices():
        allowed = ", ".join(repr(b) for b in choices())
        raise ConfigError(f"backend = {name!r} is not allowed: choose one of {allowed}")
    return name


def entry(name: str) -> BackendEntry:
    """The entry of a backend ('auto' resolved on this machine)."""
    return ENTRIES[resolve(name)]


def problem(e: BackendEntry) -> str | None:
    """Why e cannot run on this machine, or None when it can."""
    return load(e.problem)() if e.problem else None


def resolve(name: str, gpus: int | None = None) -> str:
    """The backend a name runs: a backend's name is itself; 'auto' is the first of
    :func:`auto_order` that can run -- on this machine (gpus None: its :func:`problem`
    check passes), or on a cluster with `gpus` NVIDIA GPUs (its device need is met)."""
    if check(name) != AUTO:
        return name
    for e in auto_order():
        runs = problem(e) is None if gpus is None else e.device is not Device.NVIDIA_GPU or gpus
        if runs:
            return e.name
    raise ConfigError(f"backend = {AUTO!r}: none of {[e.name for e in auto_order()]} can run here")


def default_batch_size(name: str, gpus: int | None = None, accelerator: bool | None = None) -> int:
    """Simulations per backend call: the backend's :class:`BatchRule` on this machine,
    or on `gpus` NVIDIA GPUs with or without an accelerator (a cluster's actor)."""
    rule = entry(name).batch
    if rule.per_gpu and gpus is None:
        from mjx_pick.engine.devices import nvidia_gpu_count

        gpus = nvidia_gpu_count()
    if rule.accelerator and accelerator is None:
        from mjx_pick.engine.devices import has_accelerator

        accelerator = has_accelerator()
    return rule.size(gpus or 0, bool(accelerator))


def differentiable() -> str:
    """The backend whose rollouts have forward-mode derivatives."""
    return next(e.name for e in ENTRIES.values() if e.differentiable)


def reference() -> str:
    """The backend whose labels the others' are compared with."""
    return next(e.name for e in ENTRIES.values() if e.reference)


def backend_help() -> str:
    """The --backend help: each backend's description, then what 'auto' picks."""
    parts = [f"{e.name}: {e.description}" for e in ENTRIES.values()]
    *tried, last = [e.name for e in auto_order()]
    auto = ", else ".join([*(f"{n} where it can run" for n in tried), last])
    return "; ".join([*parts, f"{AUTO}: {auto}"])


def batch_size_help() -> str:
    """The --batch-size help's default: each backend's rule in words."""
    rules = ", ".join(f"{e.name} {e.batch.describe()}" for e in ENTRIES.values())
    return f"per backend: {rules}"
