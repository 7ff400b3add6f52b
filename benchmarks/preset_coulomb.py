"""Coulomb's law on the shipped gripper presets with the default procedure (issue 32).

For each preset, centred blocks over masses, heights and pad frictions, one batch per
(preset, mass, height): each friction at 1.3x eq. (1)'s force with the lift
acceleration (must hold) and at 0.8x the static need (must slip), where the preset can
set that force. Reports wrong labels, diverged picks, the largest pad force against the
preset's force_max_n, and chatter (a pad's force dropping to ~0 and returning while the
part is held, counted on the per-tick trace).

    python benchmarks/preset_coulomb.py                     # all presets, MuJoCo C
    python benchmarks/preset_coulomb.py --presets robotiq-2f85 --solver s.toml
    python benchmarks/preset_coulomb.py --offset-um 0       # exactly centred
    python benchmarks/preset_coulomb.py --backend warp --copies 3 --step-check

--copies K runs every case K times in its batch (on MuJoCo Warp the copies differ: its
contact order comes from atomic counters); --step-check runs every case again at half
the time step, as `evaluate --step-check` does, and counts the wrong labels it flags.

The blocks are "centred" to within a measurement: --offset-um (default 20 um along the
grip axis, 0.5 mm along the pads and 0.2 deg of yaw), since an exactly symmetric pick
hides what any real, image-derived part shows (benchmarks/results/history.md, "The preset
grid's CI subset, and the README demo").
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import time

import numpy as np
from real_objects import multiccd_off  # benchmarks/ is on sys.path when run
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import load_toml, write_json
from mjx_pick.core.physics import load_contact
from mjx_pick.core.procedure import G, GraspConfig
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.kernels import grasp as gk
from mjx_pick.studies.evaluation import half_step

PRESETS = ("robotiq-2f85", "robotiq-2f85-linkage", "robotiq-2f140", "onrobot-rg2", "franka-hand")
MASSES = (0.01, 0.1, 0.5, 2.0)
HEIGHTS = (3.0, 30.0, 60.0)
FRICTIONS = (0.05, 0.1, 0.3, 1.0)


def cases(gripper, grasp, mass, mus):
    """(mu, factor, force, must_hold) within the gripper's force range. The holding
    case is raised to the gripper's floor where 1.3x is below it (more force still
    must hold); a slip case below the floor cannot be set and is skipped."""
    a = grasp.lift_accel_mm_s2 * 1e-3
    rows = []
    for mu in mus:
        hold = max(1.3 * mass * (G + a) / (2 * mu), gripper.force_min_n)
        slip = 0.8 * mass * G / (2 * mu)
        if hold <= gripper.force_max_n:
            rows.append((mu, 1.3, hold, True))
        if gripper.force_min_n <= slip <= gripper.force_max_n:
            rows.append((mu, 0.8, slip, False))
    return rows


def chatter_events(trace, force_n, fraction=0.02):
    """Times a pad's force fell below fraction x F_d and came back above it while the
    part was held (LIFT/HOLD phases, after both pads gripped)."""
    f = gk.TRACE_FIELDS
    phase = trace[:, f.index("phase")]
    window = (phase == gk.LIFT) | (phase == gk.HOLD)
    n = 0
    for name in ("force_left_n", "force_right_n"):
        touching = trace[window, f.index(name)] > fraction * force_n
        if not touching.any():
            continue
        # a drop and a return: a False run between two True
        first, last = np.argmax(touching), len(touching) - np.argmax(touching[::-1]) - 1
        inner = touching[first : last + 1]
        n += int(np.sum(inner[1:] & ~inner[:-1]))
    return n


def run_preset(
    name,
    solver,
    contact_base,
    grasp,
    masses,
    heights,
    mus,
    offset_um,
    backend,
    overrides=None,
    copies=1,
    step_check=False,
):
    gripper = mp.load_gripper(name)
    if overrides and gripper.mjcf is None:  # parametric presets only
        gripper = dataclasses.replace(gripper, **overrides)
    rows = []
    width = round(0.55 * gripper.stroke_mm)  # gripped across x
    for mass, height in itertools.product(masses, heights):
        cs = [c for c in cases(gripper, grasp, mass, mus) for _ in range(copies)]
        if not cs:
            continue
        block = mp.object_from_polygon(
            box(-width / 2, -15, width / 2, 15), thickness_mm=height, mass_g=mass * 1e3
        )
        n = len(cs)
        checker = pp.FeasibilityChecker(block, gripper, grasp=grasp)
        off = offset_um * 1e-3
        picks = checker.batch(
            np.arange(n),
            np.full(n, off),
            np.full(n, 25 * off),
            np.full(n, 10 * off),
            mode="user",
        )
        assert len(picks) == n, picks.rejected
        scene = mp.build_scene(block, gripper, contact_base, solver, grasp)
        runner = make_backend(backend, scene, grasp, batch_size=n)
        per_pick = dict(
            pad_friction=np.array([c[0] for c in cs], np.float32),
            grip_force_n=np.array([c[2] for c in cs], np.float32),
        )
        out, traces = runner.run(make_inputs(scene, grasp, picks, per_pick), record=True)
        if step_check:
            half = mp.build_scene(block, gripper, contact_base, half_step(solver), grasp)
            half_runner = make_backend(backend, half, grasp, batch_size=n)
            half_out, _ = half_runner.run(make_inputs(half, grasp, picks, per_pick))
        for i, (mu, factor, force, hold) in enumerate(cs):
            fmax = max(out["max_force_left_n"][i], out["max_force_right_n"][i])
            rows.append(
                dict(
                    preset=name,
                    mass_kg=mass,
                    height_mm=height,
                    mu=mu,
                    factor=factor,
                    force_n=round(float(force), 3),
                    must_hold=hold,
                    success=bool(out["success"][i]),
                    failure=gk.FAILURES[int(out["failure"][i])],
                    diverged=bool(out["diverged"][i]),
                    max_pad_n=float(fmax),
                    over_max=float(fmax / gripper.force_max_n),
                    chatter=chatter_events(traces[i], force),
                    slip_mm=float(out["slip_mm"][i]),
                    copy=i % copies,
                )
            )
            if step_check:
                rows[-1]["success_half_step"] = bool(half_out["success"][i])
    return rows


def summarise(rows):
    by = {}
    for r in rows:
        by.setdefault(r["preset"], []).append(r)
    print(
        f"{'preset':22s} {'cases':>5s} {'wrong':>5s} {'held!':>5s} {'slip!':>5s} {'div':>4s} "
        f"{'chat>0':>6s} {'chat':>5s} {'F/Fmax':>6s}"
    )
    total = dict(cases=0, wrong=0, div=0, chat=0)
    for name, rs in by.items():
        wrong = [r for r in rs if r["success"] != r["must_hold"]]
        fn = sum(1 for r in wrong if r["must_hold"])  # dropped though it must hold
        fp = len(wrong) - fn
        div = sum(r["diverged"] for r in rs)
        chat = [r["chatter"] for r in rs if r["must_hold"]]
        print(
            f"{name:22s} {len(rs):5d} {len(wrong):5d} {fn:5d} {fp:5d} {div:4d} "
            f"{sum(c > 0 for c in chat):6d} {sum(chat):5d} {max(r['over_max'] for r in rs):6.2f}"
        )
        total["cases"] += len(rs)
        total["wrong"] += len(wrong)
        total["div"] += div
        total["chat"] += sum(c > 0 for c in chat)
    print("total", total)
    if all("success_half_step" in r for r in rows):
        wrong = [r for r in rows if r["success"] != r["must_hold"]]
        flagged = [r for r in wrong if r["success_half_step"] != r["success"]]
        right = [r for r in rows if r["success"] == r["must_hold"]]
        print(
            f"step check: {len(flagged)} of {len(wrong)} wrong labels flagged; "
            f"{sum(r['success_half_step'] != r['success'] for r in right)} of {len(right)} "
            f"right labels flagged; {sum(r['success_half_step'] != r['must_hold'] for r in rows)}"
            " wrong at half the step"
        )
    for r in rows:
        half = r.get("success_half_step", r["success"])
        if (
            r["success"] != r["must_hold"]
            or half != r["success"]
            or r["diverged"]
            or r["chatter"]
            or r["over_max"] > 1
        ):
            flag = "" if half == r["success"] else " step check: " + ("held" if half else "lost")
            print(
                f"  {r['preset']:20s} m {r['mass_kg']:5.2f} h {r['height_mm']:4.0f} mu "
                f"{r['mu']:4.2f} x{r['factor']} F {r['force_n']:7.2f}: {r['failure']:16s} "
                f"chatter {r['chatter']:3d} maxF {r['max_pad_n']:6.1f} ({r['over_max']:.2f}x max)"
                f" copy {r['copy']}{flag}"
            )


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--presets", default=",".join(PRESETS))
    ap.add_argument("--masses", default=",".join(map(str, MASSES)))
    ap.add_argument("--heights", default=",".join(map(str, HEIGHTS)))
    ap.add_argument("--frictions", default=",".join(map(str, FRICTIONS)))
    ap.add_argument("--solver", help="SolverParams TOML")
    ap.add_argument("--contact", help="ContactParams TOML")
    ap.add_argument("--offset-um", type=float, default=20.0)
    ap.add_argument("--backend", default="mujoco")
    ap.add_argument("--out", help="write the rows as JSON here")
    ap.add_argument("--copies", type=int, default=1, help="runs of every case in its batch")
    ap.add_argument(
        "--step-check", action="store_true", help="every case again at half the time step"
    )
    ap.add_argument(
        "--gripper-set",
        action="append",
        default=[],
        help="FIELD=VALUE override of the parametric presets' GripperSpec (repeatable)",
    )
    ap.add_argument("--no-multiccd", action="store_true", help="as real_objects.py's")
    args = ap.parse_args()
    solver = load_toml(mp.SolverParams, args.solver) if args.solver else mp.SolverParams()
    contact = load_contact(args.contact)[0] if args.contact else mp.ContactParams()
    grasp = GraspConfig()
    floats = lambda s: tuple(float(v) for v in s.split(","))  # noqa: E731
    t0 = time.perf_counter()
    rows = []
    with multiccd_off(args.no_multiccd):
        for name in args.presets.split(","):
            rows += run_preset(
                name,
                solver,
                contact,
                grasp,
                floats(args.masses),
                floats(args.heights),
                floats(args.frictions),
                args.offset_um,
                args.backend,
                {k: float(v) for k, v in (kv.split("=") for kv in args.gripper_set)},
                args.copies,
                args.step_check,
            )
            if args.out:  # after each preset: a run cut short keeps what it finished
                write_json(args.out, rows)
    summarise(rows)
    print(
        f"{len(rows)} picks in {time.perf_counter() - t0:.0f} s; "
        f"solver {dataclasses.asdict(solver)}"
    )


if __name__ == "__main__":
    main()
