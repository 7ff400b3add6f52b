"""What the GPU backends' refilled pools share: their sizes in a run's tail, their
statistics and buffer diagnostics, and several devices' pools run as one backend."""

from __future__ import annotations

import copy
import dataclasses
import time
from concurrent.futures import ThreadPoolExecutor
from typing import Any, NamedTuple

import numpy as np

from mjx_pick.engine.backend import RunStats
from mjx_pick.engine.inputs import PickInputs

# halvings of a pool in a run's tail: as picks run out, a half-empty pool moves its live
# slots into a pool half its size, so the tail does not pay for idle slots
DEFAULT_SHRINK_LEVELS = 3
# the tail never shrinks a pool below this many slots per device: a small pool's GPU
# step is bound by kernel launches more than by its slot count, so a halving saves
# little, while every pool size is one more model and data to build
SHRINK_MIN_SLOTS = 4096


def shrink_sizes(slots: int, levels: int, min_slots: int = 1) -> tuple[int, ...]:
    """Pool sizes of a run's tail: slots, halved up to `levels` times while the halves
    stay whole numbers of at least min_slots (slots per device)."""
    sizes = [int(slots)]
    while len(sizes) <= levels and sizes[-1] % 2 == 0 and sizes[-1] // 2 >= max(min_slots, 1):
        sizes.append(sizes[-1] // 2)
    return tuple(sizes)


class Diagnostics(NamedTuple):
    """Per-simulation buffer use (int32 each; arrays of the backend's kind)."""

    overflow: Any  # Warp's overflow bits raised at any step of the pick
    nefc_max: Any  # most constraint rows in use at any step (-1: not tracked)
    nacon_max: Any  # most contacts of the whole pool in use at any step (-1: not tracked)


@dataclasses.dataclass
class PoolStats:
    """Work of refilled runs: how much of the pool's stepping simulated live picks, and
    (where the backend counts it) how the solver converged over live world-steps."""

    rounds: int = 0  # refill rounds (summed over devices)
    slot_ticks: int = 0  # slots x ticks per round, summed over rounds
    pick_ticks: int = 0  # ticks run by picks up to their end, summed over picks
    picks: int = 0
    steps: int = 0  # physics steps of the pool
    steps_converged: int = 0  # ... in which every live world converged before the cap
    solver_iterations: np.ndarray = dataclasses.field(
        default_factory=lambda: np.zeros(0, np.int64)
    )  # histogram over live world-steps: [i] = world-steps that took i iterations

    @property
    def occupancy(self) -> float:
        """Fraction of slot-ticks that simulated a pick that had not ended."""
        return self.pick_ticks / self.slot_ticks if self.slot_ticks else float("nan")

    def add(self, rounds: int, slot_ticks: int, pick_ticks: int, picks: int, counters=()) -> None:
        """Count one run: its refill rounds, slot-ticks, pick-ticks, picks and, where the
        backend counts them, the solver's counters (steps, steps converged, then the
        iteration histogram)."""
        self.rounds += rounds
        self.slot_ticks += slot_ticks
        self.pick_ticks += pick_ticks
        self.picks += picks
        if len(counters):
            self.steps += int(counters[0])
            self.steps_converged += int(counters[1])
            hist = np.asarray(counters[2:], np.int64)
            if self.solver_iterations.size != hist.size:
                self.solver_iterations = np.zeros(hist.size, np.int64)
            self.solver_iterations += hist

    def merge(self, after: PoolStats, before: PoolStats) -> None:
        """Add what another PoolStats counted between two readings (a device's run)."""
        for f in dataclasses.fields(PoolStats):
            now, then = getattr(after, f.name), getattr(before, f.name)
            if isinstance(now, np.ndarray):
                now = now - (then if then.size == now.size else 0)
                mine = self.solver_iterations
                mine = mine if mine.size == now.size else np.zeros(now.size, np.int64)
                self.solver_iterations = mine + now
            else:
                setattr(self, f.name, getattr(self, f.name) + now - then)

    def iteration_quantile(self, q: float) -> float:
        """The q-quantile (0..1) of solver iterations per live world-step."""
        h = self.solver_iterations
        if not h.size or not h.sum():
            return float("nan")
        cum = np.cumsum(h) / h.sum()
        return float(np.searchsorted(cum, q))


class DeviceThreads:
    """Several single-device backends as one: each runs a contiguous share of the
    pick-points on its own device, from its own host thread, and nothing passes between
    devices. Results come back in pick-point order.

    Why threads and not one sharded program: each device's pool should run (and be
    refilled) at its own pace -- a device whose picks end sooner must not wait for
    another's. The engines release the GIL while a device works.

    parts: backends of one class, one device each, built for the same scene and procedure.
    """

    def __init__(self, parts: list):
        if len(parts) < 2:
            raise ValueError(f"DeviceThreads needs >= 2 backends, got {len(parts)}")
        self.parts = list(parts)
        p0 = self.parts[0]
        self.name, self.scene, self.grasp = p0.name, p0.scene, p0.grasp
        self.batch_size = sum(p.batch_size for p in self.parts)
        self.devices = [d for p in self.parts for d in getattr(p, "devices", [p.device])]
        self.device = f"{p0.device} x{len(self.parts)}"
        self.refill = getattr(p0, "refill", True)
        self.stats = RunStats()
        self.pool_stats = PoolStats()
        self.last_diagnostics: Diagnostics | None = None

    def __getattr__(self, name: str):
        # what a part offers per device and the whole offers summed (a backend's own
        # sizes: preferred_chunk, peak_device_bytes): the parts' sum
        if name in ("preferred_chunk", "peak_device_bytes") and hasattr(self.parts[0], name):
            return lambda: _sum_or_none(getattr(p, name)() for p in self.parts)
        raise AttributeError(name)

    def shares(self, n: int) -> list[slice]:
        """Contiguous, near-equal shares of n pick-points, one per device."""
        bounds = np.linspace(0, n, len(self.parts) + 1).round().astype(int)
        return [slice(a, b) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def pool_size(self, n: int) -> int:
        return sum(
            p.pool_size(s.stop - s.start) for p, s in zip(self.parts, self.shares(n), strict=True)
        )

    @property
    def growths(self) -> int:
        return sum(getattr(p, "growths", 0) for p in self.parts)

    @property
    def buffers(self):
        return getattr(self.parts[0], "buffers", None)

    def run(self, inputs: PickInputs, record: bool = False):
        shares = self.shares(len(inputs))
        compile0 = [p.stats.compile_s for p in self.parts]
        before = [copy.deepcopy(p.pool_stats) for p in self.parts]
        t0 = time.perf_counter()
        with ThreadPoolExecutor(len(self.parts)) as ex:
            futures = [
                ex.submit(p.run, inputs.take(s), record)
                for p, s in zip(self.parts, shares, strict=True)
            ]
            outs = [f.result() for f in futures]  # re-raises a part's error
        wall = time.perf_counter() - t0
        # compiles run side by side too: the run is the wall time less the longest
        compiled = [p.stats.compile_s - c for p, c in zip(self.parts, compile0, strict=True)]
        self.stats.compile_s += max(compiled)
        self.stats.run_s += max(wall - max(compiled), 0.0)
        self.stats.n += len(inputs)
        for p, b in zip(self.parts, before, strict=True):
            self.pool_stats.merge(p.pool_stats, b)
        merged = {k: np.concatenate([o[0][k] for o in outs]) for k in outs[0][0]}
        traces = np.concatenate([o[1] for o in outs]) if record else None
        diags = [p.last_diagnostics for p in self.parts]
        self.last_diagnostics = Diagnostics(*(np.concatenate(x) for x in zip(*diags, strict=True)))
        return merged, traces


def _sum_or_none(values):
    values = list(values)
    return None if any(v is None for v in values) else sum(values)
