"""Ray: the runner's chunks on the actors of a Ray cluster.

Details: docs/engine.md (engine/cluster.py).
"""

from __future__ import annotations

import collections
import dataclasses
import logging
import os
import re
import signal
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np

from mjx_pick.core.config import ConfigError
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import interrupts, registry
from mjx_pick.engine.backend import RunStats
from mjx_pick.engine.runner import Cancelled, ChunkDone, Runner
from mjx_pick.outputs.rundir import versions

INSTALL_HINT = "pip install 'mjx-pick[cluster]'"
# versions that must agree between driver and actors for results to be those of one
# machine (the physics, the array code, this package)
SAME_VERSIONS = ("mjx-pick", "mujoco", "mujoco-mjx", "jax", "jaxlib", "numpy")
_ADDRESS = re.compile(r"(ray://)?(\[[0-9A-Fa-f:]+\]|[A-Za-z0-9._-]+):(\d{1,5})")


def import_ray():
    """The ray module, or a ConfigError naming the extra that installs it."""
    try:
        import ray
    except ImportError as err:
        raise ConfigError(f"--ray needs Ray, which is not installed: {INSTALL_HINT}") from err
    return ray


def check_address(address: str) -> str:
    """A cluster address as given: 'auto', 'HOST:PORT' or 'ray://HOST:PORT'."""
    text = str(address).strip()
    if text == "auto":
        return text
    m = _ADDRESS.fullmatch(text)
    if not m or not 1 <= int(m[3]) <= 65535:
        raise ConfigError(
            f"--ray {address!r} is not a cluster address: use auto, HOST:PORT (the head's "
            "port, 6379 by default) or ray://HOST:PORT"
        )
    return text


def _probe(address: str, timeout_s: float = 5.0) -> None:
    """Fail in seconds, with one line, when nothing listens at address (ray.init would
    retry for a long time before saying so)."""
    m = _ADDRESS.fullmatch(address)
    host, port = m[2].strip("[]"), int(m[3])
    try:
        socket.create_connection((host, port), timeout=timeout_s).close()
    except OSError as err:
        raise ConfigError(
            f"--ray {address}: no Ray cluster answers there ({err.strerror or err}); start "
            "one with `ray start --head` (docs/cluster.md)"
        ) from err


def connect(address: str) -> bool:
    """Connect this process to the cluster at address; True when this call connected
    (and the caller should disconnect), False when it already was connected."""
    address = check_address(address)
    ray = import_ray()
    if address != "auto":
        _probe(address)
    if ray.is_initialized():
        # the caller's own connection (a script that ran ray.init, another run's pool)
        # is used; a HOST:PORT must name that cluster (its GCS port)
        gcs = ray.get_runtime_context().gcs_address or ""
        head = address != "auto" and not address.startswith("ray://")
        if head and gcs.rpartition(":")[2] != address.rpartition(":")[2]:
            raise ConfigError(
                f"--ray {address}: this process is already connected to the Ray cluster "
                f"at {gcs}; use that one, or run from another process"
            )
        return False
    try:
        ray.init(
            address=address,
            logging_level=logging.WARNING,
            log_to_driver=False,  # actors print nothing of use; errors come back as values
        )
    except (ConnectionError, RuntimeError, ValueError, TimeoutError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise ConfigError(
            f"--ray {address}: cannot connect to a Ray cluster ({first}); start one with "
            "`ray start --head` (docs/cluster.md)"
        ) from err
    return True


# --------------------------------------------------------------------------- actors


@dataclasses.dataclass(frozen=True)
class Simulated:
    """What :meth:`_Worker.simulate` returns: one piece of a backend call."""

    results: dict  # (N,) numpy arrays (kernels.grasp.finalize)
    traces: np.ndarray | None  # (N, T, F) with record, else None
    compile_s: float
    run_s: float
    wall_s: float
    where: str  # the node's label


class _Worker:
    """The body of one Ray actor: backends on one node (all its CPUs) or one GPU.

    Scenes arrive by reference with each call, boxed in a list so that Ray does not
    fetch them: the actor fetches a scene once, the first time its key is seen, and
    keeps its backend (and so its compiled programs) for the calls that follow.

    Args:
      backend: a backend's name (resolved by the driver).
      batch_size: simulations per backend call.
      nthread: a CPU backend's threads (a CPU node's CPUs).
    """

    KEEP = 4  # backends kept (a sweep over gripper geometry has one scene per value)

    def __init__(self, backend: str, batch_size: int, nthread: int):
        import ray

        self.backend_name, self.batch_size, self.nthread = backend, batch_size, nthread
        self._locals: dict = {}  # scene key -> the chunks of a runner of its own
        node = ray.get_runtime_context().get_node_id()
        # two nodes can share a host (tests, benchmarks): the node id tells them apart
        self.label = f"{socket.gethostname()}/{node[:6]}"
        self.node_id = node

    def info(self) -> dict:
        """Where this actor runs and what it runs: node id and label, pid, the versions
        that decide results."""
        return {
            "node_id": self.node_id,
            "label": self.label,
            "pid": os.getpid(),
            "versions": {k: v for k, v in versions().items() if k in SAME_VERSIONS},
        }

    def _local(self, key: str, box: list, grasp: GraspConfig):
        if key not in self._locals:
            import ray

            scene = ray.get(box[0])
            runner = Runner(self.backend_name, self.batch_size, nthread=self.nthread)
            if len(self._locals) >= self.KEEP:
                self._locals.pop(next(iter(self._locals)))
            self._locals[key] = runner.chunks(runner.make(scene, grasp), grasp)
        return self._locals[key]

    def run_chunk(self, key: str, box: list, grasp: GraspConfig, k: int, picks: GraspBatch):
        """Chunk k (its pick-points) of the scene under key, simulated into result rows."""
        done = next(self._local(key, box, grasp).run({k: picks}))
        return dataclasses.replace(done, where=self.label)

    def record(self, key: str, box: list, grasp: GraspConfig, picks: GraspBatch) -> np.ndarray:
        """Traces (N, T, F) of picks."""
        return self._local(key, box, grasp).record(picks)

    def simulate(self, key: str, box: list, grasp: GraspConfig, inputs, record: bool):
        """A backend call on prepared inputs (``backend.PickInputs``): :class:`Simulated`."""
        t0 = time.perf_counter()
        out = self._local(key, box, grasp).simulate(inputs, record)
        t = out.timing
        wall = time.perf_counter() - t0
        return Simulated(out.results, out.traces, t.compile_s, t.run_s, wall, self.label)


@dataclasses.dataclass(frozen=True)
class ClusterEvent:
    """One step of the driver's work on the cluster, as the runner's actor pool reports it to
    its ``on_event`` callback (for a display of the nodes, for tests that act at a given
    point of a run). The callback runs in the driver's loop: while it runs, nothing is
    handed out or collected (the actors go on with the calls they hold).

    kind is one of

    * ``'actor_started'``: an actor was placed on node_id (at the start, on a node that
      joined, or in place of one that died); ``ready`` is an ObjectRef that resolves
      once the actor answers (``ray.get(event.ready)`` waits for it);
    * ``'actor_ready'``: that actor answered; it takes calls from now on;
    * ``'actor_lost'``: an actor died before it answered (its node left, or it failed
      to start);
    * ``'call_sent'``, ``'call_done'``: call ``key`` (evaluate: the chunk's index) was
      handed to the actor on node_id, or came back from it;
    * ``'call_lost'``: call ``key`` was lost with its actor; it goes back to the front of
      the queue and runs on another actor.
    """

    kind: str
    node_id: str  # Ray's node id (hex)
    label: str = ""  # 'host/3f2a1b', once the node's actor answered
    key: object = None  # the call, for the call_* kinds
    inflight: int = 0  # calls the actor holds after this event
    ready: object = None  # actor_started: the ObjectRef of its first answer


@dataclasses.dataclass
class _Slot:
    """Where one actor goes, and the actor once started."""

    node_id: str
    num_cpus: float
    num_gpus: float
    nthread: int
    actor: object = None
    info: dict | None = None  # _Worker.info once it answered
    ready_ref: object = None  # its pending info() call
    inflight: int = 0


def cluster_backend(name: str, nodes: list[dict]) -> str:
    """The backend a cluster runs: 'auto' resolved for the cluster's GPUs
    (``registry.resolve``); a backend that needs an NVIDIA GPU needs one there."""
    gpus = int(sum(n["Resources"].get("GPU", 0) for n in nodes))
    name = registry.resolve(name, gpus=gpus)
    if registry.ENTRIES[name].device is registry.Device.NVIDIA_GPU and not gpus:
        cpu = [e.name for e in registry.auto_order() if e.device is registry.Device.CPU]
        raise ConfigError(
            f"--backend {name} --ray: the cluster has no GPU; use --backend "
            f"{' or '.join(cpu)} (or {registry.AUTO})"
        )
    return name


def plan_slots(backend: str, node: dict) -> list[_Slot]:
    """The actors a node gets: one per GPU for a device backend (where it has GPUs),
    none for a GPU backend where it has none, else one for the whole node (a CPU
    backend's threads on all its CPUs)."""
    res = node["Resources"]
    cpus, gpus = int(res.get("CPU", 0)), int(res.get("GPU", 0))
    nid = node["NodeID"]
    device = registry.ENTRIES[backend].device
    if device is not registry.Device.CPU and gpus:
        return [_Slot(nid, cpus // gpus, 1, max(cpus // gpus, 1)) for _ in range(gpus)]
    if device is registry.Device.NVIDIA_GPU or cpus < 1:
        return []  # no GPU for a GPU backend here; or a node with nothing to run on
    return [_Slot(nid, cpus, 0, cpus)]


class _ActorPool:
    """The actors of one run on a Ray cluster, and the fault-tolerant loop that feeds
    them (module docstring). Made, it has connected, resolved the backend and checked
    the cluster (a bad address, a missing Ray: one line before any simulation); actors
    start on the first :meth:`map`.

    Args:
      address: 'auto' or 'HOST:PORT' / 'ray://HOST:PORT' of the cluster's head.
      backend: 'auto' or a backend's name (:func:`cluster_backend`).
      batch_size: simulations per backend call on each actor.
      cancel: once set, :meth:`map` stops with ``runner.Cancelled``.
      depth: calls queued on each actor (2: the next one is there while the driver
        handles the last).
      max_attempts: runs of one call that may end in a dead actor before the run fails
        (a call that kills every actor it meets is a bug, not bad luck); also the
        actors a node may lose before it is left alone.
      start_timeout_s: how long to wait for the first actor to start.
      on_event: called with a :class:`ClusterEvent` at each actor start and answer,
        and each call sent, done or lost.
    """

    def __init__(
        self,
        address: str,
        *,
        backend: str = registry.AUTO,
        batch_size: int | None = None,
        cancel: threading.Event | None = None,
        depth: int = 2,
        max_attempts: int = 3,
        start_timeout_s: float = 600.0,
        on_event: Callable[[ClusterEvent], None] | None = None,
    ):
        self.address = check_address(address)
        self.on_event = on_event
        self.slots: list[_Slot] = []
        self._connected = connect(self.address)
        self._ray = import_ray()
        try:
            nodes = self._alive_nodes()
            self.name = cluster_backend(backend, nodes)
            gpus = any(n["Resources"].get("GPU", 0) for n in nodes)
            # per actor: one GPU each, or one node's CPUs
            self.batch_size = (
                int(batch_size)
                if batch_size
                else registry.default_batch_size(self.name, gpus=int(gpus), accelerator=gpus)
            )
            self.planned = sum(len(plan_slots(self.name, n)) for n in nodes)
            if not self.planned:
                raise ConfigError(f"--ray {self.address}: no node can run backend {self.name!r}")
        except BaseException:
            self.close()
            raise
        self.cancel = cancel
        self.depth, self.max_attempts, self.start_timeout_s = depth, max_attempts, start_timeout_s
        self._scenes: dict[int, tuple[str, list, Scene]] = {}
        self._actor_class = None
        self._deaths: collections.Counter = collections.Counter()  # per node id
        self._given_up: set[str] = set()  # nodes whose actors died too often
        self._last_scan = 0.0
        # accounting: per node label, and in all
        self.node_picks: collections.Counter = collections.Counter()  # label -> picks
        self.node_busy_s: collections.Counter = collections.Counter()  # label -> s
        self.compile_s = self.run_s = 0.0
        self.simulated = 0
        self.lost = 0  # calls that were re-run because their actor died
        self.last_error = ""  # why the last actor that died while starting died
        self.t0: float | None = None

    @property
    def device(self) -> str:
        ready = [s for s in self.slots if s.info is not None]
        nodes = len({s.node_id for s in ready})
        kind = (
            "gpu: 1 GPU each"
            if registry.ENTRIES[self.name].device is not registry.Device.CPU
            and any(s.num_gpus for s in ready)
            else "cpu: threads = the node's CPUs"
        )
        return f"ray: {nodes} nodes, {len(ready)} actors ({kind})"

    def backend(self, scene: Scene, grasp: GraspConfig) -> _RayBackend:
        """A backend for scene and grasp whose calls run on the actors."""
        return _RayBackend(self, scene, grasp)

    def chunks(self, scene: Scene, grasp: GraspConfig) -> _RayChunks:
        """Whole chunks of scene and grasp, one per actor call."""
        return _RayChunks(self, scene, grasp)

    def scene_box(self, scene: Scene) -> tuple[str, list]:
        """(key, [ObjectRef]) of a scene in the object store, put there once."""
        entry = self._scenes.get(id(scene))
        if entry is None or entry[2] is not scene:
            key = f"scene-{len(self._scenes)}"
            entry = (key, [self._ray.put(scene)], scene)
            self._scenes[id(scene)] = entry
        return entry[0], entry[1]

    # ------------------------------------------------------------------ actors

    def _alive_nodes(self) -> list[dict]:
        return [n for n in self._ray.nodes() if n.get("Alive")]

    def _start(self, slot: _Slot) -> None:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        ray = self._ray
        if self._actor_class is None:
            self._actor_class = ray.remote(_Worker)
        slot.actor = self._actor_class.options(
            num_cpus=slot.num_cpus,
            num_gpus=slot.num_gpus,
            max_restarts=0,  # the driver replaces dead actors itself (and counts them)
            scheduling_strategy=NodeAffinitySchedulingStrategy(slot.node_id, soft=False),
        ).remote(self.name, self.batch_size, slot.nthread)
        slot.ready_ref = slot.actor.info.remote()
        self.slots.append(slot)
        self._emit("actor_started", slot, ready=slot.ready_ref)

    def _emit(self, kind: str, slot: _Slot, **fields) -> None:
        if self.on_event is not None:
            label = slot.info["label"] if slot.info else ""
            self.on_event(ClusterEvent(kind, slot.node_id, label, inflight=slot.inflight, **fields))

    def _scan(self, force: bool = False) -> None:
        """Start the actors alive nodes lack (at the start, nodes that joined, nodes one
        of whose actors died: a node of several GPUs keeps one actor per GPU); at most
        every 2 s unless forced."""
        now = time.monotonic()
        if not force and now - self._last_scan < 2.0:
            return
        self._last_scan = now
        for node in self._alive_nodes():
            nid = node["NodeID"]
            if nid in self._given_up:
                continue
            have = sum(s.node_id == nid for s in self.slots)
            for slot in plan_slots(self.name, node)[have:]:
                self._start(slot)

    def _check_ready(self) -> None:
        """Collect the info of actors that finished starting; a version mismatch is an
        error (results would not be those of one machine)."""
        ray = self._ray
        for slot in [s for s in self.slots if s.info is None and s.ready_ref is not None]:
            done, _ = ray.wait([slot.ready_ref], timeout=0)
            if not done:
                continue
            try:
                slot.info = ray.get(slot.ready_ref)
            except self._lost_errors() as err:
                # an actor that dies while starting says why (an import error, a
                # constructor's exception): kept for the error if no actor is left
                self.last_error = str(err).strip().splitlines()[-1] if str(err).strip() else ""
                self._drop(slot)
                self._emit("actor_lost", slot)
                continue
            mine = {k: v for k, v in versions().items() if k in SAME_VERSIONS}
            if slot.info["versions"] != mine:
                theirs = slot.info["versions"]
                diff = ", ".join(
                    f"{k} {theirs.get(k)} (driver: {mine[k]})"
                    for k in mine
                    if theirs.get(k) != mine[k]
                )
                raise ConfigError(
                    f"node {slot.info['label']} runs {diff}: install the same versions on "
                    "every node"
                )
            self._emit("actor_ready", slot)

    def _drop(self, slot: _Slot) -> None:
        """Forget a dead actor; its node gets a new one unless it failed too often."""
        self._kill(slot)
        if slot in self.slots:
            self.slots.remove(slot)
        self._deaths[slot.node_id] += 1
        if self._deaths[slot.node_id] >= self.max_attempts:
            self._given_up.add(slot.node_id)
        self._last_scan = 0.0  # rescan at once: the node may be gone, or need a new actor

    def _kill(self, slot: _Slot) -> None:
        try:
            self._ray.kill(slot.actor)
        except Exception:  # noqa: BLE001 -- already dead, or its node gone: nothing to end
            pass

    def _lost_errors(self) -> tuple[type, ...]:
        """Exceptions that mean an actor (or its node, or its results) is gone."""
        ex = self._ray.exceptions
        # ActorUnschedulableError: an actor placed on a node that left before it started
        names = (
            "RayActorError",
            "ActorUnschedulableError",
            "WorkerCrashedError",
            "NodeDiedError",
            "ObjectLostError",
        )
        return tuple(getattr(ex, n) for n in names if hasattr(ex, n))

    # ------------------------------------------------------------------ calls

    def map(self, calls: dict, sizes: dict[object, int]) -> Iterator[tuple[object, object]]:
        """Run calls on the actors; yield (key, result) as each finishes, in any order.

        Args:
          calls: key -> (_Worker method name, its arguments).
          sizes: key -> pick-points the call simulates (for the accounting).

        A call whose actor dies goes back to the front of the queue (a new actor starts
        on the node if it is still there); any other error of a call ends the run with
        that error (it would happen again anywhere).
        """
        ray = self._ray
        lost = self._lost_errors()
        queue = collections.deque(calls)
        attempts: collections.Counter = collections.Counter()
        inflight: dict = {}  # ObjectRef -> (key, slot)
        if self.t0 is None:
            self.t0 = time.monotonic()
        started = time.monotonic()
        self._scan(force=True)
        while queue or inflight:
            if self.cancel is not None and self.cancel.is_set():
                raise Cancelled("cancelled")
            interrupts.raise_if_requested()  # a Ctrl-C swallowed while waiting on Ray
            self._scan()
            self._check_ready()
            ready = [s for s in self.slots if s.info is not None]
            self._check_actors_left(ready, inflight, started)
            self._send(calls, queue, ready, inflight)
            if not inflight:
                time.sleep(0.1)  # actors still starting
                continue
            done, _ = ray.wait(list(inflight), num_returns=1, timeout=0.5)
            for ref in done:
                key, slot = inflight.pop(ref)
                slot.inflight -= 1
                try:
                    result = ray.get(ref)
                except lost:
                    # the actor (or its node) died with this call: run it elsewhere
                    self._requeue(key, slot, queue, attempts)
                    continue
                self._account(key, slot, result, sizes[key])
                yield key, result

    def _check_actors_left(self, ready: list[_Slot], inflight: dict, started: float) -> None:
        """RuntimeError when no actor is left to run on (every node failed or left), or
        none has started within start_timeout_s of started (time.monotonic())."""
        if not self.slots and not inflight:
            why = f"; the last actor that died said: {self.last_error}" if self.last_error else ""
            raise RuntimeError(
                f"no Ray actor is left to run backend {self.name!r}: every node failed "
                f"{self.max_attempts} times or left the cluster{why}"
            )
        if not ready and not inflight and time.monotonic() - started > self.start_timeout_s:
            raise RuntimeError(
                f"no Ray actor started within {self.start_timeout_s:.0f} s: does any node "
                f"have the resources for one ({self.name}; `ray status`)?"
            )

    def _send(self, calls: dict, queue: collections.deque, ready: list[_Slot], inflight: dict):
        """Send queued calls to the ready actors that have room (fewer than depth calls),
        the least busy first; each sent call goes into inflight (ObjectRef -> (key, slot))."""
        while queue:
            # the least busy actor first: one that just started (a node that joined,
            # a replacement) gets work at once instead of what busy ones leave
            free = [s for s in ready if s.inflight < self.depth]
            if not free:
                break
            slot = min(free, key=lambda s: s.inflight)
            key = queue.popleft()
            method, args = calls[key]
            ref = getattr(slot.actor, method).remote(*args)
            inflight[ref] = (key, slot)
            slot.inflight += 1
            self._emit("call_sent", slot, key=key)

    def _requeue(self, key, slot: _Slot, queue: collections.deque, attempts) -> None:
        """Put a call lost with its actor back at the front of the queue and drop the
        actor; RuntimeError once it was lost max_attempts times."""
        attempts[key] += 1
        self.lost += 1
        if attempts[key] >= self.max_attempts:
            raise RuntimeError(
                f"call {key!r} was lost with its actor {attempts[key]} times: see "
                "the Ray logs of its nodes (`ray logs`)"
            ) from None
        queue.appendleft(key)
        if slot in self.slots:
            self._drop(slot)
        self._emit("call_lost", slot, key=key)

    def _account(self, key, slot: _Slot, result, picks: int) -> None:
        """Count a finished call's pick-points and times against its node and the run."""
        wall = getattr(result, "wall_s", 0.0)
        label = slot.info["label"]
        self.node_picks[label] += picks
        self.node_busy_s[label] += wall
        self.compile_s += getattr(result, "compile_s", 0.0)
        self.run_s += getattr(result, "run_s", 0.0)
        self.simulated += picks
        self._emit("call_done", slot, key=key)

    def call(self, method: str, args: tuple):
        """One call on one actor (another if it dies): its result."""
        for _, result in self.map({0: (method, args)}, {0: 0}):
            return result

    # ------------------------------------------------------------------ reporting

    def rates(self) -> dict[str, float]:
        """Pick-points per second of each node (over the time its actor was busy,
        compiles included) and, under 'total', of the whole cluster (over the wall time
        since the first call)."""
        out = {
            label: self.node_picks[label] / busy
            for label, busy in sorted(self.node_busy_s.items())
            if busy > 0
        }
        if self.t0 is not None and self.simulated:
            out["total"] = self.simulated / max(time.monotonic() - self.t0, 1e-9)
        return out

    def progress_note(self) -> str:
        """Rates for a progress bar: 'host/3f2a1b 80/s, host/9c0d2e 78/s, all 150/s'."""
        r = self.rates()
        total = r.pop("total", None)
        parts = [f"{label} {v:.0f}/s" for label, v in r.items()]
        if total is not None:
            parts.append(f"all {total:.0f}/s")
        return ", ".join(parts)

    def summary(self) -> dict:
        """For summary.json: address, nodes with their pick-points and rates, calls
        (chunks) re-run after an actor died."""
        rates = self.rates()
        return {
            "address": self.address,
            "nodes": {
                label: {"picks": int(n), "picks_per_s": round(rates.get(label, 0.0), 2)}
                for label, n in sorted(self.node_picks.items())
            },
            "picks_per_s": round(rates["total"], 2) if "total" in rates else None,
            "chunks_rerun": int(self.lost),
        }

    def close(self) -> None:
        """End this run's actors, and disconnect when this pool connected."""
        for slot in list(self.slots):
            self._kill(slot)
        self.slots.clear()
        if self._connected:
            self._ray.shutdown()
            self._connected = False


class _RayChunks:
    """A runner's chunks on a Ray cluster (``Runner.chunks``): each chunk is one call on
    one actor; the driver writes every chunk as it comes back."""

    def __init__(self, pool: _ActorPool, scene: Scene, grasp: GraspConfig):
        self.pool, self.scene, self.grasp = pool, scene, grasp
        self.address, self.name, self.batch_size = pool.address, pool.name, pool.batch_size

    @property
    def device(self) -> str:
        return self.pool.device

    def run(self, chunks: dict[int, GraspBatch]) -> Iterator[ChunkDone]:
        """Simulate chunks on the cluster's actors, yielding each as it finishes."""
        key, box = self.pool.scene_box(self.scene)
        calls = {k: ("run_chunk", (key, box, self.grasp, k, sub)) for k, sub in chunks.items()}
        sizes = {k: len(sub) for k, sub in chunks.items()}
        for _, result in self.pool.map(calls, sizes):
            yield result

    def record(self, picks: GraspBatch) -> np.ndarray:
        """Traces (N, T, F) of picks, simulated on one actor."""
        key, box = self.pool.scene_box(self.scene)
        return self.pool.call("record", (key, box, self.grasp, picks))

    def progress_note(self) -> str:
        return self.pool.progress_note()

    def cluster_summary(self) -> dict:
        return self.pool.summary()

    def describe(self, wall_s: float | None = None) -> dict:
        """backend, device and timing (compile_s, run_s summed over actors)."""
        p = self.pool
        timing = {
            "compile_s": round(p.compile_s, 3),
            "run_s": round(p.run_s, 3),
            "simulations": int(p.simulated),
        }
        if wall_s is not None:
            timing["wall_s"] = round(wall_s, 3)
        return {"backend": self.name, "device": self.device, "timing": timing}


class _RayBackend:
    """A ``backend.Backend`` whose calls run on a Ray cluster: each call's inputs are
    cut into pieces of one actor batch, spread over the actors and put back in order.

    What a Ray runner makes for a scene: the studies (sweep, compare, ...) run their
    batches of pick-points x variants through it unchanged. ``batch_size`` is one batch
    per planned actor, so that each runner chunk keeps every actor busy.
    """

    def __init__(self, pool: _ActorPool, scene: Scene, grasp: GraspConfig):
        self.pool, self.scene, self.grasp = pool, scene, grasp
        self.name = pool.name
        self.batch_size = pool.batch_size * max(pool.planned, 1)
        self.call_batch_size = pool.batch_size  # the shape each actor runs
        self.stats = RunStats()

    @property
    def device(self) -> str:
        return self.pool.device

    def run(self, inputs, record: bool = False):
        """Per-pick results ((N,) arrays) and, with record, traces (N, T, F)."""
        key, box = self.pool.scene_box(self.scene)
        size = self.pool.batch_size
        n = len(inputs)
        starts = list(range(0, max(n, 1), size))
        calls = {
            i: ("simulate", (key, box, self.grasp, inputs.take(slice(s, s + size)), record))
            for i, s in enumerate(starts)
        }
        sizes = {i: min(size, n - s) for i, s in enumerate(starts)}
        parts: dict[int, Simulated] = dict(self.pool.map(calls, sizes))
        ordered = [parts[i] for i in range(len(starts))]
        results = {k: np.concatenate([p.results[k] for p in ordered]) for k in ordered[0].results}
        traces = np.concatenate([p.traces for p in ordered]) if record else None
        self.stats.compile_s += sum(p.compile_s for p in ordered)
        self.stats.run_s += sum(p.run_s for p in ordered)
        self.stats.n += n
        return results, traces


def ray_runner(
    address: str,
    backend: str = registry.AUTO,
    batch_size: int | None = None,
    *,
    chunk_size: int | None = None,
    on_progress=None,
    cancel: threading.Event | None = None,
    on_event: Callable[[ClusterEvent], None] | None = None,
) -> Runner:
    """A ``runner.Runner`` whose backends and chunks run on the Ray cluster at address
    ('auto' or 'HOST:PORT' / 'ray://HOST:PORT'). Everything else of the runner --
    chunks, progress, cancellation, timing -- is the runner's. The cluster is checked
    now (a bad address, a missing Ray: one line before any simulation); actors start on
    the first call. Call ``close()`` at the end (it ends the actors).

    backend: as :func:`cluster_backend`; batch_size: simulations per call on each actor;
    on_event: called with each :class:`ClusterEvent`, in the driver's loop.
    """
    pool = _ActorPool(
        address, backend=backend, batch_size=batch_size, cancel=cancel, on_event=on_event
    )
    return Runner(
        pool.name,
        pool.batch_size,
        chunk_size=chunk_size,
        on_progress=on_progress,
        cancel=cancel,
        cluster=pool,
    )


# ------------------------------------------------------- local clusters (one host)


def free_ports(n: int) -> list[int]:
    """n TCP ports free on this host now (for the nodes of a local cluster)."""
    socks = [socket.socket() for _ in range(n)]
    for s in socks:
        s.bind(("127.0.0.1", 0))
    ports = [s.getsockname()[1] for s in socks]
    for s in socks:
        s.close()
    return ports


def start_local_node(
    temp: Path,
    log: Path,
    head_port: int,
    head: bool,
    num_cpus: int = 1,
    env: dict | None = None,
) -> subprocess.Popen:
    """`ray start --block` for one node of a cluster on this host, in a session of its
    own (:func:`stop_local_node` ends it). For tests, benchmarks and trying ``--ray``
    on one machine; a real cluster starts its nodes with ``ray start`` (docs/cluster.md).

    Args:
      temp: the node's Ray temp folder (keep it short: Ray's socket paths must stay
        under 107 bytes).
      log: where the node's output goes.
      head_port: the head's GCS port (the cluster's address is 127.0.0.1:head_port).
      head: start the head (else a node that joins it).
      num_cpus: CPUs the node offers (its C-engine actor runs that many threads).
      env: variables set for the node and the actors it starts (JAX_PLATFORMS, ...).

    Every port a node opens is given: nodes that share a host would collide on the
    defaults (dashboard agent, metrics)."""
    p = free_ports(7)
    ray_bin = str(Path(sys.executable).with_name("ray"))  # the ray of this environment
    args = [
        ray_bin,
        "start",
        "--block",
        f"--num-cpus={num_cpus}",
        "--num-gpus=0",
        f"--temp-dir={temp}",
        "--disable-usage-stats",
        "--node-ip-address=127.0.0.1",
        f"--node-manager-port={p[0]}",
        f"--object-manager-port={p[1]}",
        f"--dashboard-agent-listen-port={p[2]}",
        f"--dashboard-agent-grpc-port={p[3]}",
        f"--metrics-export-port={p[4]}",
        f"--runtime-env-agent-port={p[5]}",
        f"--min-worker-port={p[6]}",
        f"--max-worker-port={p[6] + 30}",
    ]
    if head:
        args += ["--head", f"--port={head_port}", "--include-dashboard=false"]
    else:
        args += [f"--address=127.0.0.1:{head_port}"]
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", **(env or {})}
    with log.open("wb") as sink:
        return subprocess.Popen(
            args, stdout=sink, stderr=subprocess.STDOUT, env=env, start_new_session=True
        )


def session_pids(sid: int) -> list[int]:
    """Pids of the processes in session sid: a node's `ray start`, its raylet and the
    workers it spawned (those get process groups of their own, not sessions)."""
    pids = []
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                if os.getsid(int(entry.name)) == sid:
                    pids.append(int(entry.name))
            except OSError:
                continue  # ended while we looked
    return pids


def stop_local_node(proc: subprocess.Popen) -> None:
    """End one node: every process of the session its `ray start` opened, TERM then KILL."""
    for sig in (signal.SIGTERM, signal.SIGKILL):
        for pid in session_pids(proc.pid):
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        try:
            proc.wait(timeout=2)  # reaps `ray start` (a zombie would stay in the session)
        except subprocess.TimeoutExpired:
            continue
        deadline = time.monotonic() + 5
        while session_pids(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        if not session_pids(proc.pid):
            return
