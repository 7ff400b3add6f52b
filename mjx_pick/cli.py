"""``mjx-pick``: the command line.

  mjx-pick evaluate OBJECT [--gripper robotiq-2f85] [--n 1000] [--seed 0] --out DIR
  mjx-pick picks OBJECT --n 500 --out DIR          (pick-points and their pictures only)
  mjx-pick presets | assets                          (what is shipped)

OBJECT is a shipped asset name (``mjx-pick assets``), a top-down image (with
--px-per-mm, --thickness-mm and --mass-g) or a mesh (with --unit and --mass-g).
Every bad input ends with one line naming the input, the value and what is allowed.
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

from mjx_pick.config import ConfigError, load_toml


def _add_object_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("object")
    g.add_argument("object", help="asset name, image (PNG/JPG) or mesh (STL/OBJ/PLY/GLB)")
    g.add_argument("--px-per-mm", type=float, help="image scale (images)")
    g.add_argument("--thickness-mm", type=float, help="object thickness (images)")
    g.add_argument("--mass-g", type=float, help="object mass")
    g.add_argument("--density-kg-m3", type=float, help="density, instead of --mass-g")
    g.add_argument("--unit", choices=("m", "mm"), help="unit of a mesh file's coordinates")
    g.add_argument(
        "--pose", choices=("as_given", "stable"), default="as_given", help="mesh resting pose"
    )
    g.add_argument("--pick-height-mm", type=float, help="fingertip height (default: half)")
    g.add_argument("--simplify-mm", type=float, help="outline tolerance (images)")
    g.add_argument("--material", help="object material name (recorded)")


def _add_gripper_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("gripper")
    g.add_argument("--gripper", default="robotiq-2f85", help="preset name (mjx-pick presets)")
    g.add_argument("--gripper-file", help="a gripper TOML file (overrides --gripper)")


def _add_physics_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("physics")
    g.add_argument("--contact", help="contact parameters TOML (ContactParams fields)")
    g.add_argument("--solver", help="solver settings TOML (SolverParams fields)")
    g.add_argument("--grasp", help="grasp procedure TOML (GraspConfig fields)")
    g.add_argument("--grip-force-n", type=float, help="desired pad force F_d")
    g.add_argument("--pad-friction", type=float, help="pad-object friction coefficient")
    g.add_argument("--table-friction", type=float, help="object-table friction coefficient")
    g.add_argument("--timestep-s", type=float, help="physics time step")
    g.add_argument("--lift-height-mm", type=float)
    g.add_argument("--hold-s", type=float)
    g.add_argument(
        "--backend",
        choices=("auto", "mjx", "mujoco"),
        default="auto",
        help="auto: MJX when JAX sees a GPU/TPU, else the MuJoCo C engine",
    )
    g.add_argument("--batch-size", type=int, help="simulations per backend call")


def _add_pick_args(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("pick-points")
    g.add_argument("--n", type=int, default=1000, help="pick-points (Normal mode)")
    g.add_argument("--seed", type=int, default=0)
    g.add_argument("--safety-zone-mm", type=float)
    g.add_argument("--min-coverage", type=float)


def _objects(args):
    from mjx_pick.gripper import load_gripper
    from mjx_pick.objects import load_object

    obj = load_object(
        args.object,
        px_per_mm=args.px_per_mm,
        thickness_mm=args.thickness_mm,
        mass_g=args.mass_g,
        density_kg_m3=args.density_kg_m3,
        unit=args.unit,
        pose=args.pose,
        pick_height_mm=args.pick_height_mm,
        simplify_mm=args.simplify_mm,
        material=args.material,
    )
    gripper = load_gripper(args.gripper_file or args.gripper)
    return obj, gripper


def _settings(args):
    from mjx_pick.grasp import GraspConfig
    from mjx_pick.physics import ContactParams, SolverParams

    contact = load_toml(ContactParams, args.contact) if args.contact else ContactParams()
    solver = load_toml(SolverParams, args.solver) if args.solver else SolverParams()
    grasp = load_toml(GraspConfig, args.grasp) if args.grasp else GraspConfig()
    contact = _override(contact, pad_friction=args.pad_friction, table_friction=args.table_friction)
    solver = _override(solver, timestep_s=args.timestep_s)
    grasp = _override(
        grasp,
        grip_force_n=args.grip_force_n,
        lift_height_mm=args.lift_height_mm,
        hold_s=args.hold_s,
    )
    return contact, solver, grasp, _pick_config(args)


def _pick_config(args):
    from mjx_pick.pickpoints import PickConfig

    return _override(
        PickConfig(), safety_zone_mm=args.safety_zone_mm, min_coverage=args.min_coverage
    )


def _override(obj, **values):
    values = {k: v for k, v in values.items() if v is not None}
    return dataclasses.replace(obj, **values) if values else obj


def cmd_evaluate(args) -> int:
    from mjx_pick.evaluate import evaluate

    obj, gripper = _objects(args)
    contact, solver, grasp, picks_cfg = _settings(args)
    ev = evaluate(
        obj,
        gripper,
        n=args.n,
        seed=args.seed,
        picks=args.picks,
        contact=contact,
        solver=solver,
        grasp=grasp,
        pick_config=picks_cfg,
        backend=args.backend,
        batch_size=args.batch_size,
        out=args.out,
        n_traces=args.traces,
        progress=not args.no_progress,
        resume=args.resume,
        until=args.until,
        min_score=args.min_score,
        max_n=args.max,
    )
    print_summary(ev.summary, args.out)
    return 0


def print_summary(s: dict, out) -> None:
    rows = [
        ("object / gripper", f"{s['object']} / {s['gripper']}"),
        ("backend / device", f"{s['backend']} / {s['device']}"),
        ("pick-points", f"{s['n']} (candidates checked {s['candidates_checked']})"),
        ("success rate", f"{s['success_rate']:.3f} ({s['successes']}/{s['n']})"),
        ("diverged", f"{s['diverged']}"),
        (
            "score mean / median",
            f"{s['score_mean']:.3f} / {s['score_quantiles'].get('p50', float('nan')):.3f}",
        ),
        (
            "failures",
            ", ".join(f"{k} {v}" for k, v in s["failures"].items() if v and k != "none") or "none",
        ),
        ("F_Gmin, eq. (1)", f"{s['f_gmin_n']:.3f} N (F_d = {s['grip_force_n']:g} N)"),
        ("compile / run", f"{s['compile_s']:.1f} s / {s['run_s']:.1f} s"),
        ("pick-points per s", f"{s['picks_per_s']}"),
    ]
    width = max(len(k) for k, _ in rows)
    for k, v in rows:
        print(f"{k:<{width}}  {v}")
    if out:
        print(f"results in {out}/ (results.parquet, summary.json, config.json, traces.parquet)")


def cmd_picks(args) -> int:
    from mjx_pick import pickpoints as pp
    from mjx_pick import plots
    from mjx_pick.config import write_atomic

    obj, gripper = _objects(args)
    cfg = _pick_config(args)
    picks = pp.generate_normal(obj, gripper, args.n, seed=args.seed, config=cfg)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    lines = ["pick_id,x_mm,y_mm,yaw_deg,opening_mm,coverage"]
    lines += [
        f"{i},{x:.4f},{y:.4f},{w:.4f},{o:.4f},{c:.4f}"
        for i, x, y, w, o, c in zip(
            picks.pick_id,
            picks.x_mm,
            picks.y_mm,
            picks.yaw_deg,
            picks.opening_mm,
            picks.coverage,
            strict=True,
        )
    ]
    write_atomic(out / "picks.csv", "\n".join(lines) + "\n")
    plots.draw_pick(
        obj,
        gripper,
        picks.x_mm[0],
        picks.y_mm[0],
        picks.yaw_deg[0],
        picks.opening_mm[0],
        out / "pick_0.png",
    )
    rng = np.random.default_rng(args.seed)
    checker = pp.FeasibilityChecker(obj, gripper, cfg)
    xr, yr = checker.ranges()
    cx, cy, cyaw = rng.uniform(-xr, xr, 2000), rng.uniform(-yr, yr, 2000), rng.uniform(0, 360, 2000)
    labels = np.asarray(pp.REASONS)[checker(cx, cy, cyaw)["reason"]]
    plots.draw_candidates(obj, cx, cy, cyaw, out / "candidates.png", labels=labels)
    print(
        f"{len(picks)} feasible pick-points of {picks.n_candidates} candidates; rejected "
        f"{picks.rejected}; written to {out}/ (picks.csv, pick_0.png, candidates.png)"
    )
    return 0


def cmd_presets(_args) -> int:
    from mjx_pick.gripper import load_gripper, preset_names

    for name in preset_names():
        g = load_gripper(name)
        print(
            f"{name:<16} stroke {g.stroke_mm:g} mm, finger {g.finger_width_mm:g} x "
            f"{g.finger_depth_mm:g} mm, force {g.force_min_n:g}-{g.force_max_n:g} N, "
            f"speed {g.speed_min_mm_s:g}-{g.speed_max_mm_s:g} mm/s"
        )
    return 0


def cmd_assets(_args) -> int:
    from mjx_pick.objects import asset_manifest

    for name, entry in sorted(asset_manifest().items()):
        print(
            f"{name:<12} {entry['description']} ({entry['thickness_mm']:g} mm, "
            f"{entry['mass_g']:.1f} g)"
        )
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap = argparse.ArgumentParser(prog="mjx-pick", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="command", required=True)

    ev = sub.add_parser("evaluate", help="simulate pick-points and write results")
    _add_object_args(ev)
    _add_gripper_args(ev)
    _add_physics_args(ev)
    _add_pick_args(ev)
    ev.add_argument("--picks", help="CSV of your own pick-points (x_mm, y_mm, yaw_deg)")
    ev.add_argument("--out", help="output folder")
    ev.add_argument("--resume", action="store_true", help="continue an interrupted run")
    ev.add_argument("--chunk-size", type=int,
                    help="pick-points per chunk written to disk (default: from device memory)")
    ev.add_argument("--traces", type=int, default=3, help="traces of the n best and n worst")
    ev.add_argument("--until", type=int, help="Optimization mode: stop after K good pick-points")
    ev.add_argument("--min-score", type=float, default=0.9, help="Optimization threshold")
    ev.add_argument("--max", type=int, help="Optimization mode: most pick-points to simulate")
    ev.add_argument("--no-progress", action="store_true")
    ev.set_defaults(func=cmd_evaluate)

    pk = sub.add_parser("picks", help="generate feasible pick-points and draw them")
    _add_object_args(pk)
    _add_gripper_args(pk)
    _add_pick_args(pk)
    pk.add_argument("--out", required=True)
    pk.set_defaults(func=cmd_picks)

    sub.add_parser("presets", help="list gripper presets").set_defaults(func=cmd_presets)
    sub.add_parser("assets", help="list shipped objects").set_defaults(func=cmd_assets)
    return ap


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except ConfigError as err:
        print(f"mjx-pick: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
