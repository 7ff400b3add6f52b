"""MuJoCo Warp backend: the MJX program with ``impl='warp'`` on an NVIDIA GPU.

mujoco-mjx vendors MuJoCo Warp (``mujoco.mjx.third_party.mujoco_warp``) and calls its
CUDA kernels from JAX, so the project's rollout (``mjx_pick.engine.mjx_backend``: the shared
controller/metrics tick and ``mjx.step`` under ``lax.scan``, ``vmap`` and ``jit``) runs
unchanged; per-pick contact-pair parameters stay batched model fields. What differs:

* **Buffers.** Warp allocates contacts and constraint rows up front: ``naconmax``
  contacts for ALL simulations of a call together, ``njmax`` constraint rows for EACH.
  :func:`size_buffers` sizes them from the scene by measurement (a sample of
  pick-points simulated on the MuJoCo C engine, the largest counts seen, plus a
  margin). Warp raises an overflow bit in a simulation whose contacts or rows did not
  fit (and drops them); the rollout ORs those bits over every step, and the picks
  that overflowed are re-simulated with doubled buffers (``MAX_GROWTH`` times at most,
  then :class:`BufferOverflowError`): no result ever comes from a dropped contact.
* **cfrc_ext**, which the pad-force measurement reads, is computed by Warp only with
  the option ``run_rne_postconstraint`` on; it is switched on here.
* **No gradients** through Warp: MJX's JAX implementation (``backend='mjx'``) stays for
  forward-mode derivatives.
* **CUDA graphs.** ``graph_mode`` 'WARP' (Warp captures each call's kernels as a CUDA
  graph and replays it while the buffers stay where they are) measured fastest on an
  H100 (benchmarks/warp_profile.py compares the graph modes). Hence the
  refilled pool runs as one device program per run (``mjx_backend.make_pool``): with
  a device call per refill round it lost ~70 ms per call and ran out of memory at
  32,768 slots (likely re-captured graphs, which Warp caches with their scratch).

Requirements: warp-lang at mujoco-mjx's own pin (``pip install ".[gpu]"``) and a CUDA
GPU that both JAX and Warp see. ``MJX_PICK_WARP_CPU=1`` lets Warp run on the CPU
instead (LLVM-compiled kernels; slow; for development and tests only).

Importing this module imports neither warp nor ``mujoco.mjx`` (``backend='auto'`` asks
:func:`warp_problem` on every machine); :class:`WarpBackend`, which needs both, is
built on first access.
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import logging
import math
import time

import jax
import mujoco
import mujoco.batch
import numpy as np

from mjx_pick.core import cache
from mjx_pick.core.config import ConfigError, to_dict
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine.backend import PickInputs
from mjx_pick.engine.c_backend import MujocoBackend
from mjx_pick.engine.devices import nvidia_gpus, warp_problem

INSTALL_HINT = (
    'pip install ".[gpu]" (CUDA 13; on CUDA 12 drivers, warp-lang 1.18\'s cu12 wheel from '
    "NVIDIA's release page)"
)
GRAPH_MODES = ("WARP", "WARP_STAGED", "WARP_STAGED_EX", "JAX", "NONE")
# a run whose buffers overflowed is re-simulated with doubled buffers this many times
MAX_GROWTH = 3
# buffer margin over the largest counts measured on the sample (see size_buffers)
CONTACT_MARGIN = 1.5
CONTACT_SLACK = 4
# rows x2: Warp's convex collider makes more constraint rows per world than the C
# engine's sample shows (condim-4 pads), so rows get a wider margin than contacts
ROW_MARGIN = 2.0
ROW_SLACK = 16

log = logging.getLogger(__name__)


class BufferOverflowError(RuntimeError):
    """Warp's contact or constraint buffers overflowed even after growing them."""


def check_warp() -> None:
    """Raise a ConfigError naming the extra to install when Warp cannot run here."""
    problem = warp_problem()
    if problem:
        raise ConfigError(
            f"backend = 'warp' needs an NVIDIA GPU and warp-lang: {problem}. Install the GPU "
            f"extra: {INSTALL_HINT}; or choose backend 'mjx' (MJX's JAX physics) or "
            "'mujoco' (the C engine on CPU threads)"
        )


# --------------------------------------------------------------------------- buffers
@dataclasses.dataclass(frozen=True)
class BufferSizes:
    """Warp's preallocated buffers, per simulation.

    contacts: contacts per simulation; a call of n simulations gets ``naconmax =
    contacts * n`` (Warp's contact buffer is shared by all simulations of a call, so a
    simulation may use more than its share while others use less). rows: constraint
    rows per simulation (``njmax``; a hard limit for each simulation). measured_*: the
    largest counts seen when sizing (None: sizes given by hand).
    """

    contacts: int
    rows: int
    measured_contacts: int | None = None
    measured_rows: int | None = None
    sample: int = 0

    def __post_init__(self):
        for name in ("contacts", "rows"):
            v = getattr(self, name)
            if not isinstance(v, int | np.integer) or v < 1:
                raise ConfigError(f"buffers.{name} = {v!r} must be an integer >= 1")

    def naconmax(self, n_worlds: int) -> int:
        return int(self.contacts) * int(n_worlds)

    def grown(self, contacts: bool, rows: bool) -> BufferSizes:
        """Doubled where an overflow was seen."""
        return dataclasses.replace(
            self,
            contacts=self.contacts * (2 if contacts else 1),
            rows=self.rows * (2 if rows else 1),
        )


def buffer_margin(measured_contacts: int, measured_rows: int) -> tuple[int, int]:
    """Buffer sizes from the largest measured counts: contacts x1.5 + 4, rows x2 + 16,
    rounded up to a multiple of 4 (contacts) and 8 (rows).

    Why a margin: the sample does not hold every pick-point, per-pick contact settings
    (a friction sweep) move contacts a little, and Warp's collision functions need not
    return as many contacts per geom pair as MuJoCo C's (box-box, convex-convex with
    multi-contact): Warp makes more constraint rows per world than C's sample shows
    (contacts are pooled over all worlds, so their margin matters less). Too large
    costs time (Warp launches some kernels over every row); too small costs a re-run,
    never a wrong result (overflow is detected).
    """

    def up(x: float, q: int) -> int:
        return int(math.ceil(x / q) * q)

    contacts = up(CONTACT_MARGIN * measured_contacts + CONTACT_SLACK, 4)
    rows = up(ROW_MARGIN * measured_rows + ROW_SLACK, 8)
    return max(contacts, 4), max(rows, 8)


class _CountingBatch:
    """A mujoco.batch.Batch that records, per simulation, the most contacts (ncon) and
    constraint rows (nefc) of any physics step. Steps one substep at a time, since a
    batch reports derived fields of the last substep of a call only."""

    def __init__(self, batch: mujoco.batch.Batch):
        self._b = batch
        self._ncon = batch.bind("ncon")
        self._nefc = batch.bind("nefc")
        self.max_ncon = np.zeros(batch.nsim, np.int64)
        self.max_nefc = np.zeros(batch.nsim, np.int64)

    def __getattr__(self, name):
        return getattr(self._b, name)

    def step(self, ids=None, nstep: int = 1, stage: int = 0) -> None:
        ids = np.arange(self._b.nsim) if ids is None else np.asarray(ids)
        failed: list[np.ndarray] = []
        for _ in range(nstep):
            if not len(ids):
                break
            try:
                self._b.step(ids=ids, nstep=1, stage=stage)
            except mujoco.batch.SimulationError as err:
                # as one call of nstep substeps would: the failed ones stop, the rest go on
                failed.append(np.asarray(err.ids))
                ids = np.setdiff1d(ids, err.ids)
            np.maximum.at(self.max_ncon, ids, self._ncon[ids])
            np.maximum.at(self.max_nefc, ids, self._nefc[ids])
        if failed:
            bad = np.unique(np.concatenate(failed))
            raise mujoco.batch.SimulationError(bad, "error while sizing buffers")


class _SizingBackend(MujocoBackend):
    """The C backend (same controller, same procedure) with counting batches."""

    def _batch(self, n: int):
        if n not in self._batches:
            model = copy.copy(self.scene.model)
            model.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_AUTORESET)
            b = mujoco.batch.Batch(model, nsim=n, nthread=self.nthread)
            self._batches[n] = _CountingBatch(b)
        return self._batches[n]


def measure_buffers(
    scene: Scene, grasp: GraspConfig, inputs: PickInputs, nthread: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Simulate inputs on the MuJoCo C engine (the project's procedure, to the end of
    each pick) and return, per pick, the most contacts and constraint rows of any
    physics step: (ncon (N,), nefc (N,)), ints."""
    backend = _SizingBackend(scene, grasp, max(len(inputs), 1), nthread=nthread)
    backend.run(inputs)
    (counting,) = backend._batches.values()
    return counting.max_ncon[: len(inputs)].copy(), counting.max_nefc[: len(inputs)].copy()


def size_buffers(
    scene: Scene,
    grasp: GraspConfig,
    inputs: PickInputs | None = None,
    n_sample: int = 32,
    seed: int = 0,
    nthread: int | None = None,
) -> BufferSizes:
    """Warp buffer sizes for a scene, by measurement on the MuJoCo C engine (CPU).

    inputs: pick-points to measure (default: n_sample feasible pick-points of the
    scene's object and gripper, generated with seed, at the scene's contact settings).
    Returns the largest per-step counts seen with :func:`buffer_margin`'s margin. Costs
    about n_sample full picks on the CPU (seconds); the default sample's counts are a
    pure function of the model, the procedure and the sample, so they are kept in the
    cache (``mjx_pick.core.cache``) and a later run of the same scene reads them back.
    """
    if inputs is None:
        if n_sample < 1:
            raise ConfigError(f"n_sample = {n_sample} must be >= 1")
        key = {
            "scene_sha256": cache.digest(scene.portable_xml()),
            "silhouette_sha256": cache.digest(scene.object.polygon.wkb),
            "grasp": to_dict(grasp),
            "n_sample": int(n_sample),
            "seed": int(seed),
            "mujoco": mujoco.__version__,
        }

        def measure() -> dict:
            log.info("sizing Warp's buffers on %d pick-points on the C engine ...", n_sample)
            sample = _sample_inputs(scene, grasp, n_sample, seed)
            ncon, nefc = measure_buffers(scene, grasp, sample, nthread=nthread)
            return {"contacts": ncon.max(), "rows": nefc.max(), "sample": len(sample)}

        counts = cache.memo("warp_buffers", key, measure)
        mc, mr, n = (int(counts[k]) for k in ("contacts", "rows", "sample"))
    else:
        ncon, nefc = measure_buffers(scene, grasp, inputs, nthread=nthread)
        mc, mr, n = int(ncon.max()), int(nefc.max()), len(inputs)
    contacts, rows = buffer_margin(mc, mr)
    return BufferSizes(contacts, rows, mc, mr, n)


def _sample_inputs(scene: Scene, grasp: GraspConfig, n: int, seed: int) -> PickInputs:
    """n feasible pick-points of the scene's object and gripper (seed), as inputs."""
    from mjx_pick.core import pickpoints as pp
    from mjx_pick.engine.backend import make_inputs

    picks = pp.generate_normal(scene.object, scene.gripper, n, seed=seed, grasp=grasp)
    if not len(picks):
        raise ConfigError("no feasible pick-point to size Warp's buffers with")
    return make_inputs(scene, grasp, picks)


# --------------------------------------------------------------------------- backend
def _overflow_types():
    from mujoco.mjx.third_party.mujoco_warp._src.types import OverflowType

    return OverflowType


def overflow_masks() -> tuple[int, int]:
    """(contact bits, row bits) of Warp's OverflowType that mean a dropped contact or
    constraint row. The solver's iteration-limit bits are not buffer overflows."""
    t = _overflow_types()
    contacts = t.BROADPHASE | t.NARROWPHASE | t.CCD | t.EPA_HORIZON
    rows = t.NEFC | t.NJMAX_NNZ
    return int(contacts), int(rows)


def describe_overflow(bits: int) -> str:
    t = _overflow_types()
    return "|".join(f.name for f in t if f.value and f.value & bits and f != t.ALL) or "none"


@functools.cache
def keep_xla_stream_registrations() -> None:
    """Make a ``wp.Stream`` that wraps a CUDA stream it does not own leave that stream
    registered with Warp when the wrapper is freed (owned streams are destroyed as before).

    Warp's JAX FFI wraps XLA's stream in a new ``wp.Stream`` on each call it captures,
    and Warp's registry of streams is keyed by the raw handle without a count: freeing
    ANY wrapper unregisters the handle. A wrapper of an earlier call that Python's cyclic
    garbage collector frees while a newer wrapper of the same stream begins its graph
    capture leaves that capture on an "unknown stream", and the whole program fails --
    seen with programs that carry model fields, in every process after the first on a
    machine (benchmarks/warp_stream_repro.py reproduces it; with this, or with the
    collector off, it runs). XLA's streams live as long as the process, so keeping them
    registered costs one CUDA event per graph capture. Idempotent."""
    import warp as wp

    if getattr(wp.Stream.__del__, "keeps_foreign_streams", False):
        return
    free = wp.Stream.__del__

    def __del__(stream) -> None:
        if stream.owner:
            free(stream)

    __del__.keeps_foreign_streams = True
    wp.Stream.__del__ = __del__


def _warp_backend_class():
    from mjx_pick.engine.mjx_backend import (
        DEFAULT_SHRINK_LEVELS,
        DEFAULT_TICKS_PER_CALL,
        MjxBackend,
        Physics,
    )

    class WarpBackend(MjxBackend):
        """The MJX backend with ``impl='warp'``; refills its slots by default.

        buffers: Warp's buffer sizes (default: :func:`size_buffers` on the scene, measured
        when the backend is built). devices: one device (default: the first CUDA GPU;
        :func:`make_warp_backend` runs several GPUs). graph_mode: one of GRAPH_MODES (default
        'WARP' on a GPU, 'JAX' on the CPU, MJX's own defaults).
        """

        name = "warp"
        impl = "warp"

        def __init__(
            self,
            scene: Scene,
            grasp: GraspConfig,
            batch_size: int,
            devices=None,
            refill: bool = True,
            ticks_per_call: int = DEFAULT_TICKS_PER_CALL,
            shrink_levels: int = DEFAULT_SHRINK_LEVELS,
            buffers: BufferSizes | None = None,
            graph_mode: str | None = None,
        ):
            check_warp()
            keep_xla_stream_registrations()
            if graph_mode is not None and graph_mode not in GRAPH_MODES:
                raise ConfigError(f"graph_mode = {graph_mode!r} is not one of {GRAPH_MODES}")
            if devices is None:
                devices = (nvidia_gpus() or jax.devices("cpu"))[:1]
            if len(devices) != 1:
                # several GPUs: make_warp_backend gives each its own WarpBackend
                raise ConfigError(
                    f"WarpBackend runs on one device; got {len(devices)}: use make_warp_backend"
                )
            super().__init__(
                scene, grasp, batch_size, devices, refill, ticks_per_call, shrink_levels
            )
            self.graph_mode = graph_mode
            self._model = None  # the model on the device, made once (physics)
            if buffers is None:
                t0 = time.perf_counter()
                buffers = size_buffers(scene, grasp)
                self.stats.compile_s += time.perf_counter() - t0  # setup, apart from run time
            self.buffers = buffers
            self.growths = 0  # re-runs after an overflow
            self._contact_mask, self._row_mask = overflow_masks()
            t0 = time.perf_counter()
            self._build_kernels()
            self.stats.compile_s += time.perf_counter() - t0

        def _build_kernels(self) -> None:
            """One physics step of one world, now: Warp builds its CUDA kernels at their
            first launch (over two minutes on a fresh machine, then cached in
            ~/.cache/warp), and that build belongs to compile time, not to the first
            batch's run time (measured on an H100: a first evaluate of 40,000 door-opener
            pick-points reported 257/s, the second 2,388/s)."""
            from mujoco import mjx

            phys = self.physics(1)
            jax.block_until_ready(jax.jit(mjx.step)(phys.model, phys.data0))

        def program_identity(self) -> tuple:
            """As MjxBackend's, with the buffer sizes and the graph mode."""
            return (*super().program_identity(), repr(self.buffers), self.graph_mode)

        def physics(self, n_worlds: int) -> Physics:
            from mujoco import mjx
            from mujoco.mjx.warp import types as mjxw_types

            device = self.devices[0]
            if self._model is None:  # one transfer of the model: every pool size shares it
                mode = self.graph_mode or ("JAX" if device.platform == "cpu" else "WARP")
                mx = mjx.put_model(
                    self.scene.model,
                    impl="warp",
                    device=device,
                    graph_mode=getattr(mjxw_types.GraphMode, mode),
                )
                # cfrc_ext (the pad forces) needs the post-constraint RNE pass; Warp's
                # printed overflow warnings are replaced by the overflow check after each run
                opt = mx.opt._impl.replace(run_rne_postconstraint=True, warn_overflow=0)
                self._model = mx.replace(opt=mx.opt.replace(_impl=opt))
            mx = self._model
            d0 = mjx.make_data(
                self.scene.model,
                impl="warp",
                device=device,
                naconmax=self.buffers.naconmax(n_worlds),
                njmax=int(self.buffers.rows),
            )
            mask = self._contact_mask | self._row_mask
            return Physics(
                mx,
                d0,
                "warp",
                overflow=lambda d: d._impl.overflow & mask,
                nefc=lambda d: d._impl.nefc,
                nacon=lambda d: d._impl.nacon[0],
            )

        def run(self, inputs: PickInputs, record: bool = False):
            """As MjxBackend.run; picks whose buffers overflowed are re-simulated with
            doubled buffers (a new compile), MAX_GROWTH times at most over the backend's
            life, then BufferOverflowError."""
            merged, traces = super().run(inputs, record)
            diag = self.last_diagnostics
            todo = np.flatnonzero(diag.overflow != 0)
            while len(todo):
                seen = int(np.bitwise_or.reduce(diag.overflow[todo]))
                if self.growths >= MAX_GROWTH:
                    raise BufferOverflowError(
                        f"Warp's buffers overflowed ({describe_overflow(seen)}) in {len(todo)} of "
                        f"{len(inputs)} pick-points even at {self.buffers.contacts} contacts and "
                        f"{self.buffers.rows} constraint rows per simulation; pass larger "
                        "BufferSizes (make_backend(..., buffers=...)) or use backend 'mujoco'"
                    )
                self.buffers = self.buffers.grown(
                    contacts=bool(seen & self._contact_mask), rows=bool(seen & self._row_mask)
                )
                self.growths += 1
                log.warning(
                    "Warp buffer overflow (%s) in %d pick-points: re-simulating them with %d "
                    "contacts and %d constraint rows per simulation",
                    describe_overflow(seen),
                    len(todo),
                    self.buffers.contacts,
                    self.buffers.rows,
                )
                self._compiled.clear()  # programs of the old sizes
                self.stats.n -= len(todo)  # counted again by the re-run
                out, rows = super().run(inputs.take(todo), record)
                sub = self.last_diagnostics
                for k in merged:
                    merged[k][todo] = out[k]
                if record:
                    traces[todo] = rows
                for f in diag._fields:
                    getattr(diag, f)[todo] = getattr(sub, f)
                todo = todo[sub.overflow != 0]
            self.last_diagnostics = diag
            return merged, traces

    return WarpBackend


def make_warp_backend(scene: Scene, grasp: GraspConfig, batch_size: int, devices=None, **options):
    """The Warp backend on `devices` (default: every CUDA GPU JAX sees; the CPU with
    MJX_PICK_WARP_CPU=1 and no GPU). One device: a WarpBackend with batch_size slots.
    Several: one WarpBackend per device with batch_size / n slots each, run side by side
    (``mjx_backend._DeviceThreads``: contiguous shares of the pick-points, nothing
    communicated); their buffers are sized once, on the C engine, for all."""
    check_warp()
    if devices is None:
        devices = nvidia_gpus() or jax.devices("cpu")[:1]
    devices = list(devices)
    if not devices:
        raise ConfigError("backend 'warp': no device given")
    WarpBackend = _warp_backend_class()
    if len(devices) == 1:
        return WarpBackend(scene, grasp, batch_size, devices=devices, **options)
    from mjx_pick.engine.mjx_backend import _DeviceThreads

    if options.get("buffers") is None:
        options["buffers"] = size_buffers(scene, grasp)
    per_device = -(-int(batch_size) // len(devices))
    return _DeviceThreads(
        [WarpBackend(scene, grasp, per_device, devices=[d], **options) for d in devices]
    )


def __getattr__(name: str):
    # PEP 562: WarpBackend subclasses MjxBackend, whose module imports mujoco.mjx (and
    # through it warp); build it only when asked for
    if name == "WarpBackend":
        return _warp_backend_class()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
