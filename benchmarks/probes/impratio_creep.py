"""impratio against labels on MuJoCo C (issue 32): how much each part's labels depend
on the collider's contact points, and which labels an impratio moves.

    python benchmarks/probes/impratio_creep.py --gripper onrobot-rg2 --force-n 30
    python benchmarks/probes/impratio_creep.py --objects 037_scissors --impratios 10,100

Per part (``real_objects.py``'s pick-points: ``--n``, seed 0) and impratio: C's success,
and the share of labels that C with multi-contact off (``real_objects.without_multiccd``)
gives alike -- soft friction's creep divides among a pad's contact points, so a part
whose labels rest on creep changes them with the point count. Then every label that
moves between the first impratio and the last, as (failure before, failure after)
counts. Figures: benchmarks/results/history.md, "impratio 100".
"""

from __future__ import annotations

import argparse
import collections
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: real_objects
from real_objects import load_ycb, multiccd_off, table_picks, ycb_manifest

import mjx_pick as mp


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--force-n", type=float, default=50.0, help="F_d, N")
    ap.add_argument("--n", type=int, default=256, help="pick-points per part")
    ap.add_argument("--impratios", default="10,30,100")
    ap.add_argument(
        "--objects",
        default="door_opener,040_large_marker,037_scissors,048_hammer,044_flat_screwdriver,"
        "011_banana,050_medium_clamp",
    )
    args = ap.parse_args()
    impratios = [float(v) for v in args.impratios.split(",")]
    grasp = mp.GraspConfig(grip_force_n=args.force_n)
    manifest = ycb_manifest()
    for name in args.objects.split(","):
        obj = load_ycb(name) if name in manifest else mp.load_object(name)
        ids = None
        labels = {}
        for ratio in impratios:
            solver = mp.SolverParams(impratio=ratio)
            tables = []
            for off in (False, True):
                with multiccd_off(off):
                    if ids is None:  # the pick-points of the first run, then the same
                        ev = mp.evaluate(
                            obj, args.gripper, n=args.n, seed=0, grasp=grasp, solver=solver,
                            backend="mujoco",
                        )  # fmt: skip
                        ids = ev.table.to_pandas()
                        picks = table_picks(obj, mp.load_gripper(args.gripper), grasp, ids, "user")
                    else:
                        ev = mp.evaluate(
                            obj, args.gripper, picks=picks, grasp=grasp, solver=solver,
                            backend="mujoco",
                        )  # fmt: skip
                tables.append(ev.table.to_pandas().set_index("pick_id").loc[ids["pick_id"]])
            on, no = tables
            labels[ratio] = on["failure"]
            print(
                f"{args.gripper} {name} impratio {ratio:g}: success {on['success'].mean():.1%}, "
                f"= without multi-contact {(on['success'] == no['success']).mean():.1%}, "
                f"diverged {int(on['diverged'].sum() + no['diverged'].sum())}",
                flush=True,
            )
        first, last = labels[impratios[0]], labels[impratios[-1]]
        moved = collections.Counter((a, b) for a, b in zip(first, last, strict=True) if a != b)
        print(f"  {impratios[0]:g} -> {impratios[-1]:g}: {dict(moved)}", flush=True)


if __name__ == "__main__":
    main()
