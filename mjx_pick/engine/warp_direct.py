"""MuJoCo Warp backend: the whole rollout on NVIDIA GPUs as Warp kernels and CUDA graphs.

The ``mujoco-warp`` package is the engine; no JAX is in this path. A pool of slots steps
together; one control period (every slot's controller tick, then the physics steps) is
captured once as a CUDA graph with MuJoCo Warp's graph conditionals; between rounds of
periods the host hands slots whose pick ended the next pick-points (a reset, the pick's
rows written, a forward pass), and in a run's tail moves the live slots into a pool half
the size. A pick's result depends on its pick-point alone. docs/gpu.md describes it.
With ``MJX_PICK_WARP_CPU=1`` the same code runs on Warp's CPU device (for tests).
"""

from __future__ import annotations

import contextlib
import dataclasses
import logging
import os
import threading
import time

import mujoco
import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import devices
from mjx_pick.engine.backend import PickInputs, RunStats, addresses
from mjx_pick.engine.pool import (
    DEFAULT_SHRINK_LEVELS,
    SHRINK_MIN_SLOTS,
    DeviceThreads,
    Diagnostics,
    PoolStats,
    shrink_sizes,
)
from mjx_pick.engine.registry import Impl
from mjx_pick.engine.warp_buffers import BufferSizes, rerun_overflowed, size_buffers
from mjx_pick.kernels import types as kt

log = logging.getLogger(__name__)

ALLOW_CPU_ENV = devices.ALLOW_CPU_ENV
INSTALL_HINT = 'pip install ".[gpu]" (warp-lang and mujoco-warp, CUDA 13)'
# control periods per refill round: a finished slot idles up to this many periods before
# it takes the next pick, against one host synchronisation per round
DEFAULT_TICKS_PER_CALL = 10
# small runs use a smaller pool, a multiple of this many slots
POOL_QUANTUM = 256
# a long run's chunks hold this many pools' worth of pick-points (runner.auto_chunk)
CHUNK_POOLS = 2
RESULT_FIELDS = kt.RESULT_FIELDS


def warp_problem(allow_cpu: bool | None = None) -> str | None:
    """Why this backend cannot run here, or None. Imports warp only where an NVIDIA
    driver is installed (or the CPU is allowed), so asking on a CPU machine is quiet."""
    import importlib.util

    if allow_cpu is None:
        allow_cpu = os.environ.get(ALLOW_CPU_ENV, "") == "1"
    if not allow_cpu and not devices.nvidia_driver_present():
        return "no NVIDIA driver found"
    for module, package in (("warp", "warp-lang"), ("mujoco_warp", "mujoco-warp")):
        if importlib.util.find_spec(module) is None:
            return f"{package} is not installed"
    try:
        wp = devices.warp()
        if not allow_cpu and wp.get_cuda_device_count() < 1:
            return "warp-lang sees no CUDA device (driver too old for its CUDA build?)"
    except Exception as err:  # any failure to load warp's native library
        return f"warp-lang does not load: {type(err).__name__}: {err}"
    return None


def check_warp() -> None:
    """Raise a ConfigError naming what to install when this backend cannot run here."""
    problem = warp_problem()
    if problem:
        raise ConfigError(
            f"backend = 'warp' needs an NVIDIA GPU, warp-lang and mujoco-warp: {problem}. "
            f"Install the GPU extra: {INSTALL_HINT}; or choose backend 'mujoco' (the C "
            "engine on CPU threads)"
        )


# Warp's current device is one for the whole process (wp.ScopedDevice sets it for every
# thread): backends on several devices take turns at this lock for each stretch of Warp
# calls, and wait for their device outside it
_WARP_LOCK = threading.RLock()


@contextlib.contextmanager
def on_device(name: str):
    """Warp calls on device `name`, from any thread (see _WARP_LOCK)."""
    wp = devices.warp()
    with _WARP_LOCK, wp.ScopedDevice(name):
        yield


def cuda_devices() -> list[str]:
    """Warp's CUDA devices ('cuda:0', ...)."""
    wp = devices.warp()
    return [f"cuda:{i}" for i in range(wp.get_cuda_device_count())]


def default_devices() -> list[str]:
    """Every CUDA device, or the CPU when allowed and there is none."""
    found = cuda_devices()
    if not found and os.environ.get(ALLOW_CPU_ENV, "") == "1":
        found = ["cpu"]
    return found


def batched_model_fields() -> frozenset[str]:
    """MjModel fields that MuJoCo Warp's model can hold per world (its '*' arrays), as
    MuJoCo names them; options as ``opt.<name>`` (impratio via impratio_invsqrt)."""
    from mujoco_warp._src import types as mjw_types

    def batched(cls) -> set[str]:
        out = set()
        for f in dataclasses.fields(cls):
            shape = getattr(f.type, "shape", None)
            if shape and shape[0] == "*":
                out.add(f.name)
        return out

    fields = batched(mjw_types.Model)
    options = {f"opt.{name}" for name in batched(mjw_types.Option)}
    if "opt.impratio_invsqrt" in options:
        options.add("opt.impratio")
    return frozenset(fields | options)


def model_fields(fields: frozenset[str]) -> frozenset[str]:
    """Of the MjModel fields ``fields`` (``engine.variants``), those this backend takes
    per simulation: Warp holds them per world, or does not read them at all."""
    from mujoco_warp._src import types as mjw_types

    held = {f.name for f in dataclasses.fields(mjw_types.Model)}
    per_world = batched_model_fields()
    return frozenset(
        f for f in fields if f in per_world or (not f.startswith("opt.") and f not in held)
    )


def carried_fields() -> frozenset[str]:
    """The model fields this backend takes per simulation (``engine.variants``)."""
    from mjx_pick.engine import variants

    return variants.carried_fields(Impl.WARP)


# ------------------------------------------------------------------- the device program
def _kernels():
    """The backend's Warp kernels (``engine.warp_kernels``, imported on first use:
    importing this module imports neither warp nor mujoco_warp)."""
    devices.warp()
    from mjx_pick.engine import warp_kernels

    return warp_kernels


def _world_bytes(arr):
    """A contiguous per-world Warp array (worlds first) seen as (worlds, bytes a world)
    uint8, the same memory: what ``warp_kernels.gather_bytes`` moves."""
    wp = devices.warp()
    if not arr.is_contiguous:
        raise ValueError(f"a per-world array of shape {arr.shape} is not contiguous")
    row = arr.size // arr.shape[0] * wp.types.type_size_in_bytes(arr.dtype)
    return wp.array(ptr=arr.ptr, dtype=wp.uint8, shape=(arr.shape[0], row), device=arr.device)


def _put_model(mjm, slots: int, fields: tuple[str, ...], deterministic: bool):
    """The scene's model on the current Warp device with a row per slot for the contact
    pair values and each carried field (an ``opt.*`` field: one value per slot)."""
    import mujoco_warp as mjw

    wp = devices.warp()
    batch = {name: slots for name in ("pair_friction", "pair_solref", "pair_solimp")}
    for name in fields:
        if not name.startswith("opt."):
            batch[name] = slots
    m = mjw.put_model(mjm, batch_sizes=batch)
    for name in fields:
        if name.startswith("opt."):
            attr = "impratio_invsqrt" if name == "opt.impratio" else name[4:]
            one = getattr(m.opt, attr).numpy()
            setattr(m.opt, attr, wp.array(np.repeat(one[:1], slots), dtype=float))
    m.opt.run_rne_postconstraint = True  # cfrc_ext: the pad forces
    m.opt.warn_overflow = 0  # read back per pick instead
    m.opt.graph_conditional = wp.get_device().is_cuda
    if deterministic:
        from mujoco_warp._src.types import DeterminismType

        m.opt.deterministic = DeterminismType.ALL
    return m


class _Pool:
    """One pool of slots on one device: the model with its batched rows, the data, the
    slots' controller state and the captured control period."""

    def __init__(self, backend: WarpBackend, slots: int, record_ticks: int):
        import mujoco_warp as mjw

        wp = devices.warp()
        from mjx_pick.kernels import grasp_warp as gw

        self.slots = slots
        self.record_ticks = record_ticks
        self.device_name = dev = backend.device_name
        scene = backend.scene
        mjm = scene.model
        self.fields = backend.fields  # per-pick model fields this pool carries
        with on_device(dev):
            self.m = _put_model(mjm, slots, self.fields, backend.deterministic)
            self.buffers = backend.buffers
            self.d = mjw.make_data(
                mjm,
                nworld=slots,
                naconmax=backend.buffers.naconmax(slots),
                njmax=int(backend.buffers.rows),
            )
            S = slots
            self.params = wp.zeros(S, dtype=gw.Params)
            self.ctl = wp.zeros(S, dtype=gw.Control)
            self.acc = wp.zeros(S, dtype=gw.Acc)
            self.pos0 = wp.zeros(S, dtype=wp.vec3)
            self.quat0 = wp.zeros(S, dtype=wp.vec4)
            self.k = wp.full(S, backend.n_ticks, dtype=int)  # empty slots count as ended
            self.live = wp.zeros(S, dtype=int)
            self.nefc_max = wp.zeros(S, dtype=int)
            self.nacon_max = wp.zeros(S, dtype=int)
            self.slot_pick = wp.full(S, -1, dtype=int)
            self.fresh = wp.zeros(S, dtype=int)
            self.ended = wp.zeros(S, dtype=int)
            self.ended_host = wp.zeros(S, dtype=int, device="cpu", pinned=wp.get_device().is_cuda)
            self.saved_cfrc = wp.zeros_like(self.d.cfrc_ext)
            self.niter_hist = wp.zeros(int(mjm.opt.iterations) + 1, dtype=int)
            self.niter_step_max = wp.zeros(1, dtype=int)
            self.steps = wp.zeros(2, dtype=int)
            shape = (S, max(record_ticks, 1), gw.NTRACE) if record_ticks else (1, 1, gw.NTRACE)
            self.trace = wp.zeros(shape, dtype=float)
            self.ad = gw.addresses(backend.ad)
            self.drive = gw.drive(backend.ad, dev)
            self.graph = None

    def counters(self) -> np.ndarray:
        """(steps, steps in which every live world converged, iteration histogram...)
        so far, int64 (differences of two readings count a run)."""
        return np.concatenate([self.steps.numpy(), self.niter_hist.numpy()]).astype(np.int64)

    # the data a world carries from one physics step to the next (MuJoCo's integration
    # state) and the external forces its next tick measures; everything else a step
    # recomputes
    STATE = (
        "time",
        "qpos",
        "qvel",
        "act",
        "history",
        "plastic",
        "qacc_warmstart",
        "ctrl",
        "qfrc_applied",
        "xfrc_applied",
        "eq_active",
        "mocap_pos",
        "mocap_quat",
        "userdata",
        "cfrc_ext",
        "overflow",
    )
    SLOT = ("params", "ctl", "acc", "pos0", "quat0", "k", "nefc_max", "nacon_max")

    def state_arrays(self) -> list:
        """Every per-world array a pick needs to run on in another pool: its data's
        state, its model rows and its controller's state, in a fixed order."""
        arrays = [getattr(self.d, name) for name in self.STATE if hasattr(self.d, name)]
        arrays += [self.m.pair_friction, self.m.pair_solref, self.m.pair_solimp]
        arrays += [self.field_view(name) for name in self.fields]
        arrays += [getattr(self, name) for name in self.SLOT]
        return [a for a in arrays if a.size > 0]

    def field_view(self, name: str):
        """The model's (slots, K) float rows of a carried field."""
        if name.startswith("opt."):
            attr = "impratio_invsqrt" if name == "opt.impratio" else name[4:]
            arr = getattr(self.m.opt, attr)
        else:
            arr = getattr(self.m, name)
        return arr.view(float).reshape((self.slots, -1))

    def period(self, backend: WarpBackend) -> None:
        """One control period: the tick, then n_substeps physics steps."""
        import mujoco_warp as mjw

        wp = devices.warp()
        kern = _kernels()
        d = self.d
        wp.launch(
            kern.tick,
            dim=self.slots,
            inputs=[
                self.ad,
                self.drive,
                backend.n_ticks,
                int(self.record_ticks > 0),
                self.params,
                self.ctl,
                self.acc,
                self.pos0,
                self.quat0,
                self.k,
                self.live,
                d.qpos,
                d.qvel,
                d.cfrc_ext,
                d.ctrl,
                self.trace,
            ],
        )
        for _ in range(backend.n_sub):
            mjw.step(self.m, d)
            wp.launch(
                kern.buffer_use,
                dim=self.slots,
                inputs=[
                    self.live,
                    d.nefc,
                    d.nacon,
                    d.solver_niter,
                    self.nefc_max,
                    self.nacon_max,
                    self.niter_hist,
                    self.niter_step_max,
                ],
            )
            wp.launch(
                kern.step_done,
                dim=1,
                inputs=[int(self.m.opt.iterations), self.niter_step_max, self.steps],
            )

    def capture(self, backend: WarpBackend) -> None:
        """The control period as one CUDA graph (on a GPU; the CPU runs it eagerly)."""
        wp = devices.warp()
        if self.graph is not None or not wp.get_device(backend.device_name).is_cuda:
            return
        with on_device(backend.device_name):
            # one eager period first: Warp builds (or loads) every kernel outside the capture
            t0 = time.perf_counter()
            self.period(backend)
            wp.synchronize_device()
            backend._setup("kernels", t0)
            t0 = time.perf_counter()
            with wp.ScopedCapture() as capture:
                self.period(backend)
            self.graph = capture.graph
            backend._setup("graph", t0)

    def run_period(self, backend: WarpBackend) -> None:
        wp = devices.warp()
        if self.graph is not None:
            wp.capture_launch(self.graph)
        else:
            self.period(backend)


class _Outputs:
    """Per-pick rows a run fills as its picks end (on the current device)."""

    def __init__(self, n: int):
        wp = devices.warp()
        from mjx_pick.kernels import grasp_warp as gw

        self.acc = wp.zeros(n, dtype=gw.Acc)
        self.k = wp.zeros(n, dtype=int)
        self.phase = wp.zeros(n, dtype=int)
        self.overflow = wp.zeros(n, dtype=int)
        self.nefc = wp.zeros(n, dtype=int)
        self.nacon = wp.zeros(n, dtype=int)


class WarpBackend:
    """The MuJoCo Warp backend on one device (see the module docstring).

    Args:
      scene, grasp: what to simulate.
      batch_size: slots of the refilled pool (a run of fewer picks uses a smaller one).
      device: a Warp device name ('cuda:0'; default: the first CUDA device, or the CPU
        with MJX_PICK_WARP_CPU=1).
      ticks_per_call: control periods per refill round.
      shrink_levels: halvings of the pool in a run's tail (``engine.pool``), never below
        ``shrink_min_slots`` slots.
      buffers: Warp's buffer sizes (default: ``warp_buffers.size_buffers`` of the scene).
      deterministic: MuJoCo Warp's deterministic mode (stable contact and constraint
        order, order-invariant sums): the same results on every run on one device.
    """

    name = str(Impl.WARP)
    refill = True  # a pool of slots refilled as picks end (what reports call it)

    def __init__(
        self,
        scene: Scene,
        grasp: GraspConfig,
        batch_size: int,
        device: str | None = None,
        ticks_per_call: int = DEFAULT_TICKS_PER_CALL,
        buffers: BufferSizes | None = None,
        deterministic: bool = False,
        shrink_levels: int = DEFAULT_SHRINK_LEVELS,
        shrink_min_slots: int = SHRINK_MIN_SLOTS,
    ):
        check_warp()
        if int(shrink_levels) < 0 or int(shrink_min_slots) < 1:
            raise ConfigError(
                f"shrink_levels = {shrink_levels} must be >= 0 and shrink_min_slots = "
                f"{shrink_min_slots} >= 1"
            )
        if int(ticks_per_call) < 1:
            raise ConfigError(f"ticks_per_call = {ticks_per_call} must be >= 1")
        if int(batch_size) < 1:
            raise ConfigError(f"batch_size = {batch_size} must be >= 1")
        self.scene, self.grasp = scene, grasp
        self.n_sub = grasp.substeps(scene.solver)  # validates the control period
        self.n_ticks = grasp.n_ticks()
        self.ad = addresses(scene)
        wp = devices.warp()
        self.device_name = device or default_devices()[0]
        dev = wp.get_device(self.device_name)
        self.device = f"{'gpu' if dev.is_cuda else 'cpu'}:{dev.name}"
        self.batch_size = int(batch_size)
        self.ticks_per_call = int(ticks_per_call)
        self.shrink_levels = int(shrink_levels)
        self.shrink_min_slots = int(shrink_min_slots)
        self.deterministic = bool(deterministic)
        self.stats = RunStats()
        self.pool_stats = PoolStats()
        self.last_diagnostics: Diagnostics | None = None
        self.growths = 0
        # setup seconds by stage (buffers, model and data, kernels, graph): compile time
        self.setup_s: dict[str, float] = {}
        t0 = time.perf_counter()
        self.buffers = buffers or size_buffers(scene, grasp)
        self._setup("buffers", t0)
        self.fields: tuple[str, ...] = ()
        self._pools: dict[tuple, _Pool] = {}
        self._masks = _overflow_masks()

    def _setup(self, stage: str, t0: float) -> None:
        """Counts the time since t0 as setup (compile time) of the stage."""
        dt = time.perf_counter() - t0
        self.setup_s[stage] = self.setup_s.get(stage, 0.0) + dt
        self.stats.compile_s += dt

    def peak_device_bytes(self) -> int | None:
        """The most device memory Warp's memory pool has held on this device (None on
        the CPU)."""
        wp = devices.warp()
        dev = wp.get_device(self.device_name)
        if not dev.is_cuda or not wp.is_mempool_enabled(dev):
            return None
        return int(wp.get_mempool_used_mem_high(dev))

    # --- sizes
    def preferred_chunk(self) -> int:
        """Pick-points per chunk of a long run: two pools' worth, so that a chunk's tail
        (its pool draining) is a small part of it."""
        return CHUNK_POOLS * self.batch_size

    def pool_size(self, n: int) -> int:
        """Slots for a run of n picks: the batch size, or fewer for a small run."""
        q = POOL_QUANTUM
        return max(1, min(self.batch_size, -(-max(n, 1) // q) * q))

    def _pool(self, slots: int, record_ticks: int, family: tuple[int, ...] = ()) -> _Pool:
        """The pool of `slots` slots (built and captured on first use). The backend keeps
        the pools of one run's sizes (family: the tail's sizes) and of its last record
        run: a pool holds its data on the device."""
        key = (slots, record_ticks, self.fields, repr(self.buffers))
        pool = self._pools.get(key)
        if pool is None:
            keep = set(family) | {slots}
            for old in [k for k in self._pools if k[1] == record_ticks and k[0] not in keep]:
                del self._pools[old]
            t0 = time.perf_counter()
            pool = _Pool(self, slots, record_ticks)
            self._setup("model_and_data", t0)
            pool.capture(self)
            self._pools[key] = pool
        return pool

    # --- running
    def run(self, inputs: PickInputs, record: bool = False):
        """Simulate all inputs; returns (results dict of (N,) arrays, traces (N, T, F) or
        None). Picks whose buffers overflowed are re-simulated with doubled buffers
        (``warp_buffers.rerun_overflowed``)."""
        n = len(inputs)
        if n == 0:
            empty = _typed({name: np.zeros(0) for name in RESULT_FIELDS})
            self.last_diagnostics = Diagnostics(*(np.zeros(0, np.int32) for _ in range(3)))
            return empty, (np.zeros((0, self.n_ticks, len(kt.TRACE_FIELDS))) if record else None)
        first = self._run_once(inputs, record)
        merged, traces, diag = rerun_overflowed(
            self,
            inputs,
            first,
            lambda sub: self._run_once(sub, record),
            self._masks,
            _describe_overflow,
        )
        self.last_diagnostics = diag
        return merged, traces

    def _fields_for(self, inputs: PickInputs) -> tuple[str, ...]:
        fields = tuple(sorted(inputs.model))
        unknown = sorted(set(fields) - carried_fields())
        if unknown:
            raise ConfigError(
                f"backend 'warp' cannot take the model fields {unknown} per simulation"
            )
        return fields

    def _run_once(self, inputs: PickInputs, record: bool):
        """Every pick of inputs through the pool (record: one slot per pick, every
        tick's row kept); (results, traces, Diagnostics) in pick-point order."""
        wp = devices.warp()
        from mjx_pick.kernels import grasp_warp as gw

        n = len(inputs)
        self.fields = self._fields_for(inputs)
        sizes, family = self._pool_family(n, record)
        pools = family[:1]
        t0 = time.perf_counter()
        dev = self.device_name
        with on_device(dev):
            src = _device_inputs(inputs, self.fields, gw)
            out = _Outputs(n)
            pool = pools[0]
            pool.trace.zero_()
            counters0 = [pool.counters()]
            slot_pick = np.full(pool.slots, -1, np.int32)
            first = min(pool.slots, n)
            slot_pick[:first] = np.arange(first)
            self._refill(pool, src, slot_pick, slot_pick >= 0)
        next_pick = first
        slot_ticks = 0
        rounds = 0
        while True:
            with on_device(dev):
                for _ in range(self.ticks_per_call):
                    pool.run_period(self)
                done = self._save_ended(pool, out)
            ended = done()  # waits for the device outside the lock
            rounds += 1
            slot_ticks += pool.slots * self.ticks_per_call
            slot_pick, fresh, next_pick = refill_order(slot_pick, ended, next_pick, n)
            live = slot_pick >= 0
            if not live.any():
                break
            level = len(pools) - 1
            with on_device(dev):
                if fresh.any():
                    self._refill(pool, src, slot_pick, fresh)
                elif next_pick >= n and level + 1 < len(sizes) and live.sum() <= sizes[level + 1]:
                    # the queue is empty and half the pool idles: the live slots move
                    # into a pool half the size
                    small = family[level + 1]
                    slot_pick = self._compact(pool, small, slot_pick)
                    pools.append(small)
                    counters0.append(small.counters())
                    pool = small
                else:
                    pool.slot_pick.assign(slot_pick)
        with on_device(dev):
            wp.synchronize_device()
            counters = [p.counters() - c0 for p, c0 in zip(pools, counters0, strict=True)]
            picks, traces, diag, k = self._read_out(src, out, pool if record else None)
        self.stats.run_s += time.perf_counter() - t0
        self.stats.n += n
        self.pool_stats.add(rounds, slot_ticks, int(k.sum()), n, sum(counters))
        return picks, traces, diag

    def _pool_family(self, n: int, record: bool) -> tuple[tuple[int, ...], list[_Pool]]:
        """The slot counts of a run of n picks and their pools: the first, then each
        level of the tail (record: one pool, a slot per pick). Every pool is built and
        captured before the run, so that its cost counts as setup, not run time."""
        if record:
            sizes = (n,)
        else:
            sizes = shrink_sizes(self.pool_size(n), self.shrink_levels, self.shrink_min_slots)
        return sizes, [self._pool(size, self.n_ticks if record else 0, sizes) for size in sizes]

    def _read_out(self, src: dict, out: _Outputs, recorded: _Pool | None):
        """The run's results from the device: (results, traces or None, Diagnostics,
        (N,) ticks each pick ran) in pick-point order; traces from the recorded pool
        (one slot per pick)."""
        from mjx_pick.kernels import grasp_warp as gw

        n = out.k.shape[0]
        picks = _finalize_device(_kernels(), src, out.acc, gw)
        k = out.k.numpy().copy()
        traces = None
        if recorded is not None:
            trace = recorded.trace.numpy()[:n]
            traces = pad_traces(trace, k, out.phase.numpy().copy(), self.grasp)
        diag = Diagnostics(*(a.numpy().copy() for a in (out.overflow, out.nefc, out.nacon)))
        return picks, traces, diag, k

    def _save_ended(self, pool: _Pool, out: _Outputs):
        """Slots whose pick has ended write it to its row of out. Returns a function
        that waits for the device and gives (S,) bool of them (call it outside
        :func:`on_device`, so other devices' threads run meanwhile)."""
        wp = devices.warp()
        wp.launch(
            _kernels().save,
            dim=pool.slots,
            inputs=[
                self.n_ticks,
                pool.slot_pick,
                pool.ctl,
                pool.acc,
                pool.k,
                pool.d.overflow,
                pool.nefc_max,
                pool.nacon_max,
                pool.ended,
                out.acc,
                out.k,
                out.phase,
                out.overflow,
                out.nefc,
                out.nacon,
            ],
        )
        if not wp.get_device().is_cuda:
            ended = pool.ended.numpy().astype(bool)
            return lambda: ended
        # the flags to pinned host memory, behind the round on the device's stream
        wp.copy(pool.ended_host, pool.ended)
        event = wp.record_event()

        def wait() -> np.ndarray:
            wp.synchronize_event(event)
            return pool.ended_host.numpy().astype(bool)

        return wait

    def _compact(self, big: _Pool, small: _Pool, slot_pick: np.ndarray) -> np.ndarray:
        """The live slots of big (slot order) into the first slots of small: their
        simulation state, model rows and controller state; small's other slots idle.
        Returns small's slot_pick. Every step recomputes the rest of a world's data from
        what is copied, so a pick runs on as if it had stayed where it was."""
        wp = devices.warp()
        live = np.flatnonzero(slot_pick >= 0)
        order = np.full(small.slots, -1, np.int32)
        order[: len(live)] = live
        order_dev = wp.array(order, dtype=int)
        kern = _kernels()
        for src, dst in zip(big.state_arrays(), small.state_arrays(), strict=True):
            dst_bytes = _world_bytes(dst)
            wp.launch(
                kern.gather_bytes,
                dim=dst_bytes.shape,
                inputs=[order_dev, _world_bytes(src), dst_bytes],
            )
        wp.launch(_kernels().idle_slots, dim=small.slots, inputs=[order_dev, self.n_ticks, small.k])
        slot_pick = np.where(order >= 0, slot_pick[np.maximum(order, 0)], -1).astype(np.int32)
        small.slot_pick.assign(slot_pick)
        return slot_pick

    def _refill(self, pool: _Pool, src: dict, slot_pick: np.ndarray, fresh: np.ndarray) -> None:
        """Fresh slots take their picks: reset, inputs written, one forward pass."""
        import mujoco_warp as mjw

        wp = devices.warp()
        kern = _kernels()
        d, m = pool.d, pool.m
        pool.slot_pick.assign(slot_pick)
        pool.fresh.assign(fresh.astype(np.int32))
        mjw.reset_data(m, d, reset=pool.fresh)
        wp.launch(
            kern.start,
            dim=pool.slots,
            inputs=[
                pool.ad,
                pool.drive,
                pool.fresh,
                pool.slot_pick,
                src["qpos0"],
                src["params"],
                src["pair_friction"],
                src["pair_solref"],
                src["pair_solimp"],
                pool.params,
                pool.ctl,
                pool.acc,
                pool.pos0,
                pool.quat0,
                pool.k,
                pool.nefc_max,
                pool.nacon_max,
                d.qpos,
                d.qvel,
                d.ctrl,
                m.pair_friction,
                m.pair_solref,
                m.pair_solimp,
            ],
        )
        for name in pool.fields:
            rows = src["model"][name]
            wp.launch(
                kern.copy_rows,
                dim=(pool.slots, rows.shape[1]),
                inputs=[pool.fresh, pool.slot_pick, rows, pool.field_view(name)],
            )
        self._forward_fresh(pool)

    @staticmethod
    def _forward_fresh(pool: _Pool) -> None:
        """One forward pass of the pool; fresh slots take its contact forces and buffer
        use, the others keep the forces their last step measured."""
        import mujoco_warp as mjw

        wp = devices.warp()
        d = pool.d
        wp.copy(pool.saved_cfrc, d.cfrc_ext)
        mjw.forward(pool.m, d)
        wp.launch(
            _kernels().after_forward,
            dim=(pool.slots, d.cfrc_ext.shape[1]),
            inputs=[
                pool.fresh,
                pool.saved_cfrc,
                d.cfrc_ext,
                d.nefc,
                d.nacon,
                pool.nefc_max,
                pool.nacon_max,
            ],
        )


def refill_order(
    slot_pick: np.ndarray, ended: np.ndarray, next_pick: int, n: int
) -> tuple[np.ndarray, np.ndarray, int]:
    """The pool's bookkeeping after a round: slots whose pick ended take the next picks
    in slot order; the rest of them go idle once the queue is empty.

    Args:
      slot_pick: (S,) int, each slot's pick-point (-1: idle).
      ended: (S,) bool, slots whose pick ended this round (only slots with a pick).
      next_pick: the first pick-point not yet handed out; n: pick-points in all.

    Returns:
      (slot_pick, fresh, next_pick): the new assignment, (S,) bool of slots that start a
      pick, and the next pick-point to hand out.
    """
    slot_pick = np.asarray(slot_pick, np.int32).copy()
    ended = np.asarray(ended, bool) & (slot_pick >= 0)
    take = np.flatnonzero(ended)
    new = next_pick + np.arange(len(take))
    ok = new < n
    slot_pick[take] = np.where(ok, new, -1)
    fresh = np.zeros(len(slot_pick), bool)
    fresh[take[ok]] = True
    return slot_pick, fresh, next_pick + int(ok.sum())


def pad_traces(rows: np.ndarray, ticks: np.ndarray, phase: np.ndarray, grasp: GraspConfig):
    """Traces (N, T, F) with each pick's rows after its end held at its last row, time
    running on and the phase it ended in, as the C backend leaves a finished pick."""
    out = np.array(rows, np.float32, copy=True)
    dt = float(grasp.control_period_s)
    t_col = kt.TRACE_FIELDS.index("t_s")
    phase_col = kt.TRACE_FIELDS.index("phase")
    for i, k in enumerate(np.asarray(ticks)):
        k = int(k)
        if 0 < k < out.shape[1]:
            last = out[i, k - 1]
            out[i, k:] = last
            out[i, k:, t_col] = last[t_col] + dt * np.arange(1, out.shape[1] - k + 1)
            out[i, k:, phase_col] = phase[i]
    return out


def _device_inputs(inputs: PickInputs, fields: tuple[str, ...], gw) -> dict:
    """The picks' inputs as Warp arrays on the current device."""
    wp = devices.warp()
    n = len(inputs)
    return {
        "qpos0": wp.array(np.asarray(inputs.qpos0, np.float32), dtype=float),
        "params": gw.to_struct_array(inputs.params, gw.Params, None),
        "pair_friction": wp.array(np.asarray(inputs.pair_friction, np.float32), dtype=gw.vec5),
        "pair_solref": wp.array(np.asarray(inputs.pair_solref, np.float32), dtype=wp.vec2),
        "pair_solimp": wp.array(np.asarray(inputs.pair_solimp, np.float32), dtype=gw.vec5),
        "model": {
            name: wp.array(
                _warp_values(name, np.asarray(inputs.model[name], np.float64)).reshape(n, -1),
                dtype=float,
            )
            for name in fields
        },
    }


def _warp_values(name: str, values: np.ndarray) -> np.ndarray:
    """A carried field's values as Warp's model holds them (float32; impratio as
    Warp's impratio_invsqrt)."""
    if name == "opt.impratio":
        values = 1.0 / np.sqrt(np.maximum(values, mujoco.mjMINVAL))
    return values.astype(np.float32)


def _finalize_device(kern, src: dict, out_acc, gw) -> dict:
    """Per-pick results (kernels.grasp.finalize's fields) from their accumulators."""
    wp = devices.warp()
    n = out_acc.shape[0]
    res = wp.zeros(n, dtype=gw.Result)
    wp.launch(kern.finalize, dim=n, inputs=[src["params"], out_acc, res])
    host = gw.from_struct_array(res)
    return _typed(host)


def _typed(host: dict) -> dict:
    """Result columns in the dtypes of kernels.grasp.finalize."""
    out = {}
    for name in RESULT_FIELDS:
        v = host[name]
        if name in kt.RESULT_FLAGS:
            out[name] = v.astype(bool)
        elif name in kt.RESULT_COUNTS:
            out[name] = v.astype(np.int32)
        else:
            out[name] = v.astype(np.float32)
    return out


def _overflow_masks() -> tuple[int, int]:
    """(contact bits, row bits) of MuJoCo Warp's OverflowType that mean a dropped contact
    or constraint row (the solver's iteration cap is not a buffer overflow)."""
    from mujoco_warp._src.types import OverflowType as t

    contacts = t.BROADPHASE | t.NARROWPHASE | t.CCD | t.EPA_HORIZON
    rows = t.NEFC | t.NJMAX_NNZ
    return int(contacts), int(rows)


def _describe_overflow(bits: int) -> str:
    from mujoco_warp._src.types import OverflowType as t

    return "|".join(f.name for f in t if f.value and f.value & bits and f != t.ALL) or "none"


def make_backend(
    scene: Scene,
    grasp: GraspConfig,
    batch_size: int,
    devices=None,
    ticks_per_call: int = DEFAULT_TICKS_PER_CALL,
    buffers: BufferSizes | None = None,
    deterministic: bool = False,
    shrink_levels: int = DEFAULT_SHRINK_LEVELS,
):
    """The Warp backend on `devices` (Warp device names; default: every CUDA GPU, or the
    CPU with MJX_PICK_WARP_CPU=1). Several devices: one backend per device with
    batch_size / n slots each, run side by side, their buffers sized once for all; the
    devices build their models and capture their graphs in parallel."""
    check_warp()
    devices = [str(d) for d in (devices or default_devices())]
    if not devices:
        raise ConfigError("backend 'warp': no device to run on")
    options = {
        "ticks_per_call": ticks_per_call,
        "deterministic": deterministic,
        "shrink_levels": shrink_levels,
    }
    if len(devices) == 1:
        return WarpBackend(scene, grasp, batch_size, device=devices[0], buffers=buffers, **options)
    buffers = buffers or size_buffers(scene, grasp)
    per_device = -(-int(batch_size) // len(devices))
    parts: list = [None] * len(devices)

    def build(i: int) -> None:
        parts[i] = WarpBackend(scene, grasp, per_device, devices[i], buffers=buffers, **options)

    threads = [threading.Thread(target=build, args=(i,)) for i in range(len(devices))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    if any(p is None for p in parts):
        raise RuntimeError("backend 'warp': a device failed to start (see the log)")
    return DeviceThreads(parts)
