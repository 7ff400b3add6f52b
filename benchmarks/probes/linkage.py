"""The Robotiq 2F-85 linkage (issue 19): its pad path, and its labels against the
parallel-jaw 2F-85 on the same pick-points.

    # the height-compensation table: pad drop against opening (CSV)
    python benchmarks/probes/linkage.py path --out benchmarks/results/linkage_path.csv
    # both 2F-85 presets on one shared candidate set per object, MuJoCo C; label changes
    # by failure class, the object's tilt/turn/slip on the changed picks, and pictures of
    # the most common change re-simulated with traces
    python benchmarks/probes/linkage.py compare --objects door_opener --n 300 \\
        --out benchmarks/results/linkage_vs_parallel_door_opener.json \\
        --pictures benchmarks/results/linkage_pictures
    python benchmarks/probes/linkage.py compare --ycb --n 48 \\
        --out benchmarks/results/linkage_vs_parallel_ycb.json
    # what colliding link meshes cost: MuJoCo C step time; MJX / Warp compile time and
    # pick-points per second of a batched rollout (on a GPU machine)
    python benchmarks/probes/linkage.py links --backends mujoco,warp,mjx \\
        --out benchmarks/out/links.json

Compile time and throughput on the GPU backends: benchmarks/throughput.py with
--gripper robotiq-2f85-linkage (benchmarks/results/history.md, "GPU: the linkage on MuJoCo
Warp (H100)", gives the command).
"""

from __future__ import annotations

import argparse
import collections
import csv
import dataclasses
import time
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core import mjcf_gripper
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import write_json
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels import grasp as gk
from mjx_pick.studies.comparison import compare

PARALLEL, LINKAGE = "robotiq-2f85", "robotiq-2f85-linkage"


def path_table(out: str) -> None:
    """Pad travel, drop and the height compensation against the opening, every 5 mm."""
    gripper = mp.load_gripper(LINKAGE)
    kin = mjcf_gripper.characterise(gripper.mjcf)
    openings = np.arange(np.floor(kin.stroke_m * 1e3 / 5) * 5, 0, -5.0) * 1e-3
    rows = []
    for o in openings:
        t = float(kin.travel_at_opening(o))
        rows.append(
            {
                "opening_mm": round(o * 1e3, 1),
                "pad_travel_mm": round(t * 1e3, 2),
                "pad_drop_mm": round(float(kin.pad_centre_drop_m(o)) * 1e3, 2),
                "height_compensation_mm": round(float(kin.height_compensation_m(o)) * 1e3, 2),
                "drive_stiffness_n_per_mm": round(
                    float(np.interp(t, kin.travel, kin.stiffness_n_per_m)) * 1e-3, 1
                ),
                "force_limit_n": round(float(np.interp(t, kin.travel, kin.force_limit_n)), 1),
            }
        )
    Path(out).parent.mkdir(parents=True, exist_ok=True)
    with open(out, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    print("| " + " | ".join(rows[0]) + " |")
    print("|" + "---|" * len(rows[0]))
    for r in rows:
        print("| " + " | ".join(str(v) for v in r.values()) + " |")


def ycb_objects() -> dict:
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    manifest = tomllib.loads((folder / "manifest.toml").read_text())
    out = {}
    for name, entry in manifest.items():
        with resources.as_file(folder / entry["file"]) as p:
            out[name] = mp.load_object(p, unit=entry["unit"], mass_g=entry["mass_g"])
    return out


def changes(obj, grippers, result, seed: int) -> dict:
    """Label changes between the two grippers on the candidates both could take, and
    on each, how much higher the linkage's near pad is when it reaches the part than
    at the grasp (pickpoints.FeasibilityChecker.near_pad_rise_mm) against the part's
    top above its fingertips."""
    table = result.table.to_pandas()
    both = result.feasible.all(axis=0)
    ids = result.candidates["pick_id"][both]
    rows = {
        g.name: table[table["gripper"] == g.name].set_index("pick_id").loc[ids] for g in grippers
    }
    par, lin = rows[PARALLEL], rows[LINKAGE]
    lost = par["success"].to_numpy() & ~lin["success"].to_numpy()
    won = ~par["success"].to_numpy() & lin["success"].to_numpy()
    kept = par["success"].to_numpy() & lin["success"].to_numpy()
    checker = pp.FeasibilityChecker(obj, grippers[1], pp.PickConfig(pad_path_check=True))
    res = checker(lin["x_mm"].to_numpy(), lin["y_mm"].to_numpy(), lin["yaw_deg"].to_numpy())
    rise = checker.near_pad_rise_mm(res["opening_mm"], res["gap_left_mm"], res["gap_right_mm"])
    rides = rise >= checker.room_mm

    def quantiles(mask):
        if not mask.any():
            return []
        return [round(float(v), 2) for v in np.quantile(rise[mask], [0, 0.5, 1])]

    def describe(mask, failing):
        sub_par, sub_lin = par[mask], lin[mask]
        return {
            "n": int(mask.sum()),
            "failure_of_the_failing_gripper": dict(collections.Counter(failing[mask]["failure"])),
            "median_tilt_max_deg": {
                "parallel": float(np.nanmedian(sub_par["tilt_max_deg"])) if mask.any() else None,
                "linkage": float(np.nanmedian(sub_lin["tilt_max_deg"])) if mask.any() else None,
            },
            "median_yaw_max_deg": {
                "parallel": float(np.nanmedian(sub_par["yaw_max_deg"])) if mask.any() else None,
                "linkage": float(np.nanmedian(sub_lin["yaw_max_deg"])) if mask.any() else None,
            },
            "median_opening_mm": float(np.median(sub_par["opening_mm"])) if mask.any() else None,
            "pick_ids": [int(i) for i in ids[mask][:20]],
        }

    return {
        "object": obj.name,
        "height_mm": round(obj.height_mm, 2),
        "n_candidates": int(len(result.candidates["pick_id"])),
        "feasible": {g.name: int(result.feasible[i].sum()) for i, g in enumerate(grippers)},
        "both_feasible": int(both.sum()),
        "success_rate_on_both": {
            PARALLEL: float(par["success"].mean()),
            LINKAGE: float(lin["success"].mean()),
        },
        "labels_equal": float(np.mean(par["success"].to_numpy() == lin["success"].to_numpy())),
        "parallel_ok_linkage_fails": describe(lost, lin),
        "linkage_ok_parallel_fails": describe(won, par),
        "failures": {
            PARALLEL: dict(collections.Counter(par["failure"])),
            LINKAGE: dict(collections.Counter(lin["failure"])),
        },
        "median_tilt_max_deg_all": {
            PARALLEL: float(np.nanmedian(par["tilt_max_deg"])),
            LINKAGE: float(np.nanmedian(lin["tilt_max_deg"])),
        },
        "near_pad_rise_mm": {
            "room_mm (part top above the fingertips)": round(checker.room_mm, 2),
            "lost min/median/max": quantiles(lost),
            "both_ok min/median/max": quantiles(kept),
            "lost_with_rise_over_room": int((lost & rides).sum()),
            "both_ok_with_rise_over_room": int((kept & rides).sum()),
            "rise_over_room": int(rides.sum()),
            "linkage_fails_of_those": int((rides & ~lin["success"].to_numpy()).sum()),
        },
        "seed": seed,
    }


def picture(obj, grippers, cand_row, grasp, config, path: Path) -> None:
    """One pick re-simulated on both grippers with traces: the pick, pad forces, the
    object's lift and tilt."""
    from mjx_pick.outputs.plots import new_figure, pick_on_axes, save_png

    fig, axes = new_figure(2, 3, figsize=(15, 8))
    for row, gripper in zip(axes, grippers, strict=True):
        checker = pp.FeasibilityChecker(obj, gripper, config, grasp)
        picks = checker.batch(
            np.arange(1), [cand_row["x_mm"]], [cand_row["y_mm"]], [cand_row["yaw_deg"]], "user"
        )
        scene = mp.build_scene(obj, gripper, None, None, grasp)
        out, traces, _ = Runner("mujoco", 1).simulate(
            scene, grasp, make_inputs(scene, grasp, picks), record=True
        )
        tr = {f: traces[0, :, i] for i, f in enumerate(gk.TRACE_FIELDS)}
        label = "success" if out["success"][0] else gk.FAILURES[int(out["failure"][0])]
        pick_on_axes(
            row[0],
            obj,
            gripper,
            picks.x_mm[0],
            picks.y_mm[0],
            picks.yaw_deg[0],
            picks.opening_mm[0],
            title=f"{gripper.name}: {label}",
        )
        t = tr["t_s"]
        row[1].plot(t, tr["force_left_n"], label="left pad")
        row[1].plot(t, tr["force_right_n"], label="right pad", ls="-.")
        row[1].axhline(grasp.grip_force_n, color="k", ls="--", lw=1, label="F_d")
        row[1].set_xlabel("t, s")
        row[1].set_ylabel("N")
        row[1].legend(fontsize=8)
        row[1].set_title("pad forces")
        lift0 = tr["lift_m"][0]
        row[2].plot(t, 1e3 * (tr["lift_m"] - lift0), label="gripper lift from start, mm")
        row[2].plot(t, 1e3 * (tr["object_z_m"] - tr["object_z_m"][0]), label="object lift, mm")
        q = np.stack([tr["object_qw"], tr["object_qx"], tr["object_qy"], tr["object_qz"]], 1)
        tilt = np.degrees(np.arccos(np.clip(1 - 2 * (q[:, 1] ** 2 + q[:, 2] ** 2), -1, 1)))
        row[2].plot(t, tilt, label="object tilt, deg")
        row[2].set_xlabel("t, s")
        row[2].legend(fontsize=8)
        row[2].set_title(f"start lift {1e3 * lift0:.1f} mm (height compensation)")
    fig.tight_layout()
    save_png(fig, path, dpi=80)


def run_compare(args) -> None:
    grippers = [mp.load_gripper(PARALLEL), mp.load_gripper(LINKAGE)]
    objects = ycb_objects() if args.ycb else {}
    for name in [s for s in args.objects.split(",") if s]:
        objects[name] = mp.load_asset(name)
    grasp = mp.GraspConfig()
    rows = []
    for name, obj in objects.items():
        t0 = time.perf_counter()
        config = pp.PickConfig(pad_path_check=not args.no_pad_path_check)
        result = compare(
            obj, grippers, n=args.n, seed=args.seed, backend="mujoco", pick_config=config
        )
        row = changes(obj, grippers, result, args.seed)
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
        if args.out:
            write_json(args.out, {"args": vars(args), "rows": rows})
        print(
            f"{name:24s} both feasible {row['both_feasible']:4d}  success "
            f"{row['success_rate_on_both'][PARALLEL]:.3f} -> "
            f"{row['success_rate_on_both'][LINKAGE]:.3f}  labels equal "
            f"{row['labels_equal']:.3f}  lost {row['parallel_ok_linkage_fails']['n']} "
            f"{row['parallel_ok_linkage_fails']['failure_of_the_failing_gripper']}  won "
            f"{row['linkage_ok_parallel_fails']['n']} "
            f"{row['linkage_ok_parallel_fails']['failure_of_the_failing_gripper']}",
            flush=True,
        )
        if args.pictures:
            for key in ("parallel_ok_linkage_fails", "linkage_ok_parallel_fails"):
                ids = row[key]["pick_ids"]
                if not ids:
                    continue
                k = int(np.flatnonzero(result.candidates["pick_id"] == ids[0])[0])
                cand = {c: float(result.candidates[c][k]) for c in ("x_mm", "y_mm", "yaw_deg")}
                png = Path(args.pictures) / f"{name}_{key}.png"
                picture(obj, grippers, cand, grasp, config, png)
                print("  picture", png, flush=True)


def run_links(args) -> None:
    """What colliding link meshes cost: the same scene with the linkage's 10 link
    meshes paired with every object piece or not. MuJoCo C: microseconds per physics
    step of one simulation; MJX / Warp: a full batched rollout through the backend
    (compile time apart from run time, pick-points per second; mjx_pick.studies.throughput)."""
    from mjx_pick.studies.throughput import measure

    base = mp.load_gripper(LINKAGE)
    grasp = mp.GraspConfig()
    rows = []
    for links in (False, True):
        gripper = dataclasses.replace(
            base, mjcf=dataclasses.replace(base.mjcf, link_contacts=links)
        )
        obj = mp.load_asset(args.object)
        scene = mp.build_scene(obj, gripper, None, None, grasp)
        for backend in args.backends.split(","):
            # one row per backend, written at once: a long MJX compile of the colliding
            # links must not lose the rows before it
            row = {"object": args.object, "link_contacts": links, "backend": backend}
            row["npair"] = int(scene.model.npair)
            if backend == "mujoco":
                row["us_per_step"] = _c_step_us(scene, obj, gripper, grasp, args.steps)
            else:
                m = measure(args.object, gripper, backend, args.batch, 1, grasp, mp.SolverParams())
                for key in ("device", "batch", "compile_s", "picks_per_s", "physics_steps_per_s"):
                    row[key] = m[key]
                row["success_rate"] = m["success_rate"]
            rows.append(row)
            print(row, flush=True)
            if args.out:
                write_json(args.out, {"args": vars(args), "rows": rows})


def _c_step_us(scene, obj, gripper, grasp, steps: int) -> float:
    """MuJoCo C, one pick's start state, microseconds per physics step."""
    import mujoco

    picks = pp.generate_normal(obj, gripper, 1, seed=0, grasp=grasp)
    qpos0 = make_inputs(scene, grasp, picks).qpos0[0]
    model = scene.model
    data = mujoco.MjData(model)
    data.qpos[:] = qpos0
    data.ctrl[scene.index.lift_actuator] = qpos0[scene.index.lift_qpos]
    mujoco.mj_forward(model, data)
    t0 = time.perf_counter()
    for _ in range(steps):
        mujoco.mj_step(model, data)
    return round((time.perf_counter() - t0) / steps * 1e6, 1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)
    p = sub.add_parser("path", help="the height-compensation table")
    p.add_argument("--out", default="benchmarks/results/linkage_path.csv")
    c = sub.add_parser("compare", help="linkage against parallel jaw, MuJoCo C")
    c.add_argument("--objects", default="door_opener")
    c.add_argument("--ycb", action="store_true", help="also every shipped YCB mesh")
    c.add_argument("--n", type=int, default=300)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--out", default="")
    c.add_argument("--pictures", default="")
    c.add_argument(
        "--no-pad-path-check",
        action="store_true",
        help="simulate the poses whose near linkage pad rides over the part too",
    )
    k = sub.add_parser("links", help="colliding link meshes: compile and step time")
    k.add_argument("--object", default="door_opener")
    k.add_argument("--backends", default="mujoco")
    k.add_argument("--steps", type=int, default=200, help="MuJoCo C steps timed")
    k.add_argument("--batch", type=int, default=1024, help="MJX / Warp batch")
    k.add_argument("--out", default="")
    args = ap.parse_args()
    if args.command == "path":
        path_table(args.out)
    elif args.command == "compare":
        run_compare(args)
    else:
        run_links(args)


if __name__ == "__main__":
    main()
