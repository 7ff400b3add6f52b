"""The runner: the one place where pick-points are simulated.

Details: docs/engine.md (engine/runner.py).
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
from collections.abc import Callable, Iterator
from typing import NamedTuple

import numpy as np
import pyarrow as pa

from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.metrics import COLUMNS, results_table
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import interrupts, registry
from mjx_pick.engine.backend import Backend, make_backend
from mjx_pick.engine.chunks import BackendChunks, ChunkStore
from mjx_pick.engine.inputs import PickInputs, make_inputs

ProgressFn = Callable[[int, int], None]  # (pick-points done, pick-points in the run)


class Cancelled(RuntimeError):
    """A run stopped between chunks because its cancel event was set."""


@dataclasses.dataclass
class Timing:
    """Time spent by one runner call (or summed over several), seconds.

    compile_s: compiling device programs (MJX/Warp) or the per-tick controller and
    building C-engine batches (MuJoCo C); run_s: simulating, after compiles, with the
    device synchronised; wall_s: the whole call, host work included; n: pick-points.
    """

    compile_s: float = 0.0
    run_s: float = 0.0
    wall_s: float = 0.0
    n: int = 0

    def __add__(self, other: Timing) -> Timing:
        return Timing(*(a + b for a, b in zip(self.astuple(), other.astuple(), strict=True)))

    def __sub__(self, other: Timing) -> Timing:
        return Timing(*(a - b for a, b in zip(self.astuple(), other.astuple(), strict=True)))

    def astuple(self) -> tuple:
        return (self.compile_s, self.run_s, self.wall_s, self.n)

    @property
    def picks_per_s(self) -> float | None:
        return self.n / self.run_s if self.run_s > 0 else None


class Outcome(NamedTuple):
    """What :meth:`Runner.run` returns."""

    results: dict  # per pick-point results (kernels.grasp.finalize), (N,) numpy arrays
    traces: np.ndarray | None  # (N, T, F) with record (kernels.grasp.TRACE_FIELDS), else None
    timing: Timing  # of this call


def auto_chunk(backend: Backend) -> int:
    """Chunk size: the backend's preferred one where it has one; else what fits in half
    the free device memory (MJX on an accelerator), capped at 65536 pick-points, a whole
    number of batches; else one batch (the C engine, or a device that reports no
    memory)."""
    batch = backend.batch_size
    if hasattr(backend, "preferred_chunk"):  # a backend that knows its own (Warp)
        return int(backend.preferred_chunk())
    stats = None
    if hasattr(backend, "device_bytes_per_pick"):  # MJX, Warp: a device program
        dev = backend.devices[0]
        stats = dev.memory_stats() if dev.platform != "cpu" else None
    if not stats or "bytes_limit" not in stats:
        return batch
    free = (stats["bytes_limit"] - stats.get("bytes_in_use", 0)) * len(backend.devices)
    fits = int(0.5 * free // backend.device_bytes_per_pick())
    return max(batch, min(65536, fits) // batch * batch)


class Runner:
    """Backends, chunked runs, progress, cancellation and timing for one caller: in this
    process, or on a Ray cluster (a runner made by ``cluster.ray_runner``).

    Args:
      backend: 'auto' or a backend's name (``engine.registry``).
      batch_size: simulations per backend call (default: ``registry.default_batch_size``).
      chunk_size: pick-points per chunk, the unit of progress and cancellation
        (default: :func:`auto_chunk` of each backend).
      on_progress: default progress callback of :meth:`run`, ``(done, total)``.
      cancel: an event; once set, the next chunk raises :class:`Cancelled`.
      nthread, devices, options: passed to ``make_backend`` (C-engine threads; the
        devices MJX/Warp shard over; refill, ticks_per_call, buffers, ...).
      cluster: where backends and chunks run instead of this process: a Ray cluster's
        actors (``cluster.ray_runner`` passes it; its ``backend(scene, grasp)``,
        ``chunks(scene, grasp)``, ``close()``); None: this process.
    """

    def __init__(
        self,
        backend: str = registry.AUTO,
        batch_size: int | None = None,
        *,
        chunk_size: int | None = None,
        on_progress: ProgressFn | None = None,
        cancel: threading.Event | None = None,
        nthread: int | None = None,
        devices=None,
        cluster=None,
        **options,
    ) -> None:
        if chunk_size is not None and int(chunk_size) < 1:
            raise ConfigError(f"chunk_size = {chunk_size} is out of range: allowed >= 1")
        self.backend_name = backend
        self.batch_size = batch_size
        self.chunk_size = chunk_size
        self.on_progress = on_progress
        self.cancel = cancel
        self.nthread, self.devices, self.options = nthread, devices, options
        self.cluster = cluster
        self.backends: list[Backend] = []  # every backend this runner ran, in order built
        # what describe() counts from: a warm runner's caller (evaluate on a Session's
        # simulator) marks its start, leaving earlier calls' compiles and runs out
        self.since = Timing()
        self.rollouts = 0  # pick-point simulations run so far

    def close(self) -> None:
        """Release what the runner holds: a cluster's actors (nothing in this process)."""
        if self.cluster is not None:
            self.cluster.close()

    def make(self, scene: Scene, grasp: GraspConfig) -> Backend:
        """A new backend for scene and grasp (on MJX/Warp: one compile per batch shape)."""
        if self.cluster is not None:
            backend = self.cluster.backend(scene, grasp)
        else:
            size = self.batch_size or registry.default_batch_size(self.backend_name)
            backend = make_backend(
                self.backend_name,
                scene,
                grasp,
                size,
                nthread=self.nthread,
                devices=self.devices,
                **self.options,
            )
        self.backends.append(backend)
        return backend

    def chunks(
        self,
        backend: Backend,
        grasp: GraspConfig,
        inputs: Callable[[GraspBatch], PickInputs] | None = None,
        gripper: GripperSpec | None = None,
    ):
        """What runs whole chunks of pick-points (:class:`GraspBatch`) for
        :func:`run_chunks` on backend (built by :meth:`make` for grasp): this process, or
        one chunk per call on a cluster's actors. It has ``name``, ``device``,
        ``batch_size``, ``run(chunks)`` (yielding each :class:`ChunkDone` as it
        finishes, in any order), ``record(picks)`` (traces (N, T, F)) and
        ``describe(wall_s)`` (as :meth:`describe`).

        inputs, gripper: picks -> their inputs, and the gripper that simulates them (the
        results' height compensation), where the backend also serves other settings of
        its program (``Simulator.chunks``); default: ``make_inputs`` on the backend's
        scene and grasp, and that scene's gripper. In this process only.
        """
        if self.cluster is not None:
            if inputs is not None or gripper is not None:
                raise ValueError("a cluster's chunks make their inputs on its actors")
            return self.cluster.chunks(backend.scene, grasp)
        return _LocalChunks(self, backend, grasp, inputs, gripper)

    def adopt(self, backend: Backend) -> None:
        """Count a backend built by another runner (one runner's run shared by a study)."""
        if not any(b is backend for b in self.backends):
            self.backends.append(backend)

    @property
    def timing(self) -> Timing:
        """Compile and run time and pick-points of every backend so far (wall_s: 0)."""
        return sum(
            (Timing(b.stats.compile_s, b.stats.run_s, 0.0, b.stats.n) for b in self.backends),
            Timing(),
        )

    def describe(self, wall_s: float | None = None) -> dict:
        """What ran, for a run's metadata (``rundir.finish``): backend, device and
        timing (compile_s, run_s: summed over this runner's backends since
        :attr:`since`; simulations: the pick-point simulations run; wall_s: the
        caller's, when given)."""
        first = self.backends[0] if self.backends else None
        t = self.timing - self.since
        timing = {"compile_s": round(t.compile_s, 3), "run_s": round(t.run_s, 3)}
        timing["simulations"] = int(t.n)
        if wall_s is not None:
            timing["wall_s"] = round(wall_s, 3)
        return {
            "backend": first.name if first is not None else self.backend_name,
            "device": first.device if first is not None else None,
            "timing": timing,
        }

    def simulate(
        self, scene: Scene, grasp: GraspConfig, inputs: PickInputs, *, record: bool = False
    ) -> Outcome:
        """One run on a new backend for scene and grasp: :meth:`make`, then :meth:`run`."""
        return self.run(self.make(scene, grasp), inputs, record=record)

    def check_cancel(self) -> None:
        """Raise :class:`Cancelled` when the cancel event is set, ``KeyboardInterrupt``
        when a Ctrl-C was recorded (``mjx_pick.engine.interrupts``: it may have been swallowed
        where it was first raised)."""
        if self.cancel is not None and self.cancel.is_set():
            raise Cancelled("cancelled")
        interrupts.raise_if_requested()

    def chunk_for(self, backend: Backend) -> int:
        return int(self.chunk_size or auto_chunk(backend))

    def run(
        self,
        backend: Backend,
        inputs: PickInputs,
        *,
        record: bool = False,
        chunk_size: int | None = None,
        on_progress: ProgressFn | None = None,
        store: BackendChunks | None = None,
    ) -> Outcome:
        """Simulate inputs (N pick-points) on backend, chunk by chunk.

        Args:
          record: also return traces (N, T, F) at the control rate.
          chunk_size: pick-points per chunk for this call (default: the runner's).
          on_progress: ``(done, total)`` after each chunk (default: the runner's).
          store: a run's finished chunks as seen from this backend
            (``ChunkStore.for_backend``): a chunk found there is read instead of
            simulated, each simulated one is saved; the chunk size is the store's for
            this program once it has one (not with record).

        Returns:
          :class:`Outcome`: results ((N,) arrays), traces, this call's timing.
        """
        report = on_progress if on_progress is not None else self.on_progress
        n = len(inputs)
        chunk = int(chunk_size or self.chunk_for(backend))
        if record:
            store = None  # traces are not kept
        if store is not None:
            chunk = store.chunk_size(chunk)
        stats = backend.stats
        compile0, run0 = stats.compile_s, stats.run_s
        t0 = time.perf_counter()
        if report is not None:
            report(0, n)
        results, traces = [], []
        # an empty run still calls the backend once: it says what an empty batch gives
        for start in range(0, max(n, 1), chunk):
            self.check_cancel()
            rows = slice(start, start + chunk)
            part = inputs.take(rows)
            out = store.read(part, rows) if store is not None else None
            trace = None
            if out is None:
                out, trace = backend.run(part, record=record)
                if store is not None:
                    store.write(part, rows, out)
            results.append(out)
            traces.append(trace)
            self.rollouts += min(chunk, n - start)
            if report is not None:
                report(min(start + chunk, n), n)
        merged, merged_traces = _joined(results, traces if record else None)
        timing = Timing(stats.compile_s - compile0, stats.run_s - run0, time.perf_counter() - t0, n)
        return Outcome(merged, merged_traces, timing)


def _joined(results: list[dict], traces: list | None) -> tuple[dict, np.ndarray | None]:
    """The chunks' results joined into (N,) arrays, and their traces into (N, T, F)
    (traces None: none were recorded)."""
    merged = results[0]
    if len(results) > 1:
        merged = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
    if traces is None:
        return merged, None
    return merged, traces[0] if len(traces) == 1 else np.concatenate(traces)


# ------------------------------------------------------------------- chunked, resumable


@dataclasses.dataclass(frozen=True)
class ChunkDone:
    """One finished chunk, as a runner's chunks (:meth:`Runner.chunks`) hand it back."""

    k: int  # the chunk's index in its run
    table: pa.Table  # its rows (``metrics.COLUMNS``), in pick-point order
    run_s: float  # simulating, after compiles, s
    compile_s: float  # compiling or building batches for it, s
    wall_s: float  # the whole call where it ran, s
    where: str  # who ran it: "local", or a cluster node's label


class _LocalChunks:
    """Chunks run one after another on one backend of a runner, in this process
    (:meth:`Runner.chunks`). Cancellation is the runner's: its event is checked before
    every chunk."""

    def __init__(
        self,
        runner: Runner,
        backend: Backend,
        grasp: GraspConfig,
        inputs: Callable[[GraspBatch], PickInputs] | None = None,
        gripper: GripperSpec | None = None,
    ):
        self.runner, self.backend, self.grasp = runner, backend, grasp
        self.name, self.device = backend.name, backend.device
        self.batch_size = int(backend.batch_size)
        self.inputs = inputs or (lambda picks: make_inputs(backend.scene, grasp, picks))
        self.gripper = gripper or backend.scene.gripper

    def run(self, chunks: dict[int, GraspBatch]) -> Iterator[ChunkDone]:
        for k in sorted(chunks):
            sub = chunks[k]
            inputs = self.inputs(sub)
            self.runner.check_cancel()
            # one chunk per runner call: progress is reported by the caller, in its terms
            out = self.runner.run(
                self.backend, inputs, chunk_size=max(len(sub), 1), on_progress=_quiet
            )
            t = out.timing
            yield ChunkDone(
                k,
                results_table(sub, out.results, self.gripper),
                t.run_s,
                t.compile_s,
                t.wall_s,
                "local",
            )

    def simulate(self, inputs: PickInputs, record: bool) -> Outcome:
        """One call on prepared inputs, as one chunk (a cluster actor's piece of a run)."""
        return self.runner.run(self.backend, inputs, record=record, chunk_size=len(inputs) or 1)

    def record(self, picks: GraspBatch) -> np.ndarray:
        return self.runner.run(self.backend, self.inputs(picks), record=True).traces

    def describe(self, wall_s: float | None = None) -> dict:
        return self.runner.describe(wall_s)


def chunk_name(k: int) -> str:
    """The name of chunk k of an evaluate run in its store (``part-000007.parquet``)."""
    return f"{k:06d}"


def read_chunk(store: ChunkStore | None, k: int, picks: GraspBatch) -> pa.Table | None:
    """Chunk k of a run from its store, or None when it is not there; checked against
    its pick-points."""
    if store is None:
        return None
    table = store.read(chunk_name(k), len(picks))
    if table is None:
        return None
    ids = np.asarray(table["pick_id"]) if "pick_id" in table.column_names else None
    if ids is None or not np.array_equal(ids, picks.pick_id):
        raise ConfigError(
            f"{store.path(chunk_name(k))} does not hold the pick-points of chunk {k}: "
            "choose another --out"
        )
    if table.column_names[: len(COLUMNS)] != list(COLUMNS):
        # written by a version of mjx-pick whose results had other columns: the rows
        # could not be joined with this run's
        raise ConfigError(
            f"{store.path(chunk_name(k))} was written by another version of mjx-pick "
            f"(columns {table.column_names[: len(COLUMNS)]}, this version writes "
            f"{list(COLUMNS)}): choose another --out"
        )
    return table


def _distributed() -> bool:
    """Whether this process is one of several of a ``jax.distributed`` job (asked
    without starting JAX: a process that never imported it is not)."""
    if "jax" not in sys.modules:
        return False
    import jax

    return jax.distributed.is_initialized()


def run_chunks(
    chunks_of,
    picks: GraspBatch,
    chunk_size: int,
    store: ChunkStore | None = None,
    on_progress: ProgressFn | None = None,
    on_chunk: Callable[[ChunkDone], None] | None = None,
) -> pa.Table:
    """Simulate picks chunk by chunk into a results table (``metrics.COLUMNS``).

    Chunk k holds picks ``[k * chunk_size, (k + 1) * chunk_size)``; chunks_of runs them
    (:meth:`Runner.chunks`: this process, or a cluster's actors), finishing them in any
    order; the table is in pick-point order. With a store, each finished chunk is
    written at once (atomically) by this process alone; a chunk already there (an
    earlier, interrupted run of the same configuration) is read instead of simulated.

    on_progress(done, total): pick-points finished (read or simulated) of len(picks),
    once before the first chunk and after each one. on_chunk: each simulated chunk.
    """
    n = len(picks)
    if _distributed():
        raise ConfigError(
            "evaluate runs one driver process: spread a run over machines with --ray "
            "(docs/cluster.md), not jax.distributed"
        )
    size = int(chunk_size)
    n_chunks = max(1, -(-n // size))
    chunks = {k: picks.take(slice(k * size, (k + 1) * size)) for k in range(n_chunks)}
    parts: dict[int, pa.Table] = {}
    done = 0
    if on_progress is not None:
        on_progress(0, n)
    for k, sub in chunks.items():
        table = read_chunk(store, k, sub)
        if table is not None:
            parts[k] = table  # finished by an earlier run: reported as it is read
            done += len(sub)
            if on_progress is not None:
                on_progress(done, n)
    todo = {k: sub for k, sub in chunks.items() if k not in parts}
    for result in chunks_of.run(todo) if todo else ():
        parts[result.k] = result.table
        if store is not None:
            store.write(chunk_name(result.k), result.table)
        done += len(chunks[result.k])
        if on_chunk is not None:
            on_chunk(result)
        if on_progress is not None:
            on_progress(done, n)
    missing = sorted(set(chunks) - set(parts))
    if missing:
        raise RuntimeError(f"chunks {missing[:8]} were left unfinished")
    return pa.concat_tables([parts[k] for k in range(n_chunks)])


def _quiet(done: int, total: int) -> None:
    """No progress (the caller reports it in its own terms)."""
