"""MJX-Warp backend: the MJX program with ``impl='warp'`` on NVIDIA GPUs.

MJX's JAX rollout (``engine.mjx_backend``) on MuJoCo Warp's kernels, which mujoco-mjx
vendors and calls from JAX: the MJX path at the default physics. Buffers are sized as for
the direct Warp backend (``engine.warp_buffers``; overflowing picks are re-simulated with
grown buffers); ``run_rne_postconstraint`` is on (cfrc_ext gives the pad forces); the
refilled pool runs as one device program per call, its CUDA graphs captured by Warp
(graph mode 'WARP'). docs/gpu.md compares it with the direct backend.
"""

from __future__ import annotations

import functools
import logging
import time

import jax

from mjx_pick.core.config import ConfigError
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine.backend import PickInputs
from mjx_pick.engine.devices import nvidia_gpus, warp_problem
from mjx_pick.engine.mjx_backend import (
    DEFAULT_SHRINK_LEVELS,
    DEFAULT_TICKS_PER_CALL,
    MjxBackend,
    Physics,
)
from mjx_pick.engine.warp_buffers import (  # noqa: F401 (re-exported: benchmarks, tests)
    MAX_GROWTH,
    BufferOverflowError,
    BufferSizes,
    buffer_margin,
    measure_buffers,
    rerun_overflowed,
    size_buffers,
)

INSTALL_HINT = (
    'pip install ".[gpu]" (CUDA 13; on CUDA 12 drivers, warp-lang 1.18\'s cu12 wheel from '
    "NVIDIA's release page)"
)
GRAPH_MODES = ("WARP", "WARP_STAGED", "WARP_STAGED_EX", "JAX", "NONE")

log = logging.getLogger(__name__)


def check_warp() -> None:
    """Raise a ConfigError naming the extra to install when Warp cannot run here."""
    problem = warp_problem()
    if problem:
        raise ConfigError(
            f"backend = 'mjx-warp' needs an NVIDIA GPU and warp-lang: {problem}. Install the GPU "
            f"extra: {INSTALL_HINT}; or choose backend 'mujoco' (the C engine on CPU "
            "threads; for derivatives, 'mjx': MJX's JAX physics at the differentiable physics)"
        )


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
    machine (benchmarks/probes/warp_stream_repro.py reproduces it; with this, or with the
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


class MjxWarpBackend(MjxBackend):
    """The MJX backend with ``impl='warp'``; refills its slots by default.

    buffers: Warp's buffer sizes (default: :func:`size_buffers` on the scene, measured
    when the backend is built). devices: one device (default: the first CUDA GPU;
    :func:`make_warp_backend` runs several GPUs). graph_mode: one of GRAPH_MODES (default
    'WARP' on a GPU, 'JAX' on the CPU, MJX's own defaults).
    """

    name = "mjx-warp"
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
            # several GPUs: make_warp_backend gives each its own MjxWarpBackend
            raise ConfigError(
                f"MjxWarpBackend runs on one device; got {len(devices)}: use make_warp_backend"
            )
        super().__init__(scene, grasp, batch_size, devices, refill, ticks_per_call, shrink_levels)
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
        """One physics step of one world, now: Warp builds (or loads from its cache)
        its kernels at their first launch, and that belongs to compile time, not to
        the first batch's run time."""
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
        doubled buffers, a new compile (``warp_buffers.rerun_overflowed``)."""
        first = (*super().run(inputs, record), self.last_diagnostics)

        def rerun(sub):
            self._compiled.clear()  # programs of the old sizes
            out, rows = super(MjxWarpBackend, self).run(sub, record)
            return out, rows, self.last_diagnostics

        merged, traces, diag = rerun_overflowed(
            self, inputs, first, rerun, (self._contact_mask, self._row_mask), describe_overflow
        )
        self.last_diagnostics = diag
        return merged, traces


def make_warp_backend(scene: Scene, grasp: GraspConfig, batch_size: int, devices=None, **options):
    """The Warp backend on `devices` (default: every CUDA GPU JAX sees; the CPU with
    MJX_PICK_WARP_CPU=1 and no GPU). One device: an MjxWarpBackend with batch_size slots.
    Several: one MjxWarpBackend per device with batch_size / n slots each, run side by side
    (``pool.DeviceThreads``: contiguous shares of the pick-points, nothing
    communicated); their buffers are sized once, on the C engine, for all."""
    check_warp()
    if devices is None:
        devices = nvidia_gpus() or jax.devices("cpu")[:1]
    devices = list(devices)
    if not devices:
        raise ConfigError("backend 'mjx-warp': no device given")
    if len(devices) == 1:
        return MjxWarpBackend(scene, grasp, batch_size, devices=devices, **options)
    from mjx_pick.engine.pool import DeviceThreads

    if options.get("buffers") is None:
        options["buffers"] = size_buffers(scene, grasp)
    per_device = -(-int(batch_size) // len(devices))
    return DeviceThreads(
        [MjxWarpBackend(scene, grasp, per_device, devices=[d], **options) for d in devices]
    )
