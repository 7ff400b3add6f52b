"""Pick-points on which two engines disagree, each simulated R times on every backend.

    python benchmarks/probes/differing_picks.py --object 048_hammer --pick-ids 6108 --repeats 8 \
        --backends mujoco,warp

The pick-points are those of ``real_objects.py`` (``mp.evaluate(..., n, seed)`` on
MuJoCo C, robotiq-2f85 by default). Each is repeated R times in one batch: on MuJoCo C
the copies are identical, on MuJoCo Warp they differ by its contact order (atomic
counters), so the spread over the copies shows whether a label is Warp's coin toss or a
systematic difference. Prints and writes (``--out``) each copy's label and the metrics
that decide it.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: real_objects
from real_objects import load_ycb, multiccd_off, table_picks, ycb_manifest

import mjx_pick as mp

METRICS = ("failure", "phi_max_deg", "slip_mm", "tilt_max_deg", "chatter", "max_force_left_n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--object", required=True, help="door_opener or a shipped YCB part")
    ap.add_argument("--pick-ids", required=True, help="comma-separated pick_id values")
    ap.add_argument("--n", type=int, default=256, help="real_objects.py's --n")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--force-n", type=float, default=50.0, help="real_objects.py's --force-n")
    ap.add_argument("--repeats", type=int, default=8)
    ap.add_argument("--backends", default="mujoco,warp")
    ap.add_argument("--out", default="")
    ap.add_argument("--no-multiccd", action="store_true", help="as real_objects.py's")
    args = ap.parse_args()
    with multiccd_off(args.no_multiccd):
        run(args)


def run(args) -> None:
    """Each pick of args, R copies, on every backend (see the module's docstring)."""
    obj = load_ycb(args.object) if args.object in ycb_manifest() else mp.load_object(args.object)
    ids = [int(i) for i in args.pick_ids.split(",")]
    grasp = mp.GraspConfig(grip_force_n=args.force_n)
    table = mp.evaluate(
        obj, args.gripper, n=args.n, seed=args.seed, grasp=grasp, backend="mujoco"
    ).table.to_pandas()
    unknown = sorted(set(ids) - set(table["pick_id"]))
    if unknown:
        raise SystemExit(
            f"--pick-ids: {unknown} are not among the {len(table)} pick-points of "
            f"--n {args.n} --seed {args.seed} on {args.object}"
        )
    rows = table.set_index("pick_id").loc[ids]
    result = {"args": vars(args), "picks": {}}
    gripper = mp.load_gripper(args.gripper)
    copies = rows.loc[np.repeat(ids, args.repeats)]
    picks = table_picks(obj, gripper, grasp, copies, "user", np.arange(len(copies)))
    for backend in args.backends.split(","):
        out = mp.evaluate(obj, gripper, picks=picks, grasp=grasp, backend=backend).table
        out = out.to_pandas().sort_values("pick_id")
        for k, pid in enumerate(ids):
            got = {
                m: out[m].iloc[k * args.repeats : (k + 1) * args.repeats].tolist() for m in METRICS
            }
            result["picks"].setdefault(str(pid), {})[backend] = got
            labels = dict(zip(*np.unique(got["failure"], return_counts=True), strict=True))
            labels = {str(a): int(b) for a, b in labels.items()}
            print(
                f"{args.object} pick {pid} {backend}: {labels}; phi_max "
                f"{np.round(got['phi_max_deg'], 1).tolist()}; slip "
                f"{np.round(got['slip_mm'], 2).tolist()}",
                flush=True,
            )
    if args.out:
        Path(args.out).write_text(json.dumps(result, indent=1, default=str))


if __name__ == "__main__":
    main()
