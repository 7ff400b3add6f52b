"""Throughput measurement: pick-points per second against batch size, per backend.

Used by ``benchmarks/throughput.py`` (CSV rows for RESULTS.md) and the throughput
notebook; ``plot_throughput`` draws rows against the paper's figures.
"""

from __future__ import annotations

import statistics
import time

import jax
import numpy as np

import mjx_pick as mp
from mjx_pick import pickpoints as pp
from mjx_pick.simulate import make_backend, make_inputs

# Bencak et al. 2023: ~53 s for one simulation; ~4.5 s per simulation with 12 parallel
# MATLAB workers, i.e. about 0.22 pick-points per second
PAPER_SECONDS_PER_PICK = 53.0
PAPER_PICKS_PER_S_12_WORKERS = 0.22


def device_name(n: int | None = None) -> str:
    d = jax.devices()[0]
    n = n or len(jax.devices())
    return f"{n}x {d.device_kind}" if d.platform != "cpu" else "cpu"


def peak_bytes() -> int | None:
    stats = jax.devices()[0].memory_stats() if jax.devices()[0].platform != "cpu" else None
    return None if not stats else int(stats.get("peak_bytes_in_use", 0))


def tile_picks(picks: pp.PickBatch, n: int, offset: int) -> pp.PickBatch:
    idx = (np.arange(n) + offset) % len(picks)
    return picks.take(idx)


def measure(obj_name, gripper, backend_name, batch, repeats, grasp, solver, n_devices=None):
    """One throughput row: compile time apart from run time (median of repeats over
    distinct pick-point sets, after a warm-up run), pick-points and physics steps per
    second, peak device memory per pick-point (MJX on GPU), success rate.

    repeats = 0 times the first run itself (its compile is already apart: MJX compiles
    ahead of time), for runs where device time is short."""
    obj = mp.load_object(obj_name)
    scene = mp.build_scene(obj, gripper, solver=solver)
    pool = pp.generate_normal(obj, gripper, min(max(batch, 256), 20000), seed=0)
    devices = jax.local_devices()[:n_devices] if n_devices else None
    backend = make_backend(backend_name, scene, grasp, batch_size=batch, devices=devices)
    steps = grasp.n_ticks() * grasp.substeps(scene.solver)
    first = make_inputs(scene, grasp, tile_picks(pool, batch, 0))
    t0 = time.perf_counter()
    out, _ = backend.run(first)  # compiles, then runs once (warm-up)
    first_wall = time.perf_counter() - t0
    compile_s = backend.stats.compile_s
    times = [] if repeats else [backend.stats.run_s]
    for r in range(repeats):
        inputs = make_inputs(scene, grasp, tile_picks(pool, batch, (r + 1) * 7919))
        before = backend.stats.run_s
        out, _ = backend.run(inputs)
        times.append(backend.stats.run_s - before)
    run_s = statistics.median(times)
    peak = peak_bytes()
    return {
        "object": obj_name,
        "backend": backend.name,
        "device": device_name(n_devices) if backend.name == "mjx" else backend.device,
        "batch": batch,
        "compile_s": round(compile_s, 2),
        "first_call_s": round(first_wall, 2),
        "run_s_median": round(run_s, 3),
        "picks_per_s": round(batch / run_s, 1),
        "physics_steps_per_s": round(batch * steps / run_s),
        "steps_per_pick": steps,
        "peak_mem_mb_per_pick": round(peak / batch / 2**20, 3) if peak else None,
        "success_rate": round(float(np.mean(out["success"])), 4),
        "diverged": int(np.sum(out["diverged"])),
        "timestep_s": scene.solver.timestep_s,
        "cone": scene.solver.cone,
        "iterations": scene.solver.iterations,
    }


def plot_throughput(rows: list[dict], path) -> None:
    """Pick-points per second against batch size, one line per (object, backend, device),
    with the paper's figures as horizontal lines (log scales)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from mjx_pick.plots import save_png

    fig, ax = plt.subplots(figsize=(7, 4.5))
    keys = sorted({(r["object"], r["backend"], r["device"]) for r in rows})
    for key in keys:
        sel = sorted(
            (r for r in rows if (r["object"], r["backend"], r["device"]) == key),
            key=lambda r: r["batch"],
        )
        ax.plot(
            [r["batch"] for r in sel],
            [r["picks_per_s"] for r in sel],
            "o-",
            label=" / ".join(str(k) for k in key),
        )
    ax.axhline(
        PAPER_PICKS_PER_S_12_WORKERS, color="r", ls="--", label="paper: 12 MATLAB workers (0.22/s)"
    )
    ax.axhline(
        1.0 / PAPER_SECONDS_PER_PICK, color="r", ls=":", label="paper: one simulation (53 s)"
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("batch size (pick-points per call)")
    ax.set_ylabel("pick-points per second")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    save_png(fig, path)
