"""Which engines this machine can run (GPUs, whether MuJoCo Warp loads) and which JAX
platforms this process may start.

Kept apart from the Warp backend so that choosing a backend (``backend.make_backend``
with 'auto') asks these questions without importing the backend that needs the answer.
"""

from __future__ import annotations

import atexit
import functools
import importlib.metadata
import importlib.util
import os
import sys
import threading

from mjx_pick.core.config import ConfigError
from mjx_pick.engine import compiled
from mjx_pick.kernels.warp_runtime import warp

# set to 1: let the Warp backend run on the CPU (warp-lang's CPU device; tests only)
ALLOW_CPU_ENV = "MJX_PICK_WARP_CPU"


_jax_on_cpu = False  # keep_jax_on_cpu() was called in this process


def keep_jax_on_cpu() -> None:
    """Let JAX start its CPU platform only, in this process, from now on.

    A backend that drives the GPU without JAX (the direct MuJoCo Warp backend) calls it:
    JAX may still run host programs in its process (the C engine's per-tick controller
    when Warp's buffers are sized on it), but starting JAX's CUDA platform would take
    three quarters of every GPU's memory (XLA preallocates it) from Warp. Sets
    ``jax_platforms = "cpu"`` now if JAX is imported, else when :func:`jax_cpu_device`
    first imports it (nothing is imported here); JAX starts every platform at once at
    its first device query, so this must come before. A JAX program on a device is
    refused from then on (:func:`check_jax_devices`).

    Raises:
      ConfigError: JAX already started a platform other than the CPU in this process.
    """
    global _jax_on_cpu
    _jax_on_cpu = True
    if "jax" in sys.modules:
        _confine_jax()


def _confine_jax() -> None:
    import jax

    # whether a platform started, asked without starting one (JAX's public API has no
    # such question); once started, backends() starts nothing more
    from jax._src import xla_bridge

    if not xla_bridge.backends_are_initialized():
        jax.config.update("jax_platforms", "cpu")
        return
    started = sorted(set(xla_bridge.backends()) - {"cpu"})
    if started:
        raise ConfigError(
            f"JAX has started {', '.join(started)} in this process, whose memory the direct "
            "MuJoCo Warp backend needs: run it in a process of its own (the MJX backends in "
            "another)"
        )


def check_jax_devices() -> None:
    """Refuse a backend that runs JAX programs on JAX's devices in a process whose JAX
    is kept on the CPU (:func:`keep_jax_on_cpu`) on a machine with an NVIDIA GPU (where
    they would run on the CPU instead; without one, the CPU is their device anyway)."""
    if _jax_on_cpu and nvidia_driver_present():
        raise ConfigError(
            "this process keeps JAX on the CPU for the direct MuJoCo Warp backend: run the "
            "MJX backends in a process of their own"
        )


def jax_cpu_device():
    """JAX's CPU device, for host programs (the C engine's per-tick controller), with
    JAX's compiled programs kept on disk (``engine.compiled``); starts JAX's CPU
    platform only once :func:`keep_jax_on_cpu` was called."""
    if _jax_on_cpu:
        _confine_jax()
    import jax

    compiled.use_persistent_cache()
    return jax.devices("cpu")[0]


def nvidia_gpus() -> list:
    """JAX's CUDA devices (empty when JAX has no CUDA backend)."""
    import jax

    try:
        return list(jax.devices("cuda"))
    except RuntimeError:
        return []


def nvidia_driver_present() -> bool:
    """Whether an NVIDIA driver is loaded (Linux), asked without importing anything."""
    return os.path.exists("/proc/driver/nvidia/version") or os.path.exists("/dev/nvidiactl")


def nvidia_gpu_count() -> int:
    """NVIDIA GPUs on this machine, asked without starting JAX's CUDA backend (which
    would take most of their memory): none without an NVIDIA driver; else as Warp sees
    them, or JAX where warp-lang is not installed."""
    if not nvidia_driver_present():
        return 0
    if importlib.util.find_spec("warp") is not None:
        try:
            return int(warp().get_cuda_device_count())
        except Exception:  # warp's native library does not load: ask JAX
            pass
    return len(nvidia_gpus())


def start_warp() -> None:
    """Start Warp -- its import, CUDA's driver and the GPUs' contexts -- on a thread of
    its own, while the caller goes on with its imports and the part's preparation.

    CUDA's start runs in Warp's native library, which does not hold Python's GIL, so it
    overlaps the caller's Python work (an import on a second thread does not: the two
    take turns at the GIL). Nothing happens without an NVIDIA driver or warp-lang; a
    failure is left for the next ``warp()`` call (``kernels.warp_runtime``) to raise.
    The process waits for the thread before it exits (a CUDA call cut off by the
    interpreter's exit)."""
    if not nvidia_driver_present() or importlib.util.find_spec("warp") is None:
        return

    def start() -> None:
        try:
            warp()
        except Exception:  # noqa: BLE001 - the caller's own warp() call says what failed
            pass

    thread = threading.Thread(target=start, name="warp-start", daemon=True)
    thread.start()
    atexit.register(thread.join)


def has_accelerator() -> bool:
    """Whether JAX sees a GPU or TPU (device batches are sized for it)."""
    import jax

    return any(d.platform in ("gpu", "tpu", "cuda", "rocm") for d in jax.devices())


def warp_pin() -> str | None:
    """mujoco-mjx's own requirement on warp-lang (its 'warp' extra), e.g. '==1.18.0'."""
    try:
        reqs = importlib.metadata.requires("mujoco-mjx") or []
    except importlib.metadata.PackageNotFoundError:
        return None
    for r in reqs:
        name, _, rest = r.partition(";")
        if name.strip().startswith("warp-lang"):
            return name.strip()[len("warp-lang") :].strip() or None
    return None


@functools.cache
def warp_problem() -> str | None:
    """Why the Warp backend cannot run here, or None when it can.

    Checked in order: a CUDA GPU that JAX sees (unless MJX_PICK_WARP_CPU=1),
    warp-lang installed, at mujoco-mjx's pinned version, importable, and seeing the GPU.
    Never imports warp when there is no GPU (so ``auto`` on a CPU machine stays quiet).
    """
    allow_cpu = os.environ.get(ALLOW_CPU_ENV, "") == "1"
    if not nvidia_gpus() and not allow_cpu:
        return "JAX sees no NVIDIA (CUDA) GPU"
    if importlib.util.find_spec("warp") is None:
        return "warp-lang is not installed"
    try:
        version = importlib.metadata.version("warp-lang")
    except importlib.metadata.PackageNotFoundError:
        version = None
    pin = warp_pin()
    if version and pin:
        try:
            from packaging.specifiers import SpecifierSet

            if version not in SpecifierSet(pin):
                return f"warp-lang {version} is installed, but mujoco-mjx needs warp-lang{pin}"
        except ImportError:  # packaging absent: trust the installed version
            pass
    try:
        wp = warp()
        from mujoco.mjx import warp as mjxw

        if not mjxw.WARP_INSTALLED:
            return "mujoco.mjx could not import warp"
        if not allow_cpu and wp.get_cuda_device_count() < 1:
            return "warp-lang sees no CUDA device (driver too old for its CUDA build?)"
    except Exception as err:  # any failure to load warp's native library
        return f"warp-lang does not load: {type(err).__name__}: {err}"
    return None


def checks_device(backend) -> str | None:
    """The Warp device on which a run on `backend` checks its pick-point candidates
    (``pickpoints.FeasibilityChecker(device=...)``): the first CUDA device of the direct
    MuJoCo Warp backend in this process (its Warp device name, 'cuda:0'); None -- numpy
    on the host's threads -- for every other: MuJoCo C, MJX and MJX's Warp bridge (JAX
    holds the GPU there), a Ray cluster (its GPUs are the actors'), Warp on the CPU."""
    parts = getattr(backend, "parts", None) or [backend]  # pool.DeviceThreads: one a device
    name = getattr(parts[0], "device_name", None)  # warp_direct.WarpBackend's own
    return name if isinstance(name, str) and name.startswith("cuda") else None
