"""The simulation engine: the one place where pick-points are simulated.

Every caller runs its simulations through an :class:`Engine`: ``evaluate`` (chunked,
resumable: :func:`run_chunks`), the studies through :class:`Simulator` (sweep, compare,
design search, robustness, minimum grip force), calibration (``calibration.Problem``) and
the throughput benchmarks (``throughput.measure``, ``side_by_side``). It owns

* backend choice: ``simulate.make_backend`` ('auto', 'warp', 'mjx', 'mujoco'); a new
  backend is one module implementing the small ``simulate.Backend`` protocol;
* batching: inputs reach the backend in chunks, which the backend splits into its own
  batches -- MJX/Warp run fixed-size padded batches or a pool of slots refilled as
  picks end (the refill stays inside those backends: it is part of the device program);
* chunking and resume (:func:`run_chunks`, :class:`ChunkPlan`): chunks run on a
  :class:`ChunkExecutor` -- this process (:class:`LocalExecutor`) or the actors of a Ray
  cluster (``mjx_pick.engine.cluster``); the caller alone writes the output folder;
* progress: ``on_progress(done, total)`` in pick-points, called once before the first
  chunk and after every chunk;
* cancellation: a ``threading.Event`` checked before every chunk; once set, the run
  stops with :class:`Cancelled` (finished chunks of an evaluate folder are kept for
  ``resume``); a recorded Ctrl-C (``mjx_pick.engine.interrupts``) stops it the same way with
  ``KeyboardInterrupt``. A chunk that has started runs to its end: a device program cannot be
  interrupted, and a chunk is the unit that is saved;
* compile time apart from run time (:class:`Timing`, read from the backends' stats).

Every pick-point is simulated on its own (MJX pads batches with copies whose results
are dropped; a refilled pool gives the results of full-length rollouts), but the float32
rounding of a batched program may depend on the batch's SHAPE: on the C engine, the
per-tick kernel (XLA on the CPU) gave some scores one float32 step apart in batches of
different sizes (labels equal); it runs on
``c_backend.tick_rows(n)`` rows, the next power of two. So results
are bitwise the same for the same batch size and chunk size -- chunks that are whole
numbers of batches give every call the full batch but the run's last -- which is why a
resumed run keeps its chunk plan and a cluster run chunks as one machine would.

The one path that does not go through :meth:`Engine.run` is calibration's forward-mode
gradient: :func:`differentiable_rollout` says why.
"""

from __future__ import annotations

import dataclasses
import hashlib
import io
import json
import shutil
import sys
import threading
import time
import zipfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import NamedTuple, Protocol

import jax
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mjx_pick.core.config import ConfigError, to_dict, write_atomic, write_json, write_parquet
from mjx_pick.core.metrics import results_table
from mjx_pick.core.pickpoints import PickBatch
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import compiled, interrupts
from mjx_pick.engine.backend import (
    Backend,
    PickInputs,
    default_batch_size,
    make_backend,
    make_inputs,
)
from mjx_pick.outputs.rundir import claim, config_hash, is_complete

ProgressFn = Callable[[int, int], None]  # (pick-points done, pick-points in the run)


class Cancelled(RuntimeError):
    """A run stopped between chunks because its cancel event was set."""


@dataclasses.dataclass
class Timing:
    """Time spent by one engine call (or summed over several), seconds.

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
    """What :meth:`Engine.run` returns."""

    results: dict  # per pick-point results (kernels.grasp.finalize), (N,) numpy arrays
    traces: np.ndarray | None  # (N, T, F) with record (kernels.grasp.TRACE_FIELDS), else None
    timing: Timing  # of this call


def auto_chunk(backend: Backend) -> int:
    """Chunk size: what fits in half the free device memory (MJX/Warp on an
    accelerator), capped at 65536 pick-points, a whole number of batches; else one
    batch (the C engine, or a device that reports no memory)."""
    batch = backend.batch_size
    stats = None
    if hasattr(backend, "device_bytes_per_pick"):  # MJX, Warp: a device program
        dev = backend.devices[0]
        stats = dev.memory_stats() if dev.platform != "cpu" else None
    if not stats or "bytes_limit" not in stats:
        return batch
    free = (stats["bytes_limit"] - stats.get("bytes_in_use", 0)) * len(backend.devices)
    fits = int(0.5 * free // backend.device_bytes_per_pick())
    return max(batch, min(65536, fits) // batch * batch)


class Engine:
    """Backends, chunked runs, progress, cancellation and timing for one caller.

    Args:
      backend: 'auto', 'warp', 'mjx' or 'mujoco' (``simulate.make_backend``).
      batch_size: simulations per backend call (default: ``default_batch_size``).
      chunk_size: pick-points per chunk, the unit of progress and cancellation
        (default: :func:`auto_chunk` of each backend).
      on_progress: default progress callback of :meth:`run`, ``(done, total)``.
      cancel: an event; once set, the next chunk raises :class:`Cancelled`.
      nthread, devices, options: passed to ``make_backend`` (C-engine threads; the
        devices MJX/Warp shard over; refill, ticks_per_call, buffers, ...).
    """

    def __init__(
        self,
        backend: str = "auto",
        batch_size: int | None = None,
        *,
        chunk_size: int | None = None,
        on_progress: ProgressFn | None = None,
        cancel: threading.Event | None = None,
        nthread: int | None = None,
        devices=None,
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
        self.backends: list[Backend] = []  # every backend this engine ran, in order built
        self.rollouts = 0  # pick-point simulations run so far
        # simulating starts here: compiled programs kept on disk from now on (not at import)
        compiled.use_persistent_cache()

    def close(self) -> None:
        """Release what the engine holds: nothing here; a cluster's actors for
        ``cluster.RayEngine``."""

    def make(self, scene: Scene, grasp: GraspConfig) -> Backend:
        """A new backend for scene and grasp (on MJX/Warp: one compile per batch shape)."""
        size = self.batch_size or default_batch_size(self.backend_name)
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

    def adopt(self, backend: Backend) -> None:
        """Count a backend built by another engine (one engine's run shared by a study)."""
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
        timing (compile_s, run_s: summed over this engine's backends; simulations: the
        pick-point simulations run; wall_s: the caller's, when given)."""
        first = self.backends[0] if self.backends else None
        t = self.timing
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
        store: StoredScene | None = None,
    ) -> Outcome:
        """Simulate inputs (N pick-points) on backend, chunk by chunk.

        Args:
          record: also return traces (N, T, F) at the control rate.
          chunk_size: pick-points per chunk for this call (default: the engine's).
          on_progress: ``(done, total)`` after each chunk (default: the engine's).
          store: a study's finished chunks as seen from this backend
            (:meth:`ChunkStore.scene`): a chunk found there is read instead of
            simulated, each simulated one is saved; the chunk size is the store's for
            this scene once it has one (not with record).

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
            part = inputs.take(slice(start, start + chunk))
            out = store.read(part) if store is not None else None
            if out is None:
                out, rows = backend.run(part, record=record)
                if store is not None:
                    store.write(part, out)
            else:
                rows = None
            results.append(out)
            traces.append(rows)
            self.rollouts += min(chunk, n - start)
            if report is not None:
                report(min(start + chunk, n), n)
        merged = results[0]
        if len(results) > 1:
            merged = {k: np.concatenate([r[k] for r in results]) for k in results[0]}
        rows = None
        if record:
            rows = traces[0] if len(traces) == 1 else np.concatenate(traces)
        timing = Timing(stats.compile_s - compile0, stats.run_s - run0, time.perf_counter() - t0, n)
        return Outcome(merged, rows, timing)


# ------------------------------------------------------------------- chunked, resumable


@dataclasses.dataclass(frozen=True)
class ChunkDone:
    """One finished chunk, as a :class:`ChunkExecutor` hands it back."""

    k: int  # the chunk's index in its run
    table: pa.Table  # its rows (``metrics.COLUMNS``), in pick-point order
    run_s: float  # simulating, after compiles, s
    compile_s: float  # compiling or building batches for it, s
    wall_s: float  # the whole call where it ran, s
    where: str  # who ran it: "local", or a cluster node's label


class ChunkExecutor(Protocol):
    """Runs chunks of pick-points for :func:`run_chunks`: in this process
    (:class:`LocalExecutor`) or on the actors of a Ray cluster (``cluster.RayExecutor``).

    An executor simulates; it never writes the output folder (the caller alone does).
    """

    name: str  # the backend every chunk runs on ('mujoco', 'warp', ...)
    device: str  # what it runs on, in words
    batch_size: int  # simulations per backend call

    def run(self, chunks: dict[int, PickBatch]) -> Iterator[ChunkDone]:
        """Simulate every chunk, yielding each as it finishes (in any order)."""
        ...

    def record(self, picks: PickBatch) -> np.ndarray:
        """Traces (N, T, F) of picks at the control rate (``kernels.grasp.TRACE_FIELDS``)."""
        ...

    def describe(self, wall_s: float | None = None) -> dict:
        """backend, device and timing, for ``rundir.finish`` (as :meth:`Engine.describe`)."""
        ...


class LocalExecutor:
    """Chunks run one after another on one backend of an engine, in this process.

    Cancellation is the engine's: its event is checked before every chunk.
    """

    def __init__(self, engine: Engine, backend: Backend, grasp: GraspConfig):
        self.engine, self.backend, self.grasp = engine, backend, grasp
        self.name, self.device = backend.name, backend.device
        self.batch_size = int(backend.batch_size)

    def run(self, chunks: dict[int, PickBatch]) -> Iterator[ChunkDone]:
        for k in sorted(chunks):
            sub = chunks[k]
            inputs = make_inputs(self.backend.scene, self.grasp, sub)
            self.engine.check_cancel()
            # one chunk per engine call: progress is reported by the caller, in its terms
            out = self.engine.run(
                self.backend, inputs, chunk_size=max(len(sub), 1), on_progress=_quiet
            )
            t = out.timing
            yield ChunkDone(
                k,
                results_table(sub, out.results, self.backend.scene.gripper),
                t.run_s,
                t.compile_s,
                t.wall_s,
                "local",
            )

    def record(self, picks: PickBatch) -> np.ndarray:
        inputs = make_inputs(self.backend.scene, self.grasp, picks)
        return self.engine.run(self.backend, inputs, record=True).traces

    def describe(self, wall_s: float | None = None) -> dict:
        return self.engine.describe(wall_s)


@dataclasses.dataclass(frozen=True)
class ChunkPlan:
    """How a run cuts its pick-points into chunks: the state that must survive a kill.

    Saved (atomically) as ``chunks/plan.json`` before the first chunk is simulated and
    read back by a resumed run, which keeps the plan's chunk size: the size a new start
    would pick (from free device memory, or another ``--chunk-size``) may differ, and
    chunk k on disk must mean the same pick-points. The chunk files are the progress
    (each written atomically): a chunk is done exactly when its file exists.
    """

    key: str  # the experiment's resume key (evaluate's experiment_key)
    n: int  # pick-points in the run (Optimization mode: at most)
    chunk_size: int  # pick-points per chunk

    @property
    def n_chunks(self) -> int:
        return max(1, -(-self.n // self.chunk_size))

    @staticmethod
    def path(out_dir: Path) -> Path:
        return Path(out_dir) / "chunks" / "plan.json"

    def save(self, out_dir: Path) -> None:
        write_json(self.path(out_dir), dataclasses.asdict(self))

    @classmethod
    def load(cls, out_dir: Path) -> ChunkPlan | None:
        """The saved plan, or None when there is none."""
        path = cls.path(out_dir)
        if not path.is_file():
            return None
        try:
            data = json.loads(path.read_text())
            return cls(str(data["key"]), int(data["n"]), int(data["chunk_size"]))
        except (ValueError, KeyError, TypeError) as err:
            raise ConfigError(
                f"{path}: unreadable chunk plan ({err}); choose another --out"
            ) from err


def chunk_path(out_dir: Path, k: int) -> Path:
    """Where chunk k of a run in out_dir is written (the GUI counts these files)."""
    return out_dir / "chunks" / f"part-{k:06d}.parquet"


def plan_chunks(out_dir: Path | None, key: str, n: int, chunk: int, resume: bool) -> ChunkPlan:
    """The chunk plan of a run: a new one (saved in out_dir), or, resuming, the saved one.

    Raises ConfigError, before anything is simulated, when out_dir holds finished chunks
    and resume is off, or chunks of another experiment (another key).
    """
    if int(chunk) < 1:
        raise ConfigError(f"chunk_size = {chunk} is out of range: allowed >= 1")
    plan = ChunkPlan(key, int(n), int(chunk))
    if out_dir is None:
        return plan
    old = ChunkPlan.load(out_dir)
    has_chunks = any((Path(out_dir) / "chunks").glob("part-*.parquet"))
    if has_chunks and not resume:
        raise ConfigError(
            f"{out_dir} holds results of an earlier run: pass --resume to continue it, "
            "or choose another --out"
        )
    if has_chunks and old is None:
        raise ConfigError(
            f"{out_dir} holds chunks without a chunk plan (an older mjx-pick wrote them); "
            "they cannot be resumed: choose another --out or pass --overwrite"
        )
    if has_chunks and (old.key != key or old.n != plan.n):
        raise ConfigError(
            f"{out_dir} holds a run with a different configuration; it cannot be resumed "
            "with these settings (choose another --out)"
        )
    if has_chunks:
        return old  # chunk k on disk keeps its meaning
    plan.save(out_dir)
    return plan


def read_chunk(out_dir: Path, k: int, picks: PickBatch) -> pa.Table | None:
    """Chunk k from disk, or None when it is not there; checked against its pick-points."""
    path = chunk_path(out_dir, k)
    if not path.is_file():
        return None
    try:
        table = pq.read_table(path)
        ids = np.asarray(table["pick_id"])
    except (OSError, KeyError, pa.ArrowException) as err:
        _unreadable(path, err)
        return None
    if len(ids) != len(picks) or not np.array_equal(ids, picks.pick_id):
        raise ConfigError(
            f"{path} does not hold the pick-points of chunk {k}: choose another --out"
        )
    return table


def _unreadable(path: Path, err: BaseException) -> None:
    """Say that a saved chunk cannot be read (a disk error, a copy cut short): it is
    simulated again and written over, atomically."""
    print(
        f"mjx-pick: {path}: unreadable chunk ({type(err).__name__}: {err}); simulating it again",
        file=sys.stderr,
    )


def open_study_store(
    out: str | Path | None, command: str, request: dict, *, resume: bool, overwrite: bool
) -> tuple[ChunkStore | None, bool]:
    """A resumable study's output folder (sweep, compare), before it simulates: the
    folder claimed for command under request's configuration key and its
    :class:`ChunkStore` -- or, on resume, whether the folder already holds this study
    complete (the caller reads it back and simulates nothing). Returns (store,
    complete); (None, False) without out."""
    if out is None:
        return None, False
    key = config_hash(request)
    if resume and not overwrite and is_complete(out, command, key):
        return None, True
    claim(out, command, key, resume=resume, overwrite=overwrite, settings=request)
    return ChunkStore(out, key, resume), False


class ChunkStore:
    """A study's finished chunks in its output folder (sweep, compare): what lets a
    killed or stopped run continue with ``resume`` instead of starting again.

    :meth:`Engine.run` asks the store (through :meth:`scene`'s view) for each chunk
    before simulating it and saves each chunk it simulates, atomically, as
    ``chunks/<digest>.npz``: the chunk's result arrays, named by a digest of what decides
    them -- the compiled simulation's structure (``Settings.structure``: gripper,
    solver, scan length, grasp height; the object is the folder's, fixed by its
    configuration key), the backend, its batch size (the float32 rounding of a batched
    program depends on its shape: module docstring) and the chunk's per-pick inputs
    (pose, contact, controller). A chunk is read back exactly when the same backend
    simulated the same inputs in the same structure; whether that ran in this process
    or on a Ray cluster makes no difference. The chunk size of each structure is saved
    (``chunks/store.json``) on first use and kept by a resumed run, so that the chunks
    cut the same way, whatever the new start (another cluster size, another device's
    memory) would choose.

    Args:
      out_dir: the study's output folder (already claimed: ``rundir.claim``).
      key: the study's configuration key (the folder's manifest's).
      resume: continue from the chunks there; without it, a folder that holds chunks
        is refused (ConfigError) before anything is simulated.
    """

    def __init__(self, out_dir: str | Path, key: str, resume: bool = False):
        self.dir = Path(out_dir) / "chunks"
        self.key = key
        meta = self.dir / "store.json"
        has_chunks = any(self.dir.glob("*.npz"))
        saved = None
        if meta.is_file():
            try:
                saved = json.loads(meta.read_text())
            except ValueError as err:
                raise ConfigError(f"{meta}: unreadable ({err}); choose another --out") from err
        if has_chunks and not resume:
            raise ConfigError(
                f"{out_dir} holds results of an earlier run: pass --resume to continue it, "
                "or choose another --out"
            )
        if has_chunks and (saved is None or saved.get("key") != key):
            raise ConfigError(
                f"{out_dir} holds a run with a different configuration; it cannot be resumed "
                "with these settings (choose another --out)"
            )
        self.sizes: dict[str, int] = dict(saved["chunk_sizes"]) if has_chunks else {}
        self.read_chunks = self.written_chunks = 0

    def scene(self, backend: Backend, structure: tuple) -> StoredScene:
        """The store as :meth:`Engine.run` uses it for backend, whose compiled
        simulation is settings' ``structure()``."""
        h = hashlib.sha256(json.dumps(to_dict(structure), sort_keys=True, default=str).encode())
        # a Ray backend's calls are actor batches (its batch_size is one per actor)
        batch = getattr(backend, "call_batch_size", backend.batch_size)
        h.update(f"{backend.name}/{batch}".encode())
        return StoredScene(self, h.hexdigest()[:16])

    def remove(self) -> None:
        """Drop the chunks once the study's outputs are written (they hold every row)."""
        shutil.rmtree(self.dir, ignore_errors=True)


@dataclasses.dataclass(frozen=True)
class StoredScene:
    """A :class:`ChunkStore` seen from one compiled simulation (:meth:`ChunkStore.scene`)."""

    store: ChunkStore
    base: str  # digest of the structure, backend and batch size

    def chunk_size(self, proposed: int) -> int:
        """This scene's chunk size: the saved one, else proposed (then saved)."""
        sizes = self.store.sizes
        if self.base not in sizes:
            sizes[self.base] = int(proposed)
            meta = {"key": self.store.key, "chunk_sizes": sizes}
            write_json(self.store.dir / "store.json", meta)
        return sizes[self.base]

    def _path(self, inputs: PickInputs) -> Path:
        h = hashlib.sha256(self.base.encode())
        for leaf in jax.tree.leaves(inputs):
            a = np.ascontiguousarray(leaf)
            h.update(f"{a.dtype.str}{a.shape}".encode())
            h.update(a.tobytes())
        return self.store.dir / f"{h.hexdigest()[:32]}.npz"

    def read(self, inputs: PickInputs) -> dict | None:
        """The saved results of this chunk ((N,) arrays), or None."""
        path = self._path(inputs)
        if not path.is_file():
            return None
        try:
            with np.load(path) as data:
                out = {k: data[k] for k in data.files}
        except (OSError, ValueError, EOFError, zipfile.BadZipFile) as err:
            _unreadable(path, err)
            return None
        if any(len(v) != len(inputs) for v in out.values()):
            raise ConfigError(f"{path} does not hold this chunk's results: choose another --out")
        self.store.read_chunks += 1
        return out

    def write(self, inputs: PickInputs, results: dict) -> None:
        """Save a simulated chunk's results (atomically)."""
        buf = io.BytesIO()
        np.savez(buf, **results)
        write_atomic(self._path(inputs), buf.getvalue())
        self.store.written_chunks += 1


def run_chunks(
    executor: ChunkExecutor,
    picks: PickBatch,
    plan: ChunkPlan,
    out_dir: Path | None = None,
    on_progress: ProgressFn | None = None,
    on_chunk: Callable[[ChunkDone], None] | None = None,
) -> pa.Table:
    """Simulate picks chunk by chunk into a results table (``metrics.COLUMNS``).

    Chunk k holds picks ``[k * plan.chunk_size, (k + 1) * plan.chunk_size)``. With
    out_dir, each finished chunk is written at once (atomically) to :func:`chunk_path`
    by this process alone; a chunk file already there (an earlier, interrupted run of
    the same plan) is read instead of simulated. The executor may finish chunks in any
    order; the table is in pick-point order.

    on_progress(done, total): pick-points finished (read or simulated) of len(picks),
    once before the first chunk and after each one. on_chunk: each simulated chunk.
    """
    n = len(picks)
    if plan.n != n:
        raise ValueError(f"the chunk plan is for {plan.n} pick-points, not {n}")
    if jax.process_count() > 1:
        raise ConfigError(
            "evaluate runs one driver process: spread a run over machines with --ray "
            "(docs/cluster.md), not jax.distributed"
        )
    size = plan.chunk_size
    chunks = {k: picks.take(slice(k * size, (k + 1) * size)) for k in range(plan.n_chunks)}
    parts: dict[int, pa.Table] = {}
    done = 0
    if on_progress is not None:
        on_progress(0, n)
    for k, sub in chunks.items():
        table = read_chunk(out_dir, k, sub) if out_dir is not None else None
        if table is not None:
            parts[k] = table  # finished by an earlier run: reported as it is read
            done += len(sub)
            if on_progress is not None:
                on_progress(done, n)
    todo = {k: sub for k, sub in chunks.items() if k not in parts}
    for result in executor.run(todo) if todo else ():
        parts[result.k] = result.table
        if out_dir is not None:
            write_parquet(chunk_path(out_dir, result.k), result.table)
        done += len(chunks[result.k])
        if on_chunk is not None:
            on_chunk(result)
        if on_progress is not None:
            on_progress(done, n)
    missing = sorted(set(chunks) - set(parts))
    if missing:
        raise RuntimeError(f"the executor left chunks {missing[:8]} unfinished")
    return pa.concat_tables([parts[k] for k in range(plan.n_chunks)])


def _quiet(done: int, total: int) -> None:
    """No progress (the caller reports it in its own terms)."""
