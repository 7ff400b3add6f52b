"""Time to answer: whole ``mjx-pick`` commands as a user runs them, each in a new process.

Each case runs twice with the cache (emptied before the first run: a part never seen,
then the same part again) and once with ``--no-cache`` (today's cost without it). Cases:

* ``mesh``: a YCB mesh never seen before (``evaluate <stl> --unit m``), ``--n-mesh`` picks;
* ``photo``: the shipped door-opener photo object, ``--n-photo`` picks;
* ``sweep``: 8 finger widths x ``--n-sweep`` picks (``sweep --param gripper.finger_width_mm``);
* ``design``: ``design door_opener --bound finger_width_mm=10:40``, design's defaults
  otherwise (12 variants, 3 rounds);
* ``linkage``: the door opener with the robotiq-2f85-linkage MJCF gripper, ``--n-linkage``
  picks (its quasi-static close: computed, or read from the cache);
* ``session``: the mesh case's command answered twice in ONE new process, through
  ``mjx_pick.Session`` (a warm process): "first" and "second" are its two calls (the
  same command), each call's wall time and breakdown; the process's own wall time and
  import beside them. Its "second" against the mesh case's "second" (a new process for
  a part seen before) is what a warm process saves; with both, the two tables are
  compared too.

``--runs`` picks which of the three runs to make (a GPU call's time is short; the
session case makes its one process for "first" or "second").

It also checks that the cache changes no result: the mesh case's ``results.parquet``
with and without the cache must be the same table. Writes one JSON under
``benchmarks/results/`` with the wall time of every run and evaluate's fixed-cost
breakdown (summary.json ``time_s``).

  python benchmarks/time_to_answer.py --backend mujoco --n-mesh 64 --n-photo 200 --n-sweep 64
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
YCB = ROOT / "mjx_pick" / "assets" / "objects" / "ycb"
WIDTHS = "10,14,18,22,26,30,34,38"  # mm: 8 finger widths


def run(cmd: list[str], env: dict) -> dict:
    """One command in a new process: wall seconds, exit status, last lines of output."""
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        sys.stderr.write(done.stdout + done.stderr)
        raise SystemExit(f"failed: {' '.join(cmd)}")
    return {"wall_s": round(wall, 2), "tail": done.stdout.strip().splitlines()[-3:]}


# the session case's process: the mesh command answered twice through one Session
SESSION = """
import json, sys, time
t0 = time.perf_counter()
import mjx_pick as mp
imported = time.perf_counter() - t0
backend, mesh, mass_g, n, out = sys.argv[1:6]
calls = {}
with mp.Session(backend) as s:
    for label in ("first", "second"):
        t = time.perf_counter()
        part = s.object(mesh, unit="m", mass_g=float(mass_g))  # read once, then kept
        costs = {"object_s": time.perf_counter() - t}
        ev = s.evaluate(part, n=int(n), out=f"{out}_{label}", fixed_costs=costs)
        calls[label] = {"wall_s": round(time.perf_counter() - t, 2), "time_s": ev.summary["time_s"]}
print(json.dumps({"import_s": round(imported, 2), "calls": calls}))
"""


def breakdown(out: Path) -> dict | None:
    """evaluate's fixed-cost breakdown (summary.json), or a sweep's timing (config.json:
    compile and run seconds, scenes built, compiled programs)."""
    f = out / "summary.json"
    if f.is_file():
        return json.loads(f.read_text()).get("time_s")
    f = out / "config.json"
    return json.loads(f.read_text()).get("timing") if f.is_file() else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--backend", default="mujoco")
    ap.add_argument("--mesh", default="011_banana.stl", help="a file of assets/objects/ycb")
    ap.add_argument("--mass-g", type=float, default=66.0, help="the mesh's mass, g")
    ap.add_argument("--n-mesh", type=int, default=1024)
    ap.add_argument("--n-photo", type=int, default=200)
    ap.add_argument("--n-sweep", type=int, default=512)
    ap.add_argument("--n-linkage", type=int, default=64)
    ap.add_argument(
        "--cases", default="mesh,photo,sweep", help="of mesh,photo,sweep,design,linkage,session"
    )
    ap.add_argument(
        "--runs", default="no_cache,first,second", help="which of no_cache,first,second"
    )
    ap.add_argument("--out", default=str(ROOT / "benchmarks" / "results" / "time_to_answer.json"))
    args = ap.parse_args()

    work = Path(tempfile.mkdtemp(prefix="time_to_answer."))
    # this checkout first, then whatever the caller's path holds (a GPU machine's wheels)
    path = os.pathsep.join(p for p in (str(ROOT), os.environ.get("PYTHONPATH", "")) if p)
    env = {**os.environ, "MJX_PICK_CACHE_DIR": str(work / "cache"), "PYTHONPATH": path}
    env.pop("MJX_PICK_CACHE", None)
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    cli = [sys.executable, "-m", "mjx_pick.cli"]
    common = ["--backend", args.backend, "--no-progress"]
    mesh = str((YCB / args.mesh).relative_to(ROOT))  # as a user in a checkout types it
    cases = {
        "mesh": [
            "evaluate",
            mesh,
            "--unit",
            "m",
            "--mass-g",
            str(args.mass_g),
            "--n",
            str(args.n_mesh),
        ],
        "photo": ["evaluate", "door_opener", "--n", str(args.n_photo)],
        # design's defaults: 12 variants over 3 rounds of successive halving
        "design": ["design", "door_opener", "--bound", "finger_width_mm=10:40"],
        "sweep": [
            "sweep",
            "door_opener",
            "--param",
            f"gripper.finger_width_mm={WIDTHS}",
            "--n",
            str(args.n_sweep),
        ],
        "linkage": [
            "evaluate",
            "door_opener",
            "--gripper",
            "robotiq-2f85-linkage",
            "--n",
            str(args.n_linkage),
        ],
    }
    record = {
        "date": datetime.date.today().isoformat(),
        "device": f"{platform.processor() or platform.machine()}, {os.cpu_count()} CPUs",
        # a copy of the tree without git (a GPU machine) names its commit in MJX_PICK_COMMIT
        "commit": os.environ.get("MJX_PICK_COMMIT")
        or subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True
        ).stdout.strip(),
        "backend": args.backend,
        "cases": {},
    }
    for name in args.cases.split(","):
        shutil.rmtree(work / "cache", ignore_errors=True)  # a part never seen
        if name == "session":
            record["cases"][name] = session_case(cli, args, mesh, work, env)
            continue
        rows = {}
        runs = {"no_cache": ["--no-cache"], "first": [], "second": []}
        for label, extra in ((k, runs[k]) for k in args.runs.split(",")):
            out = work / f"{name}_{label}"
            cmd = [*cli, *cases[name], *common, "--out", str(out), *extra]
            rows[label] = run(cmd, env)
            rows[label]["time_s"] = breakdown(out)
            print(name, label, rows[label]["wall_s"], "s", rows[label]["time_s"], flush=True)
        rows["command"] = " ".join(["mjx-pick", *cases[name], *common])
        record["cases"][name] = rows
    import pyarrow.parquet as pq

    # bit for bit on the C engine; MuJoCo Warp on a GPU is not bit-reproducible (atomic
    # contact counters), so the share of equal labels is said beside the bits
    pairs = {
        "mesh": ("mesh_no_cache", "mesh_second", "with and without the cache"),
        "session": (
            "mesh_second",
            "session_second",
            "from a new process and a session's second call",
        ),
    }
    for key, (left, right, what) in pairs.items():
        files = [work / left / "results.parquet", work / right / "results.parquet"]
        if not all(f.is_file() for f in files):
            continue
        a, b = (pq.read_table(f).sort_by("pick_id") for f in files)
        labels = (a["success"].to_numpy() == b["success"].to_numpy()).mean()
        record[f"{key}_tables_equal"] = bool(a.equals(b))
        record[f"{key}_labels_equal"] = round(float(labels), 5)
        print(f"mesh results.parquet {what}: bit for bit {a.equals(b)}, labels equal {labels:.2%}")
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(record, indent=2) + "\n")
    shutil.rmtree(work, ignore_errors=True)
    print(f"written {args.out}")


def session_case(cli: list[str], args, mesh: str, work: Path, env: dict) -> dict:
    """The session case: one new process answering the mesh command twice through
    ``mjx_pick.Session`` (its calls' wall times and breakdowns, the process's wall)."""
    cmd = [sys.executable, "-c", SESSION, args.backend, mesh, str(args.mass_g)]
    cmd += [str(args.n_mesh), str(work / "session")]
    t0 = time.perf_counter()
    done = subprocess.run(cmd, env=env, capture_output=True, text=True, cwd=ROOT)
    wall = time.perf_counter() - t0
    if done.returncode != 0:
        sys.stderr.write(done.stdout + done.stderr)
        raise SystemExit("failed: the session case")
    out = json.loads(done.stdout.strip().splitlines()[-1])
    rows = {"process_wall_s": round(wall, 2), "import_s": out["import_s"], **out["calls"]}
    for label, call in out["calls"].items():
        print("session", label, call["wall_s"], "s", call["time_s"], flush=True)
    print("session process", rows["process_wall_s"], "s", flush=True)
    rows["command"] = (
        f"mjx_pick.Session({args.backend!r}): evaluate({mesh}, unit='m', "
        f"mass_g={args.mass_g:g}, n={args.n_mesh}) twice in one process"
    )
    return rows


if __name__ == "__main__":
    main()
