"""Benchmark: scaling of a CPU Ray cluster -- pick-points per second on 1 and 2 nodes.

Each node count starts a local cluster of that many nodes on THIS machine (``ray start``
in sessions of their own, each node offering --cpus-per-node CPUs: one C-engine actor
with that many threads), runs ``evaluate(..., ray=address)`` on the same pick-points and
ends the cluster. A single-process run (no Ray, the C engine on every core) is the
baseline, and every cluster table must equal it. One CSV row per run:

  python benchmarks/cluster.py --nodes 1,2 --n 512 --cpus-per-node 1 --out benchmarks/out

Columns: nodes, cpus_per_node, n, wall_s (the whole evaluate call: connecting, starting
actors, compiling, simulating, writing), picks_per_s (n / wall_s), cluster_picks_per_s
(the driver's rate over its chunk loop, ``summary['cluster']``), per-node rates (pick-points
over the time each node's actor was busy, compile included), chunks, equal (table equal
to the single-process one).

On a machine with fewer cores than nodes x CPUs the nodes share cores: say so with the
figures (benchmarks/RESULTS.md).
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import mjx_pick as mp
from mjx_pick.engine.cluster import free_ports, start_local_node, stop_local_node
from mjx_pick.studies.evaluation import evaluate


def local_cluster(n_nodes: int, cpus: int, logs: Path):
    """Start n_nodes local nodes; (address, processes, temp folders)."""
    import ray

    port = free_ports(1)[0]
    temps = [Path(tempfile.mkdtemp(prefix="mjxray", dir="/tmp")) for _ in range(n_nodes)]
    env = {"JAX_PLATFORMS": "cpu"}
    nodes = [start_local_node(temps[0], logs / "head.log", port, True, cpus, env)]
    deadline = time.monotonic() + 120
    while True:
        try:
            socket.create_connection(("127.0.0.1", port), timeout=1).close()
            break
        except OSError:
            if time.monotonic() > deadline:
                raise RuntimeError("the head did not start") from None
            time.sleep(0.2)
    for i in range(1, n_nodes):
        nodes.append(start_local_node(temps[i], logs / f"node{i}.log", port, False, cpus, env))
    address = f"127.0.0.1:{port}"
    ray.init(address=address, logging_level="WARNING", log_to_driver=False)
    try:
        while sum(n["Alive"] for n in ray.nodes()) < n_nodes:
            if time.monotonic() > deadline:
                raise RuntimeError("the nodes did not join")
            time.sleep(0.2)
    finally:
        ray.shutdown()
    return address, nodes, temps


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", default="block")
    ap.add_argument("--n", type=int, default=512)
    ap.add_argument("--nodes", default="1,2", help="node counts to run")
    ap.add_argument("--cpus-per-node", type=int, default=1)
    ap.add_argument("--chunk-size", type=int, default=32)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="benchmarks/out")
    args = ap.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    obj = mp.load_asset(args.object)
    run = {"n": args.n, "seed": args.seed, "backend": "mujoco", "n_traces": 0}

    t0 = time.perf_counter()
    # the same command without Ray: the same chunks, so the same call shapes (a
    # batch's float32 rounding depends on its shape: engine module docstring)
    base = evaluate(obj, **run, chunk_size=args.chunk_size)
    rows = [
        {
            "nodes": 0,
            "cpus_per_node": os.cpu_count(),
            "n": args.n,
            "wall_s": round(time.perf_counter() - t0, 2),
            "picks_per_s": round(args.n / (time.perf_counter() - t0), 1),
            "cluster_picks_per_s": None,
            "node_picks_per_s": None,
            "chunks": None,
            "equal": True,
        }
    ]
    print(rows[-1], flush=True)
    for k in (int(v) for v in args.nodes.split(",")):
        logs = Path(tempfile.mkdtemp(prefix="mjxray-logs"))
        address, nodes, temps = local_cluster(k, args.cpus_per_node, logs)
        try:
            folder = Path(tempfile.mkdtemp(prefix="mjxbench")) / "run"
            t0 = time.perf_counter()
            ev = evaluate(obj, **run, ray=address, chunk_size=args.chunk_size, out=folder)
            wall = time.perf_counter() - t0
        finally:
            for proc in reversed(nodes):
                stop_local_node(proc)
            for temp in temps:
                shutil.rmtree(temp, ignore_errors=True)
        cl = ev.summary["cluster"]
        rows.append(
            {
                "nodes": k,
                "cpus_per_node": args.cpus_per_node,
                "n": args.n,
                "wall_s": round(wall, 2),
                "picks_per_s": round(args.n / wall, 1),
                "cluster_picks_per_s": cl["picks_per_s"],
                "node_picks_per_s": json.dumps(
                    {v: d["picks_per_s"] for v, d in cl["nodes"].items()}
                ),
                "chunks": -(-args.n // args.chunk_size),
                "equal": bool(ev.table.equals(base.table)),
            }
        )
        print(rows[-1], flush=True)
    path = out / "cluster_scaling.csv"
    with path.open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    print(f"rows in {path} (commit {commit}, {os.cpu_count()} CPU cores on this machine)")


if __name__ == "__main__":
    main()
