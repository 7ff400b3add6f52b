"""The Backend protocol, what every backend shares, and making one by name.

A backend turns ``inputs.PickInputs`` into per-pick results (``kernels.grasp.finalize``)
and, on request, traces; the runner (``engine.runner``) calls it.
"""

from __future__ import annotations

import dataclasses
from typing import Protocol

import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import compiled, registry
from mjx_pick.engine.devices import check_jax_devices, keep_jax_on_cpu

# what every backend takes (their home: engine.inputs)
from mjx_pick.engine.inputs import PickInputs, addresses, make_inputs  # noqa: F401


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


def plan_jax(names) -> None:
    """Before one process builds backends of several names (a benchmark's runs): where
    one of them drives the GPU without JAX, JAX is kept on the CPU from the start (the C
    engine's host programs then never start JAX's CUDA platform, whose memory Warp
    needs), and one that runs JAX programs on devices is refused now, not after the
    others ran."""
    entries = [registry.entry(n) for n in names]
    without = [e.name for e in entries if e.jax is registry.Jax.NONE]
    on_devices = [e.name for e in entries if e.jax is registry.Jax.DEVICES]
    if without and on_devices:
        raise ConfigError(
            f"backends {sorted(set(without))} and {sorted(set(on_devices))} cannot share a "
            "process (the first keep JAX off the GPU, the second run JAX on it): run them "
            "in separate processes"
        )
    if without:
        keep_jax_on_cpu()


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
    allowed = {o.name for o in entry.options}
    unknown = sorted(k for k in options if k not in allowed)
    if unknown:
        raise ConfigError(f"backend {entry.name!r} takes no options {unknown}")
    # devices and nthread are hints: a CPU backend runs threads, a device backend
    # shards over devices; neither is given the other's
    hint = ("nthread", nthread) if entry.device is registry.Device.CPU else ("devices", devices)
    if hint[1] is not None:
        options[hint[0]] = hint[1]
    if entry.jax is registry.Jax.NONE:  # its host side's JAX (the C engine's sizing) on the CPU
        keep_jax_on_cpu()
    elif entry.jax is registry.Jax.DEVICES:
        check_jax_devices()
        # simulating starts here: JAX's compiled programs kept on disk (not at import);
        # host programs turn it on where they start (devices.jax_cpu_device)
        compiled.use_persistent_cache()
    return registry.load(entry.factory)(scene, grasp, batch_size, **options)
