"""MJX-JAX at the differentiable physics against MuJoCo C: labels, time per pick, and
forward-mode derivatives.

For each part, the same pick-points (``generate_normal``, seed 0, the default procedure)
run on

* MuJoCo C at the default physics (``SolverParams()``, ``ContactParams()``),
* MuJoCo C and MJX-JAX at the differentiable physics (``SolverParams.differentiable()``,
  ``ContactParams.differentiable()``: what the 'mjx' backend runs).

Per part: each engine's run time per pick (wall and this process's CPU seconds; MJX's
program compiled before the timed run), success rates, the share of MJX's labels equal
to C's at the same physics and to C's at the default physics, and C's own labels at the
two physics against each other (95 % Wilson intervals); and whether ``jax.jvp`` through
whole rollouts with respect to the pad friction (calibration's ``jvp`` estimator's
mapping) is finite on the first ``--jvp-picks`` pick-points.

    python benchmarks/mjx_physics.py --objects block,door_opener,l_bracket --n 128 \\
        --out benchmarks/results/mjx_physics_cpu.json

MJX-JAX at the default physics is not run here (the backend refuses it):
``benchmarks/mjx_step_profile.py`` measures what one control period costs there.
Figures: benchmarks/RESULTS.md, "mjx_physics.py".
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from real_objects import load_ycb, ycb_manifest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.metrics import wilson_interval
from mjx_pick.engine.inputs import pick_inputs, scene_of
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels.types import FAILURES

# the results whose forward-mode derivatives are checked
JVP_FIELDS = ("lift_height_mm", "t_reached_s", "slip_mm", "yaw_max_deg", "max_force_left_n")


def agreement(a, b) -> dict:
    """How many of two label vectors are equal, with a 95 % Wilson interval."""
    same = int(np.sum(np.asarray(a) == np.asarray(b)))
    n = len(a)
    lo, hi = wilson_interval(same, n)
    share = round(same / n, 4)
    return {"equal": same, "n": n, "share": share, "wilson95": [round(lo, 4), round(hi, 4)]}


def jvp_finite(scene, settings, picks, n: int) -> dict:
    """Forward-mode derivatives of JVP_FIELDS of n picks' whole rollouts with respect to
    the pad friction (calibration's mapping, ``contact_arrays_jnp``): finite or not."""
    import jax
    import jax.numpy as jnp

    from mjx_pick.engine.simulator import differentiable_rollout
    from mjx_pick.studies.calibration.parameters import contact_arrays_jnp

    inp = pick_inputs(scene, settings, picks.take(np.arange(n)))
    roll = differentiable_rollout(scene, settings.grasp, False)

    def results(mu):
        fr, ref, force = contact_arrays_jnp(
            ["pad_friction"], [mu], inp, scene, settings, scene.object.mass_kg
        )
        params = inp.params._replace(grip_force_n=force)
        out, _ = roll(inp.qpos0, params, fr, ref, inp.pair_solimp)
        return {k: out[k] for k in JVP_FIELDS}

    t0 = time.perf_counter()
    mu = jnp.float32(settings.contact.pad_friction)
    _, tangents = jax.jit(lambda m: jax.jvp(results, (m,), (jnp.float32(1.0),)))(mu)
    tangents = {k: np.asarray(v) for k, v in tangents.items()}
    finite = np.all([np.isfinite(v) for v in tangents.values()], axis=0)
    return {
        "picks": n,
        "finite_picks": int(finite.sum()),
        "wall_s": round(time.perf_counter() - t0, 1),  # compile and run
        "d_lift_height_mm_d_mu": np.round(tangents["lift_height_mm"], 3).tolist(),
    }


def timed(run) -> tuple[dict, dict]:
    """(results, times) of run(), a Runner call: its simulating seconds (``run_s``,
    compiles apart) and this process's CPU seconds over the call (``cpu_s``)."""
    c0 = time.process_time()
    outcome = run()
    return outcome.results, {"run_s": outcome.timing.run_s, "cpu_s": time.process_time() - c0}


def compile_first(backend, inputs) -> float:
    """Compile backend's batch program for inputs (every batch is padded to the batch
    size: one program) before the timed run, so that the run's CPU seconds are the
    simulation's alone; the compile's wall seconds."""
    import jax

    args = tuple(
        jax.device_put(a, backend.sharding)
        for a in inputs.take(slice(0, backend.batch_size)).pad_to(backend.batch_size)
    )
    backend._compiled_for(args, False)
    return backend.stats.compile_s


def per_pick(times: dict, n: int) -> dict:
    return {f"{k}_per_pick": round(v / n, 3) for k, v in times.items()}


def summary(results) -> dict:
    """Success rate, divergences and the failure reasons' counts of one run."""
    failures = Counter(FAILURES[int(f)] for f in results["failure"])
    return {
        "success": round(float(np.mean(results["success"])), 4),
        "diverged": int(np.sum(results["diverged"])),
        "failures": dict(sorted(failures.items())),
    }


def run_part(name: str, obj, args) -> dict:
    """One part: C at the default physics, C and MJX at the differentiable physics."""
    gripper = mp.load_gripper(args.gripper)
    picks = pp.generate_normal(obj, gripper, args.n, seed=0)
    n = len(picks)
    row = {"object": name, "n": n}
    c_runner = Runner("mujoco", nthread=args.threads)
    labels = {}
    for physics, settings in (
        ("default", mp.Settings(gripper)),
        ("differentiable", mp.Settings(
            gripper, mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
        )),
    ):  # fmt: skip
        scene = scene_of(obj, settings)
        inputs = pick_inputs(scene, settings, picks)
        c, t = timed(lambda: c_runner.simulate(scene, settings.grasp, inputs))  # noqa: B023
        row[f"c_{physics}"] = {**summary(c), **per_pick(t, n)}
        labels[f"c_{physics}"] = c["success"]
    # MJX at the differentiable physics (scene, settings, inputs: the loop's last)
    runner = Runner("mjx", args.batch)
    backend = runner.make(scene, settings.grasp)
    compile_s = compile_first(backend, inputs)
    j, t = timed(lambda: runner.run(backend, inputs))
    row["mjx_differentiable"] = {
        **summary(j),
        **per_pick(t, n),
        "device": backend.device,
        "batch": backend.batch_size,
        "compile_s": round(compile_s, 1),
    }
    labels["mjx_differentiable"] = j["success"]
    row["mjx_vs_c_differentiable"] = agreement(j["success"], labels["c_differentiable"])
    row["mjx_vs_c_default"] = agreement(j["success"], labels["c_default"])
    row["c_differentiable_vs_c_default"] = agreement(
        labels["c_differentiable"], labels["c_default"]
    )
    failure = {"mjx": j["failure"], "c": c["failure"]}  # c: the differentiable physics
    row["failure_equal_differentiable"] = agreement(failure["mjx"], failure["c"])
    if args.jvp_picks:
        row["jvp"] = jvp_finite(scene, settings, picks, min(args.jvp_picks, n))
    row["labels"] = {k: np.asarray(v).astype(int).tolist() for k, v in labels.items()}
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--objects", default="block,door_opener,l_bracket")
    ap.add_argument("--gripper", default="robotiq-2f85")
    ap.add_argument("--n", type=int, default=128, help="pick-points per part")
    ap.add_argument("--batch", type=int, default=None, help="MJX batch (default: the backend's)")
    ap.add_argument("--threads", type=int, default=None, help="MuJoCo C threads")
    ap.add_argument("--jvp-picks", type=int, default=4, help="picks whose derivatives are checked")
    ap.add_argument("--out", default="benchmarks/out/mjx_physics.json")
    args = ap.parse_args()
    manifest = ycb_manifest()
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True, check=False
    ).stdout.strip()
    report = {
        "command": " ".join(["python", *sys.argv]),
        "commit": commit,
        "date": time.strftime("%Y-%m-%d"),
        "cpus": os.cpu_count(),
        "rows": [],
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    for name in args.objects.split(","):
        obj = load_ycb(name) if name in manifest else mp.load_asset(name)
        row = run_part(name, obj, args)
        row["load_avg"] = round(os.getloadavg()[0], 1)
        report["rows"].append(row)
        print(json.dumps({k: v for k, v in row.items() if k != "labels"}), flush=True)
        tmp = out.with_suffix(".tmp")
        tmp.write_text(json.dumps(report, indent=1))
        tmp.replace(out)


if __name__ == "__main__":
    main()
