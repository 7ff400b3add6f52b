"""Ray as the distributed engine, on a real local Ray cluster (no mock of Ray).

A head and a second node are started with ``ray start`` on this machine, each with 1 CPU
(so each gets one C-engine actor), in their own temp folders, on free ports, each in a
process group of its own that the fixture's finalizer ends. Every run below must give
the very table of one uninterrupted single-process run: spread over both nodes, with a
worker killed mid-chunk, and with the driver killed and resumed.

The physics is kept short (a 0.6 s close, a 20 mm lift, a 0.2 s hold: test_scale's
kill test) so that 192 pick-points take seconds on one CPU.
"""

import json
import os
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

import mjx_pick as mp
from mjx_pick import cli
from mjx_pick.core.config import to_toml
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.cluster import free_ports, session_pids, start_local_node, stop_local_node
from mjx_pick.engine.simulator import Simulator
from mjx_pick.studies.evaluation import evaluate
from mjx_pick.studies.robust import robust_best

GRASP = GraspConfig(close_timeout_s=0.6, lift_height_mm=20.0, hold_s=0.2)
N = 192  # pick-points per run
CHUNK = 16  # 12 chunks: enough for both nodes to take several, and to kill mid-run
CPU = {"JAX_PLATFORMS": "cpu", "XLA_FLAGS": ""}  # the nodes' actors: plain CPU JAX
RUN = {"n": N, "seed": 3, "grasp": GRASP, "backend": "mujoco", "n_traces": 0}


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, block):
    """A two-node local Ray cluster: (address, [head, worker] processes, the reference
    table: the same command without --ray -- one uninterrupted single-process run, same
    seed, backend and chunks (calls of one shape: engine module docstring) -- simulated
    while the second node starts)."""
    import ray

    logs = tmp_path_factory.mktemp("ray-logs")
    temps: list[Path] = []
    nodes = []
    try:
        ports = iter(free_ports(3))  # a new head port for each try

        def answers(port: int) -> bool:  # the head's GCS port
            try:
                socket.create_connection(("127.0.0.1", port), timeout=1).close()
                return True
            except OSError:
                return False

        head, port = _start_node(logs / "head.log", lambda: next(ports), True, answers, temps)
        nodes.append(head)
        address = f"127.0.0.1:{port}"
        temps.append(Path(tempfile.mkdtemp(prefix="mjxray", dir="/tmp")))
        log = logs / "worker.log"
        nodes.append(start_local_node(temps[-1], log, port, head=False, env=CPU))
        reference = evaluate(block, **RUN, chunk_size=CHUNK).table  # while it starts
        ray.init(address=address, logging_level="WARNING", log_to_driver=False)
        try:

            def joined(_port: int) -> bool:
                return sum(n["Alive"] for n in ray.nodes()) >= 2

            deadline = time.monotonic() + 60
            while not joined(port):
                if nodes[1].poll() is not None:  # it exited (a port taken): start it again
                    stop_local_node(nodes.pop())
                    nodes.append(_start_node(log, lambda: port, False, joined, temps)[0])
                    break
                assert time.monotonic() < deadline, f"no second node in 60 s: {log.read_text()}"
                time.sleep(0.1)
        finally:
            ray.shutdown()
        yield address, nodes, reference
    finally:
        for proc in reversed(nodes):
            stop_local_node(proc)
        for temp in temps:
            subprocess.run(["rm", "-rf", str(temp)], check=False)


def _start_node(log: Path, head_port, head: bool, up, temps: list[Path]):
    """Start a node of the local cluster (``cluster.start_local_node``) and wait until
    up(port) says it is there: (its process, the head's port). A node that exits before
    is started again (up to 3 tries, new ports and temp folder): the free ports it was
    given can be taken by another process of a shared machine before it binds them.

    head_port: () -> the head's port for this try; temps: where each try's temp folder
    is listed, for the caller to remove. Ray's socket paths must stay short (107 bytes):
    the temp folders go under /tmp."""
    for _ in range(3):
        port = head_port()
        temp = Path(tempfile.mkdtemp(prefix="mjxray", dir="/tmp"))
        temps.append(temp)
        proc = start_local_node(temp, log, port, head=head, env=CPU)
        deadline = time.monotonic() + 60
        while proc.poll() is None and not up(port):
            assert time.monotonic() < deadline, f"{log.name}: not up in 60 s: {log.read_text()}"
            time.sleep(0.1)
        if proc.poll() is None:
            return proc, port
        stop_local_node(proc)  # what it started before it exited
    raise AssertionError(f"{log.name}: the node exited 3 times: {log.read_text()}")


def _chunk_workers(nodes: list[subprocess.Popen]) -> list[int]:
    """Pids of this cluster's worker actors (``cluster._Worker``; Ray titles an actor's
    process ray::<class>[.<method>])."""
    pids = []
    for node in nodes:
        for pid in session_pids(node.pid):
            try:
                title = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")[0]
            except OSError:
                continue
            if title.startswith(b"ray::_Worker"):
                pids.append(pid)
    return pids


def test_run_spread_over_two_nodes_equals_one_process(cluster, block, tmp_path):
    address, _, reference = cluster
    out = tmp_path / "ray"
    ev = evaluate(block, **RUN, out=out, chunk_size=CHUNK, ray=address)
    assert ev.table.equals(reference)
    assert pq.read_table(out / "results.parquet").equals(reference)
    nodes = ev.summary["cluster"]["nodes"]
    assert len(nodes) == 2 and all(v["picks"] > 0 for v in nodes.values()), nodes
    assert sum(v["picks"] for v in nodes.values()) == N
    assert ev.summary["cluster"]["chunks_rerun"] == 0
    assert not (out / "chunks").exists(), "a complete run's chunks are removed"
    assert ev.config["ray"] == address and ev.config["backend"] == "mujoco"
    assert ev.summary["device"].startswith("ray: 2 nodes, 2 actors")


def test_worker_killed_mid_chunk_is_rerun_elsewhere(cluster, block, tmp_path):
    address, nodes, reference = cluster
    killed = []

    def kill_one_worker(done: int, _total: int) -> None:
        # after the second chunk both actors are busy with more queued: kill one mid-chunk
        if done >= 2 * CHUNK and not killed:
            pids = _chunk_workers(nodes)
            assert pids, "no worker actor process found"
            os.kill(pids[0], signal.SIGKILL)
            killed.append(pids[0])

    ev = evaluate(
        block,
        **RUN,
        out=tmp_path / "ray",
        chunk_size=CHUNK,
        ray=address,
        on_progress=kill_one_worker,
    )
    assert killed
    assert ev.summary["cluster"]["chunks_rerun"] >= 1, ev.summary["cluster"]
    assert ev.table.equals(reference)


def test_node_joining_is_used_and_node_leaving_is_survived(cluster, block, tmp_path):
    """A third node joins while the run goes on and takes chunks; then it leaves (its
    `ray start` session stopped) with a chunk in flight, which runs on another node
    unless its result was already on the way. The table is still the one of one
    uninterrupted process.

    Nothing here sleeps and hopes: the test acts on the driver's events
    (``cluster.ClusterEvent``), which the driver reports from its loop and waits for.
    Holding the loop at the first chunk done (the join) and at the third node's actor
    start (until it answers) leaves most chunks in the queue for the new actor, which
    the driver serves first (the least busy)."""
    import ray

    address, _, reference = cluster
    port = int(address.rsplit(":", 1)[1])
    temps: list[Path] = []
    third: dict = {"proc": None, "id": None, "inflight": 0, "left": False}
    kinds: list[str] = []
    # the third node's call events after it left: its actor can still be handed a call
    # before the driver sees the node gone (that call is lost)
    after_leaving: list[str] = []

    def act(ev) -> None:
        kinds.append(ev.kind)
        if third["left"] and ev.node_id == third["id"] and ev.kind.startswith("call_"):
            after_leaving.append(ev.kind)
        if ev.kind == "call_done" and third["proc"] is None:
            before = {n["NodeID"] for n in ray.nodes() if n["Alive"]}

            def joined(_port: int) -> bool:
                return bool({n["NodeID"] for n in ray.nodes() if n["Alive"]} - before)

            log = tmp_path / "third.log"
            third["proc"], _ = _start_node(log, lambda: port, False, joined, temps)
            (third["id"],) = {n["NodeID"] for n in ray.nodes() if n["Alive"]} - before
        elif ev.kind == "actor_started" and ev.node_id == third["id"] and not third["left"]:
            ray.get(ev.ready, timeout=120)  # the joined node's actor answers
        elif ev.kind == "call_done" and ev.node_id == third["id"] and not third["left"]:
            # it has done a chunk and runs the next (sent with it): it leaves with that
            # one in flight. Its actor is killed first, so that the chunk cannot finish
            # while the node shuts down; the node then leaves as `ray stop` would
            third["inflight"] = ev.inflight
            for pid in _chunk_workers([third["proc"]]):
                os.kill(pid, signal.SIGKILL)
            stop_local_node(third["proc"])
            third["left"] = True

    try:
        ev = evaluate(block, **RUN, chunk_size=CHUNK, ray=address, on_cluster_event=act)
    finally:
        if third["proc"] is not None and not third["left"]:
            stop_local_node(third["proc"])
        for temp in temps:
            subprocess.run(["rm", "-rf", str(temp)], check=False)
    assert third["left"], f"the joined node never finished a chunk: {kinds}"
    assert third["inflight"] >= 1, "it left holding a chunk (sent with its first)"
    assert ev.table.equals(reference)
    nodes = ev.summary["cluster"]["nodes"]
    joined = [label for label in nodes if label.endswith("/" + third["id"][:6])]
    assert len(nodes) == 3 and joined, nodes
    assert nodes[joined[0]]["picks"] >= CHUNK, "the joined node simulated a chunk"
    # every chunk it held ended once: lost and run elsewhere, or back from it when its
    # result was on the way before the kill (a chunk can end between its predecessor's
    # result and the kill on a loaded machine; test_worker_killed_mid_chunk_is_rerun_
    # elsewhere re-runs one for sure)
    sent, lost = after_leaving.count("call_sent"), after_leaving.count("call_lost")
    ended = len(after_leaving) - sent
    assert ended == third["inflight"] + sent, (after_leaving, third["inflight"])
    assert ev.summary["cluster"]["chunks_rerun"] == lost, (ev.summary["cluster"], kinds)


def test_driver_killed_then_resumed_equals_one_process(cluster, block, tmp_path):
    address, _, reference = cluster
    grasp_file = tmp_path / "grasp.toml"
    grasp_file.write_text(to_toml(GRASP))
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "mjx_pick.cli",
        "evaluate",
        "block",
        "--n",
        str(N),
        "--seed",
        "3",
        "--chunk-size",
        str(CHUNK),
        "--backend",
        "mujoco",
        "--grasp",
        str(grasp_file),
        "--out",
        str(out),
        "--no-progress",
        "--traces",
        "0",
        "--ray",
        address,
    ]
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "XLA_FLAGS": ""}
    log = tmp_path / "driver.log"
    chunks = out / "chunks"
    with log.open("wb") as sink:
        # the driver runs outside the checkout (the installed package), as a user's would
        driver = subprocess.Popen(cmd, env=env, stdout=sink, stderr=subprocess.STDOUT, cwd=tmp_path)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and driver.poll() is None:
            if len(list(chunks.glob("part-*.parquet"))) >= 3:
                break
            time.sleep(0.05)
        alive = driver.poll() is None
        driver.send_signal(signal.SIGKILL)
        driver.wait()
    assert alive, f"the driver ended before it could be killed: {log.read_text()}"
    before = {p.name: p.stat().st_mtime_ns for p in chunks.glob("part-*.parquet")}
    assert 3 <= len(before) < N // CHUNK and not (out / "results.parquet").exists()

    resumed = evaluate(block, **RUN, out=out, resume=True, ray=address, keep_chunks=True)
    for name, stamp in before.items():
        assert (chunks / name).stat().st_mtime_ns == stamp, f"{name} was simulated again"
    assert resumed.table.equals(reference)
    assert pq.read_table(out / "results.parquet").equals(reference)
    assert resumed.summary["cluster"]["nodes"], "the rest ran on the cluster"


def test_sweep_on_the_cluster_equals_one_process(cluster, block):
    # the studies run their pick-points x variants batches through a Ray runner
    # (``cluster.ray_runner``): each runner chunk is cut into one actor batch per actor
    # and put back in order
    address, _, _ = cluster
    params = [mp.ParamSpec.parse("contact.pad_friction=0.5:0.9:2")]
    run = {"n": 32, "backend": "mujoco", "batch_size": 16, "seed": 1}
    local = mp.sweep(block, params, mp.Settings(grasp=GRASP), **run)
    remote = mp.sweep(block, params, mp.Settings(grasp=GRASP), **run, ray=address)
    assert remote.table.num_rows == 64
    assert remote.table.equals(local.table)


@pytest.fixture(scope="module")
def cluster_sim(cluster, block):
    """One Simulator on the cluster for the studies below (their actors start once):
    the C engine, 16 pick-points per actor batch."""
    address, _, _ = cluster
    sim = Simulator(block, "mujoco", 16, ray=address)
    yield sim
    sim.close()


def test_robust_on_the_cluster_equals_one_process(cluster_sim, block):
    # the n pick-points, then the top-k's perturbed draws, all through the Ray runner
    run = {"n": 32, "top_k": 4, "m": 8, "seed": 2}
    local = robust_best(block, mp.Settings(grasp=GRASP), **run, backend="mujoco", batch_size=16)
    remote = robust_best(block, mp.Settings(grasp=GRASP), **run, simulator=cluster_sim)
    assert remote.num_rows == 4 and int(pc.sum(remote["trials"]).as_py()) == 32
    assert remote.equals(local)


def test_design_on_the_cluster_equals_one_process(cluster_sim, block):
    # every round's comparison (a scene per gripper variant) and the final one
    bounds = {"finger_width_mm": (10.0, 30.0)}
    run = {"variants": 2, "n": 16, "rounds": 2, "final_n": 16, "seed": 0}
    settings = mp.Settings(grasp=GRASP)
    local = mp.design_search(block, bounds, settings, **run, backend="mujoco", batch_size=16)
    remote = mp.design_search(block, bounds, settings, **run, simulator=cluster_sim)
    assert remote.best == local.best
    assert json.dumps(remote.rounds) == json.dumps(local.rounds)  # NaN-safe equality
    assert remote.final.table.num_rows > 0
    assert remote.final.table.equals(local.final.table)


def _same_outputs(a: Path, b: Path, names: tuple[str, ...]) -> None:
    """The study's outputs in a and b are equal: tables row for row, JSON files as text."""
    for name in names:
        if name.endswith(".parquet"):
            assert pq.read_table(a / name).equals(pq.read_table(b / name)), name
        else:
            assert (a / name).read_text() == (b / name).read_text(), name


def test_sweep_stopped_on_the_cluster_resumes_on_one_machine(cluster_sim, block, tmp_path):
    # started on the cluster (chunks of one actor batch per actor: 2 x 16), stopped as
    # Ctrl-C stops it after its first chunk, resumed without Ray: the chunk on disk is
    # read back (the chunk size with it), the rest simulated here; the outputs are
    # those of one uninterrupted run without Ray
    params = [mp.ParamSpec.parse("contact.pad_friction=0.5,0.9")]
    run = {"n": 32, "seed": 1, "backend": "mujoco", "batch_size": 16}
    settings = mp.Settings(grasp=GRASP)
    mp.sweep(block, params, settings, **run, out=tmp_path / "ref")
    out = tmp_path / "sw"

    def ctrl_c(done: int, _total: int) -> None:
        if done > 0:
            raise KeyboardInterrupt

    cluster_sim.runner.on_progress = ctrl_c
    try:
        with pytest.raises(KeyboardInterrupt):
            mp.sweep(block, params, settings, **run, simulator=cluster_sim, out=out)
    finally:
        cluster_sim.runner.on_progress = None
    assert len(list((out / "chunks").glob("part-*.parquet"))) == 1
    assert json.loads((out / "run.json").read_text())["status"] == "interrupted"
    with pytest.raises(mp.ConfigError, match="pass --resume"):
        mp.sweep(block, params, settings, **run, out=out)  # refused before simulating
    with pytest.raises(mp.ConfigError, match="--resume needs --out"):
        mp.sweep(block, params, settings, **run, resume=True)
    resumed = mp.sweep(block, params, settings, **run, out=out, resume=True)
    assert resumed.timing["chunks_resumed"] == 1 and resumed.table.num_rows == 64
    _same_outputs(out, tmp_path / "ref", ("results.parquet", "variants.json"))
    assert not (out / "chunks").exists(), "a complete sweep's chunks are removed"
    again = mp.sweep(block, params, settings, **run, out=out, resume=True)
    assert again.already_complete and again.table.equals(resumed.table)


def test_compare_killed_then_resumed_on_the_cluster(cluster_sim, block, tmp_path):
    # `mjx-pick compare` without Ray, killed (SIGKILL) once a chunk is on disk, then
    # resumed on the cluster: only the missing chunks are simulated there, and the
    # outputs are those of one uninterrupted run without Ray
    grasp_file = tmp_path / "grasp.toml"
    grasp_file.write_text(to_toml(GRASP))
    names = ["robotiq-2f85", "franka-hand"]
    run = {"n": 32, "seed": 0, "backend": "mujoco", "batch_size": 16}
    settings = mp.Settings(mp.load_gripper("robotiq-2f85"), grasp=GRASP)  # the CLI's base
    grippers = [mp.load_gripper(g) for g in names]
    reference = mp.compare(block, grippers, settings, **run, out=tmp_path / "ref")
    out = tmp_path / "cmp"
    cmd = [sys.executable, "-m", "mjx_pick.cli", "compare", "block", "--grippers", ",".join(names)]
    cmd += ["--n", "32", "--seed", "0", "--backend", "mujoco", "--batch-size", "16"]
    cmd += ["--grasp", str(grasp_file), "--out", str(out), "--no-progress"]
    log = tmp_path / "compare.log"
    with log.open("wb") as sink:
        env = {**os.environ, "JAX_PLATFORMS": "cpu", "XLA_FLAGS": ""}
        proc = subprocess.Popen(cmd, env=env, stdout=sink, stderr=subprocess.STDOUT, cwd=tmp_path)
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline and proc.poll() is None:
            if list((out / "chunks").glob("part-*.parquet")):
                break
            time.sleep(0.05)
        alive = proc.poll() is None
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert alive, f"compare ended before it could be killed: {log.read_text()}"
    kept = list((out / "chunks").glob("part-*.parquet"))
    on_disk = sum(pq.read_table(f).num_rows for f in kept)
    simulated = int(np.sum(reference.feasible))
    assert kept and on_disk < simulated and not (out / "ranking.json").exists()
    before = cluster_sim.runner.cluster.simulated
    resumed = mp.compare(
        block, grippers, settings, **run, simulator=cluster_sim, out=out, resume=True
    )
    assert cluster_sim.runner.cluster.simulated - before == simulated - on_disk
    assert resumed.table.equals(reference.table)
    _same_outputs(out, tmp_path / "ref", ("results.parquet", "ranking.json"))
    again = mp.compare(block, grippers, settings, **run, out=out, resume=True)
    assert again.already_complete and again.ranking == json.loads(
        (out / "ranking.json").read_text()
    )
    assert np.array_equal(again.success, reference.success)
    assert np.array_equal(again.score, reference.score)


COMMANDS = {  # each study's own arguments, for the address checks below
    "evaluate": ["--n", "8"],
    "sweep": ["--n", "8", "--param", "contact.pad_friction=0.5,0.9"],
    "compare": ["--n", "8", "--grippers", "robotiq-2f85,franka-hand"],
    "design": ["--n", "8", "--bound", "finger_width_mm=10:30"],
    "robust": ["--n", "8"],
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_bad_cluster_addresses_are_one_line_errors(command, capsys, tmp_path):
    port = free_ports(1)[0]  # nothing listens there
    for address, message in (
        ("no address", "is not a cluster address"),
        ("host:99999", "is not a cluster address"),
        (f"127.0.0.1:{port}", "no Ray cluster answers there"),
    ):
        argv = [command, "block", *COMMANDS[command], "--backend", "mujoco", "--ray", address]
        assert cli.main([*argv, "--out", str(tmp_path / "never")]) == 2
        err = capsys.readouterr().err.strip()
        # the error is one line (sweep's size estimate may come before it), no traceback
        last = err.splitlines()[-1]
        assert message in last and "Traceback" not in err, err
        assert all(line.startswith("mjx-pick:") for line in err.splitlines()), err
        assert not (tmp_path / "never").exists(), "nothing may be written before the error"


def test_missing_ray_names_the_extra(monkeypatch, block):
    from mjx_pick.engine import cluster

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` raises ImportError
    with pytest.raises(mp.ConfigError, match=r"mjx-pick\[cluster\]"):
        cluster.import_ray()
    with pytest.raises(mp.ConfigError, match=r"mjx-pick\[cluster\]"):
        evaluate(block, n=8, grasp=GRASP, backend="mujoco", ray="auto")


def test_min_force_on_a_cluster_is_refused_before_connecting(block):
    with pytest.raises(mp.ConfigError, match="--min-force"):
        evaluate(block, n=8, grasp=GRASP, min_force=True, ray="127.0.0.1:1")


def test_importing_the_package_does_not_import_ray():
    code = "import sys, mjx_pick, mjx_pick.engine.cluster; assert 'ray' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True, cwd=tempfile.gettempdir())


def test_cluster_backend_choice():
    from mjx_pick.engine.cluster import cluster_backend, plan_slots

    cpu = {"NodeID": "a", "Resources": {"CPU": 8.0}}
    gpu = {"NodeID": "b", "Resources": {"CPU": 16.0, "GPU": 4.0}}
    assert cluster_backend("auto", [cpu]) == "mujoco"
    assert cluster_backend("auto", [cpu, gpu]) == "warp"
    with pytest.raises(mp.ConfigError, match="no GPU"):
        cluster_backend("warp", [cpu])
    # one C-engine actor per CPU node on all its CPUs; one actor per GPU for the GPU backend
    (slot,) = plan_slots("mujoco", cpu)
    assert (slot.num_cpus, slot.num_gpus, slot.nthread) == (8, 0, 8)
    slots = plan_slots("warp", gpu)
    assert len(slots) == 4 and all(s.num_gpus == 1 and s.num_cpus == 4 for s in slots)
    assert plan_slots("warp", cpu) == []


def test_a_gpu_node_that_loses_one_of_its_actors_gets_it_back():
    # a node of four GPUs runs four actors; one dies (dropped by the driver): the next
    # scan starts one actor there, not four and not none (measured on a 2-GPU host:
    # before, the node went on with one actor for the rest of the run)
    from mjx_pick.engine.cluster import _ActorPool, _Slot

    gpu = {"NodeID": "b", "Resources": {"CPU": 16.0, "GPU": 4.0}, "Alive": True}
    pool = object.__new__(_ActorPool)
    pool.name, pool.slots, pool._given_up, pool._last_scan = "warp", [], set(), 0.0
    started = []
    pool._alive_nodes = lambda: [gpu]
    pool._start = lambda slot: (started.append(slot), pool.slots.append(slot))
    pool._scan(force=True)
    assert len(started) == 4
    pool.slots.remove(started[1])
    pool._scan(force=True)
    assert len(started) == 5 and sum(s.node_id == "b" for s in pool.slots) == 4
    pool._given_up.add("b")
    pool.slots.pop()
    pool._scan(force=True)
    assert len(started) == 5  # a node that lost too many actors is left alone
    assert isinstance(started[0], _Slot)
