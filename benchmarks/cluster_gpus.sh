#!/usr/bin/env bash
# Benchmark (issue 20): Ray actors, one per GPU, against the single-process multi-GPU
# path -- the door opener on MuJoCo Warp, the same pick-points and chunks, both tables
# compared. Run on one machine with several NVIDIA GPUs where mjx_pick[gpu,cluster] is
# installed:
#
#   bash benchmarks/cluster_gpus.sh            (N=262144 CH=65536 by default)
#
# It starts a one-node Ray head with every GPU of the machine (port 6380), runs
# `mjx-pick evaluate` twice without Ray (the first run builds Warp's kernels) and once
# with `--ray`, prints each summary and how far the tables agree, and stops the head.
# On the project's offline GPU machines Ray is not in the image: its wheel (79 MB) is
# sent in parts beside ../shared/tools/device-wheels' halves and joined there, then
# installed with `pip install --target /tmp/raysite` and a .pth in the user site (so it
# comes after the image's own packages); RAY_SITE=/tmp/raysite puts its `ray` on PATH.
set -u
export XLA_PYTHON_CLIENT_MEM_FRACTION=${XLA_PYTHON_CLIENT_MEM_FRACTION:-0.6} NCCL_NVLS_ENABLE=0
[ -n "${RAY_SITE:-}" ] && export PATH=$RAY_SITE/bin:$PATH
OUT=${OUT:-/tmp/cluster_gpus}; mkdir -p "$OUT"
nvidia-smi -L; nproc
python3 -c "import ray, mjx_pick; print('ray', ray.__version__)"
N=${N:-262144}; CH=${CH:-65536}
common="evaluate door_opener --n $N --seed 0 --backend warp --chunk-size $CH --traces 0 --no-progress"
t=$(date +%s); python3 -m mjx_pick.cli $common --out $OUT/one 2>&1 | tail -4; echo "one process (kernel build included): $(( $(date +%s) - t )) s"
t=$(date +%s); python3 -m mjx_pick.cli $common --out $OUT/one2 2>&1 | tail -4; echo "one process, warm: $(( $(date +%s) - t )) s"
ray start --head --disable-usage-stats --include-dashboard=false --port=6380 2>&1 | tail -3
ray status 2>&1 | grep -E "GPU|CPU" | head -4
t=$(date +%s); timeout 300 python3 -m mjx_pick.cli $common --ray 127.0.0.1:6380 --out $OUT/ray1 2>&1 | tail -6; echo "ray, one actor per GPU: $(( $(date +%s) - t )) s"
# a GPU actor killed mid-run (SIGKILL, KILL_AFTER s after the start, once it simulates):
# its chunk goes back to the queue and a new actor takes it; the table must be ray1's
( sleep "${KILL_AFTER:-25}"; pid=$(pgrep -f "ray::_Worker" | head -1)
  [ -n "$pid" ] && kill -9 "$pid" && echo "killed actor process $pid" ) &
t=$(date +%s); timeout 400 python3 -m mjx_pick.cli $common --ray 127.0.0.1:6380 --out $OUT/ray_killed 2>&1 | tail -6; echo "ray, an actor killed: $(( $(date +%s) - t )) s"
wait
OUT=$OUT python3 - <<'EOF'
import json, os, numpy as np, pyarrow.parquet as pq
from pathlib import Path
rows = {}
for name in ("one", "one2", "ray1", "ray_killed"):
    d = Path(os.environ["OUT"]) / name
    if not (d / "summary.json").is_file():
        print(name, "no summary"); continue
    s = json.loads((d / "summary.json").read_text())
    keep = {k: s.get(k) for k in ("n", "n_feasible", "success_rate", "n_diverged", "compile_s", "run_s", "wall_s", "picks_per_s", "backend", "device", "cluster")}
    print(name, json.dumps(keep)[:1500])
    rows[name] = pq.read_table(d / "results.parquet").to_pandas().sort_values("pick_id").reset_index(drop=True)
if "one" in rows:
    a = rows["one"]
    for name in ("one2", "ray1", "ray_killed"):
        if name not in rows: continue
        b = rows[name]
        same_ids = (a.pick_id.values == b.pick_id.values).all()
        lab = (a.success.values == b.success.values).mean()
        eq = {c: float((a[c].values == b[c].values).mean()) for c in a.columns if a[c].dtype.kind in "fiub"}
        print(name, "vs one: ids equal", same_ids, "labels equal", lab, "columns bit-equal (fraction):", {k: round(v, 5) for k, v in eq.items() if v < 1}, "all other columns 1.0")
EOF
ray stop --force >/dev/null 2>&1
