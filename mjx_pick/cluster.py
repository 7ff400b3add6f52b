"""Ray as the distributed engine: the chunks of a run on the actors of a Ray cluster.

``evaluate(..., ray="auto" | "HOST:PORT")`` (``mjx-pick evaluate --ray``) runs its chunks
through a :class:`RayExecutor` instead of this process's backend. Who owns what
(docs/cluster.md says why):

* the driver (the process that called evaluate) owns the experiment: it draws the
  pick-points, cuts them into chunks (``engine.ChunkPlan``), hands chunks out, and is
  the only writer of the output folder -- every chunk file, the one results table,
  summary, config and traces;
* an actor (:class:`ChunkWorker`) owns a backend: one per GPU on GPU nodes (the GPU
  backend), one per node on CPU nodes (the MuJoCo C engine on all the node's CPUs). It
  gets the driver's compiled scene (the MjModel travels with it: no object, mesh or MJCF
  file has to exist on the node), simulates the chunks it is given through the same
  ``engine.LocalExecutor`` a single-machine run uses, and returns result rows.

Faults: an actor that dies (its process killed, its node gone) loses only the chunks it
held; they go back to the queue and run on another actor, and the driver starts a new
actor on that node if the node is still alive. Nodes that join during a run get actors.
A driver that dies loses only the chunks in flight: ``--resume`` reads the chunk files.

Ray is an optional dependency (``pip install 'mjx-pick[cluster]'``), imported only when
a run asks for a cluster.
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
from collections.abc import Iterator
from pathlib import Path

import numpy as np

from mjx_pick.config import ConfigError
from mjx_pick.engine import Cancelled, ChunkDone, Engine, LocalExecutor
from mjx_pick.grasp import GraspConfig
from mjx_pick.pickpoints import PickBatch
from mjx_pick.rundir import versions
from mjx_pick.scene import Scene
from mjx_pick.simulate import BACKENDS, default_batch_size

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
    if ray.is_initialized():
        return False  # the caller's own connection (a script that ran ray.init) is used
    if address != "auto":
        _probe(address)
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


class ChunkWorker:
    """The body of one Ray actor: a backend for the run's scene, on one node or GPU.

    Args:
      scene: the driver's scene (its compiled MjModel included).
      grasp: the procedure.
      backend: 'mujoco', 'warp' or 'mjx' (already resolved by the driver).
      batch_size: simulations per backend call.
      nthread: the C engine's threads (a CPU node's CPUs).
    """

    def __init__(
        self, scene: Scene, grasp: GraspConfig, backend: str, batch_size: int, nthread: int
    ):
        import ray

        self.engine = Engine(backend, batch_size, nthread=nthread)
        self.local = LocalExecutor(self.engine, self.engine.make(scene, grasp), grasp)
        node = ray.get_runtime_context().get_node_id()
        # two nodes can share a host (tests, benchmarks): the node id tells them apart
        self.label = f"{socket.gethostname()}/{node[:6]}"
        self.node_id = node

    def info(self) -> dict:
        """Where this actor runs and what it runs: node id and label, pid, device,
        the versions that decide results."""
        return {
            "node_id": self.node_id,
            "label": self.label,
            "pid": os.getpid(),
            "device": self.local.device,
            "versions": {k: v for k, v in versions().items() if k in SAME_VERSIONS},
        }

    def run(self, k: int, picks: PickBatch) -> ChunkDone:
        """Chunk k (its pick-points) simulated into result rows."""
        done = next(self.local.run({k: picks}))
        return dataclasses.replace(done, where=self.label)

    def record(self, picks: PickBatch) -> np.ndarray:
        """Traces (N, T, F) of picks."""
        return self.local.record(picks)


@dataclasses.dataclass
class _Slot:
    """Where one actor goes, and the actor once started."""

    node_id: str
    num_cpus: float
    num_gpus: float
    nthread: int
    actor: object = None
    info: dict | None = None  # ChunkWorker.info once it answered
    ready_ref: object = None  # its pending info() call
    inflight: int = 0


def cluster_backend(name: str, nodes: list[dict]) -> str:
    """The backend a cluster runs: 'auto' is 'warp' when the cluster has GPUs, else
    'mujoco' (the C engine); 'warp' needs GPUs."""
    if name not in BACKENDS:
        allowed = ", ".join(repr(b) for b in BACKENDS)
        raise ConfigError(f"backend = {name!r} is not allowed: choose one of {allowed}")
    gpus = sum(n["Resources"].get("GPU", 0) for n in nodes)
    if name == "auto":
        return "warp" if gpus else "mujoco"
    if name == "warp" and not gpus:
        raise ConfigError(
            "--backend warp --ray: the cluster has no GPU; use --backend mujoco (or auto)"
        )
    return name


def plan_slots(backend: str, node: dict) -> list[_Slot]:
    """The actors a node gets: one per GPU for the GPU backends (where it has GPUs), else
    one for the whole node (the C engine's threads on all its CPUs)."""
    res = node["Resources"]
    cpus, gpus = int(res.get("CPU", 0)), int(res.get("GPU", 0))
    nid = node["NodeID"]
    if backend in ("warp", "mjx") and gpus:
        return [_Slot(nid, cpus // gpus, 1, max(cpus // gpus, 1)) for _ in range(gpus)]
    if backend == "warp" or cpus < 1:
        return []  # no GPU for Warp here; or a node with nothing to run on
    return [_Slot(nid, cpus, 0, cpus)]


def _batch_size(backend: str, batch_size: int | None, gpus: bool) -> int:
    """Simulations per backend call on one actor (one GPU, or one node's CPUs)."""
    if batch_size:
        return int(batch_size)
    if backend == "mujoco":
        return default_batch_size("mujoco")
    if backend == "warp":
        return 32768  # one GPU's pool (simulate.default_batch_size, per GPU)
    return 8192 if gpus else 64


class RayExecutor:
    """Runs chunks on actors of a Ray cluster (engine.ChunkExecutor); see the module doc.

    Connecting, resolving the backend and checking the cluster happen here, so that a
    bad address, a missing Ray or an unreachable cluster is one line before any
    simulation. Actors start on the first :meth:`run` or :meth:`record`.

    Args:
      address: 'auto' or 'HOST:PORT' / 'ray://HOST:PORT' of the cluster's head.
      scene, grasp: what every chunk simulates.
      backend: 'auto', 'mujoco', 'warp' or 'mjx' (:func:`cluster_backend`).
      batch_size: simulations per backend call on each actor.
      cancel: once set, :meth:`run` stops with ``engine.Cancelled``.
      depth: chunks queued on each actor (2: the next chunk is there while the driver
        writes the last one).
      max_attempts: runs of one chunk that may end in a dead actor before the run fails
        (a chunk that kills every actor it meets is a bug, not bad luck).
      start_timeout_s: how long to wait for the first actor to start.
    """

    def __init__(
        self,
        address: str,
        scene: Scene,
        grasp: GraspConfig,
        *,
        backend: str = "auto",
        batch_size: int | None = None,
        cancel: threading.Event | None = None,
        depth: int = 2,
        max_attempts: int = 3,
        start_timeout_s: float = 600.0,
    ):
        self.address = check_address(address)
        self._connected = connect(self.address)
        self._ray = import_ray()
        try:
            nodes = self._alive_nodes()
            self.name = cluster_backend(backend, nodes)
            gpus = any(n["Resources"].get("GPU", 0) for n in nodes)
            self.batch_size = _batch_size(self.name, batch_size, gpus)
            if not any(plan_slots(self.name, n) for n in nodes):
                raise ConfigError(f"--ray {self.address}: no node can run backend {self.name!r}")
        except BaseException:
            self.close()
            raise
        self.scene, self.grasp, self.cancel = scene, grasp, cancel
        self.depth, self.max_attempts, self.start_timeout_s = depth, max_attempts, start_timeout_s
        self.slots: list[_Slot] = []
        self._scene_ref = None
        self._actor_class = None
        self._deaths: collections.Counter = collections.Counter()  # per node id
        self._given_up: set[str] = set()  # nodes whose actors died too often
        self._last_scan = 0.0
        # progress and timing
        self.node_picks: collections.Counter = collections.Counter()  # label -> picks
        self.node_busy_s: collections.Counter = collections.Counter()  # label -> s
        self.compile_s = self.run_s = 0.0
        self.simulated = 0
        self.lost_chunks = 0  # chunks that were re-run because their actor died
        self._t0: float | None = None

    @property
    def device(self) -> str:
        ready = [s.info for s in self.slots if s.info is not None]
        nodes = len({i["node_id"] for i in ready}) or len(self._alive_nodes())
        kinds = sorted({i["device"] for i in ready})
        return f"ray: {nodes} nodes, {len(ready)} actors" + (
            f" ({', '.join(kinds)})" if kinds else ""
        )

    # ------------------------------------------------------------------ actors

    def _alive_nodes(self) -> list[dict]:
        return [n for n in self._ray.nodes() if n.get("Alive")]

    def _start(self, slot: _Slot) -> None:
        from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

        ray = self._ray
        if self._scene_ref is None:
            self._scene_ref = ray.put(self.scene)  # once: every actor reads the same copy
        if self._actor_class is None:
            self._actor_class = ray.remote(ChunkWorker)
        slot.actor = self._actor_class.options(
            num_cpus=slot.num_cpus,
            num_gpus=slot.num_gpus,
            max_restarts=0,  # the driver replaces dead actors itself (and counts them)
            scheduling_strategy=NodeAffinitySchedulingStrategy(slot.node_id, soft=False),
        ).remote(self._scene_ref, self.grasp, self.name, self.batch_size, slot.nthread)
        slot.ready_ref = slot.actor.info.remote()
        self.slots.append(slot)

    def _scan(self, force: bool = False) -> None:
        """Start actors on alive nodes that have none (at the start, nodes that joined,
        nodes whose actor died); at most every 2 s unless forced."""
        now = time.monotonic()
        if not force and now - self._last_scan < 2.0:
            return
        self._last_scan = now
        for node in self._alive_nodes():
            nid = node["NodeID"]
            if nid in self._given_up or any(s.node_id == nid for s in self.slots):
                continue
            for slot in plan_slots(self.name, node):
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
            except self._lost_errors():
                self._drop(slot)
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

    def _drop(self, slot: _Slot) -> None:
        """Forget a dead actor; its node gets a new one unless it failed too often."""
        if slot in self.slots:
            self.slots.remove(slot)
        self._deaths[slot.node_id] += 1
        if self._deaths[slot.node_id] >= self.max_attempts:
            self._given_up.add(slot.node_id)
        self._last_scan = 0.0  # rescan at once: the node may be gone, or need a new actor

    def _lost_errors(self) -> tuple[type, ...]:
        """Exceptions that mean an actor (or its node, or its results) is gone."""
        ex = self._ray.exceptions
        names = ("RayActorError", "WorkerCrashedError", "NodeDiedError", "ObjectLostError")
        return tuple(getattr(ex, n) for n in names if hasattr(ex, n))

    # ------------------------------------------------------------------ chunks

    def run(self, chunks: dict[int, PickBatch]) -> Iterator[ChunkDone]:
        """Simulate chunks on the cluster's actors, yielding each as it finishes."""
        ray = self._ray
        lost = self._lost_errors()
        queue = collections.deque(sorted(chunks))
        attempts: collections.Counter = collections.Counter()
        inflight: dict = {}  # ObjectRef -> (k, slot)
        if self._t0 is None:
            self._t0 = time.monotonic()
        started = time.monotonic()
        self._scan(force=True)
        while queue or inflight:
            if self.cancel is not None and self.cancel.is_set():
                raise Cancelled("cancelled")
            self._scan()
            self._check_ready()
            ready = [s for s in self.slots if s.info is not None]
            if not ready and not any(s.ready_ref for s in self.slots) and not inflight:
                raise RuntimeError(
                    f"no Ray actor is left to run backend {self.name!r}: every node failed "
                    f"{self.max_attempts} times or left the cluster"
                )
            if not ready and not inflight and time.monotonic() - started > self.start_timeout_s:
                raise RuntimeError(
                    f"no Ray actor started within {self.start_timeout_s:.0f} s: does any node "
                    f"have the resources for one ({self.name}; `ray status`)?"
                )
            for slot in ready:
                while queue and slot.inflight < self.depth:
                    k = queue.popleft()
                    ref = slot.actor.run.remote(k, chunks[k])
                    inflight[ref] = (k, slot)
                    slot.inflight += 1
            if not inflight:
                time.sleep(0.1)  # actors still starting
                continue
            done, _ = ray.wait(list(inflight), num_returns=1, timeout=0.5)
            for ref in done:
                k, slot = inflight.pop(ref)
                slot.inflight -= 1
                try:
                    result = ray.get(ref)
                except lost:
                    # the actor (or its node) died with this chunk: run it elsewhere
                    attempts[k] += 1
                    self.lost_chunks += 1
                    if attempts[k] >= self.max_attempts:
                        raise RuntimeError(
                            f"chunk {k} was lost with its actor {attempts[k]} times: see the "
                            "Ray logs of its nodes (`ray logs`)"
                        ) from None
                    queue.appendleft(k)
                    if slot in self.slots:
                        self._kill(slot)
                        self._drop(slot)
                    continue
                self._count(result, len(chunks[k]))
                yield result

    def _count(self, result: ChunkDone, n: int) -> None:
        self.node_picks[result.where] += n
        self.node_busy_s[result.where] += result.wall_s
        self.compile_s += result.compile_s
        self.run_s += result.run_s
        self.simulated += n

    def record(self, picks: PickBatch) -> np.ndarray:
        """Traces (N, T, F) of picks, simulated on one actor (another if it dies)."""
        ray = self._ray
        lost = self._lost_errors()
        started = time.monotonic()
        while True:
            self._scan(force=not self.slots)
            self._check_ready()
            ready = [s for s in self.slots if s.info is not None]
            if not ready:
                if time.monotonic() - started > self.start_timeout_s or not self.slots:
                    raise RuntimeError("no Ray actor is left to record traces")
                time.sleep(0.1)
                continue
            slot = ready[0]
            try:
                return ray.get(slot.actor.record.remote(picks))
            except lost:
                self._kill(slot)
                self._drop(slot)

    def _kill(self, slot: _Slot) -> None:
        try:
            self._ray.kill(slot.actor)
        except Exception:  # noqa: BLE001 -- already dead, or its node gone: nothing to end
            pass

    # ------------------------------------------------------------------ reporting

    def rates(self) -> dict[str, float]:
        """Pick-points per second of each node (over the time its actor was busy) and,
        under 'total', of the whole cluster (over this run's wall time)."""
        out = {
            label: self.node_picks[label] / busy
            for label, busy in sorted(self.node_busy_s.items())
            if busy > 0
        }
        if self._t0 is not None and self.simulated:
            out["total"] = self.simulated / max(time.monotonic() - self._t0, 1e-9)
        return out

    def progress_note(self) -> str:
        """Rates for a progress bar: 'host/3f2a1b 80/s, host/9c0d2e 78/s, all 150/s'."""
        r = self.rates()
        total = r.pop("total", None)
        parts = [f"{label} {v:.0f}/s" for label, v in r.items()]
        if total is not None:
            parts.append(f"all {total:.0f}/s")
        return ", ".join(parts)

    def describe(self, wall_s: float | None = None) -> dict:
        """backend, device and timing (compile_s, run_s summed over actors)."""
        timing = {
            "compile_s": round(self.compile_s, 3),
            "run_s": round(self.run_s, 3),
            "simulations": int(self.simulated),
        }
        if wall_s is not None:
            timing["wall_s"] = round(wall_s, 3)
        return {"backend": self.name, "device": self.device, "timing": timing}

    def cluster_summary(self) -> dict:
        """For summary.json: address, nodes with their pick-points and rates, chunks
        re-run after an actor died."""
        rates = self.rates()
        return {
            "address": self.address,
            "nodes": {
                label: {"picks": int(n), "picks_per_s": round(rates.get(label, 0.0), 2)}
                for label, n in sorted(self.node_picks.items())
            },
            "picks_per_s": round(rates["total"], 2) if "total" in rates else None,
            "chunks_rerun": int(self.lost_chunks),
        }

    def close(self) -> None:
        """End this run's actors, and disconnect when this executor connected."""
        for slot in list(getattr(self, "slots", [])):
            self._kill(slot)
        if getattr(self, "slots", None) is not None:
            self.slots.clear()
        if self._connected:
            self._ray.shutdown()
            self._connected = False


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
            proc.wait(timeout=5)  # reaps `ray start` (a zombie would stay in the session)
        except subprocess.TimeoutExpired:
            continue
        deadline = time.monotonic() + 5
        while session_pids(proc.pid) and time.monotonic() < deadline:
            time.sleep(0.1)
        if not session_pids(proc.pid):
            return
