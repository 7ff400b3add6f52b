"""Throughput measurement: pick-points per second against batch size, per backend.

Used by ``benchmarks/throughput.py`` (CSV rows) and the throughput
notebook; ``plot_throughput`` draws rows against the paper's figures. ``side_by_side``
runs several backends (Warp, MJX's JAX physics, MuJoCo C) on the same pick-points and
compares their labels with MuJoCo C's. Both run through ``mjx_pick.engine.runner.Runner``,
each timed run as ONE backend call (one chunk), so a refilled pool is measured whole.
"""

from __future__ import annotations

import dataclasses
import statistics
import time
import warnings

import jax
import numpy as np

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.objects import load_object
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.settings import Settings
from mjx_pick.engine import registry
from mjx_pick.engine.backend import plan_jax
from mjx_pick.engine.inputs import make_inputs, scene_of
from mjx_pick.engine.runner import Runner

# Bencak et al. 2023: ~53 s for one simulation; ~4.5 s per simulation with 12 parallel
# MATLAB workers, i.e. about 0.22 pick-points per second
PAPER_SECONDS_PER_PICK = 53.0
PAPER_PICKS_PER_S_12_WORKERS = 0.22


def device_name(n: int | None = None) -> str:
    d = jax.devices()[0]
    n = n or len(jax.devices())
    return f"{n}x {d.device_kind}" if d.platform != "cpu" else "cpu"


def peak_bytes(backend=None) -> int | None:
    """Peak device memory: the backend's own report (Warp's memory pool), else JAX's
    allocator (MJX programs); None on the CPU."""
    if backend is not None and hasattr(backend, "peak_device_bytes"):
        return backend.peak_device_bytes()
    stats = jax.devices()[0].memory_stats() if jax.devices()[0].platform != "cpu" else None
    return None if not stats else int(stats.get("peak_bytes_in_use", 0))


def tile_picks(picks: pp.GraspBatch, n: int, offset: int) -> pp.GraspBatch:
    idx = (np.arange(n) + offset) % len(picks)
    return picks.take(idx)


def _physics_of(backend: str, solver: SolverParams, contact: ContactParams):
    """(solver, contact) a backend simulates: MJX-JAX's differentiable physics for it
    (it refuses any other: ``mjx_backend.check_physics``), else the ones given."""
    if registry.entry(backend).differentiable:
        return SolverParams.differentiable(solver), ContactParams.differentiable(contact)
    return solver, contact


def measure(obj_name, gripper, backend_name, batch, repeats, grasp, solver, n_devices=None):
    """One throughput row: compile time apart from run time (median of repeats over
    distinct pick-point sets, after a warm-up run), pick-points and physics steps per
    second, peak device memory per pick-point (MJX on GPU), success rate.

    repeats = 0 times the first run itself (its compile is already apart: MJX compiles
    ahead of time), for runs where device time is short."""
    obj = load_object(obj_name)
    solver, contact = _physics_of(backend_name, solver, ContactParams())
    scene = scene_of(obj, Settings(gripper, contact, solver, grasp))
    pool = pp.generate_normal(obj, gripper, min(max(batch, 256), 20000), seed=0, grasp=grasp)
    devices = jax.local_devices()[:n_devices] if n_devices else None
    # one chunk per call: each timed call is one backend call of `batch` pick-points
    runner = Runner(backend_name, batch, chunk_size=batch, devices=devices)
    backend = runner.make(scene, grasp)
    steps = grasp.n_ticks() * grasp.substeps(scene.solver)
    first = runner.run(backend, make_inputs(scene, grasp, tile_picks(pool, batch, 0)))
    out = first.results  # compiled, then ran once (warm-up)
    compile_s = first.timing.compile_s
    times = [] if repeats else [first.timing.run_s]
    for r in range(repeats):
        inputs = make_inputs(scene, grasp, tile_picks(pool, batch, (r + 1) * 7919))
        timed = runner.run(backend, inputs)
        out = timed.results
        times.append(timed.timing.run_s)
    run_s = statistics.median(times)
    peak = peak_bytes()
    return {
        "object": obj_name,
        "backend": backend.name,
        "device": backend.device if _on_cpu(backend.name) else device_name(n_devices),
        "batch": batch,
        "compile_s": round(compile_s, 2),
        "first_call_s": round(first.timing.wall_s, 2),
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


@dataclasses.dataclass(frozen=True)
class RunSpec:
    """One backend run of a side-by-side comparison.

    n: pick-points (the first n of the shared set); batch: the backend's batch size
    (MJX/Warp: slots of the pool with refill); options: make_backend options (refill,
    ticks_per_call, graph_mode); warmup: pick-points run once before the timed run
    (MJX/Warp: a full-length first call also builds Warp's kernels and captures its
    CUDA graphs; 0: none).
    """

    backend: str
    n: int
    batch: int
    options: tuple = ()
    warmup: int = 0
    solver: tuple = ()  # SolverParams fields replaced for this run (iterations, ...)
    contact: tuple = ()  # ContactParams fields replaced for this run (pad_collision)
    devices: int | None = None  # the first this many local devices (default: the backend's)
    grasps: str = "topdown"  # the shared set drawn from: top-down pick-points or antipodal

    @property
    def label(self) -> str:
        opts = "".join(f",{k}={v}" for k, v in self.options + self.solver + self.contact)
        gpus = f",devices={self.devices}" if self.devices else ""
        kind = f",grasps={self.grasps}" if self.grasps != "topdown" else ""
        return f"{self.backend}{opts}{gpus}{kind}"

    @classmethod
    def parse(cls, text: str) -> RunSpec:
        """'warp:n=65536:batch=16384:refill=1:ticks_per_call=20:warmup=16384'.

        Keys: n, batch, warmup, devices (ints); the backend's options that read from
        text (``registry.BackendEntry.options``), and rows (Warp's constraint rows per
        simulation; contacts sized as usual); solver settings iterations,
        ls_iterations, tolerance, timestep_s; the contact setting pad_collision; grasps
        (topdown or antipodal: the shared set the run takes its first n of)."""
        name, *parts = text.split(":")
        parsers = {o.name: o.parse for o in registry.entry(name).options if o.parse}
        parsers["rows"] = int  # becomes Warp's buffers (backend_options)
        fields: dict = {}
        options, solver, contact = [], [], []
        for part in parts:
            key, sep, value = part.partition("=")
            if not sep:
                raise ValueError(f"run {text!r}: {part!r} is not key=value")
            if key in ("n", "batch", "warmup", "devices"):
                fields[key] = int(value)
            elif key in parsers:
                options.append((key, parsers[key](value)))
            elif key in ("iterations", "ls_iterations"):
                solver.append((key, int(value)))
            elif key in ("tolerance", "timestep_s"):
                solver.append((key, float(value)))
            elif key in ("pad_collision",):
                contact.append((key, value))
            elif key == "grasps":
                if value not in ("topdown", "antipodal"):
                    raise ValueError(f"run {text!r}: grasps={value!r}: topdown or antipodal")
                fields[key] = value
            else:
                raise ValueError(f"run {text!r}: unknown key {key!r}")
        if "n" not in fields:
            raise ValueError(f"run {text!r} needs n=")
        fields.setdefault("batch", fields["n"])
        return cls(
            name, options=tuple(options), solver=tuple(solver), contact=tuple(contact), **fields
        )

    def backend_options(self, scene, grasp) -> dict:
        """make_backend options; 'rows' becomes Warp buffers sized on the C engine with
        that many constraint rows."""
        opts = dict(self.options)
        if "rows" in opts:
            from mjx_pick.engine.warp_buffers import size_buffers

            sized = size_buffers(scene, grasp)
            opts["buffers"] = dataclasses.replace(sized, rows=opts.pop("rows"))
        if self.devices:
            if registry.entry(self.backend).cuda_devices:  # JAX is not involved
                opts["devices"] = [f"cuda:{i}" for i in range(self.devices)]
            else:
                opts["devices"] = jax.local_devices()[: self.devices]
        return opts


def side_by_side(obj_name, gripper, runs: list[RunSpec], grasp, solver, seed=0, on_row=None):
    """Run each RunSpec on the first n of one shared set of pick-points; one row each.

    Row fields: pick-points/s (timed run only: compile, Warp's buffer sizing and the
    warm-up apart), physics steps/s the device performed (every slot steps, finished or
    not), steps per pick-point actually simulated (to its end; refill only: the
    full-length rollout simulates n_ticks x substeps for every pick), slot occupancy
    (refill: the fraction of slot-steps spent on picks that had not ended), peak device
    memory per pick (JAX's allocator; Warp's own scratch is not in it), success rate,
    and labels (success, failure reason) agreeing with the reference backend's (MuJoCo
    C, ``registry.reference``) on the pick-points both ran, when it is among the runs.
    on_row(row) is called as each row is done (a long benchmark keeps what it measured
    if it is cut short).
    """
    plan_jax([r.backend for r in runs])
    obj = load_object(obj_name)
    sets: dict = {}  # per grasp source: (the shared set, its distinct grasps)

    def shared(kind: str):
        if kind not in sets:
            n_max = max(r.n for r in runs if r.grasps == kind)
            with warnings.catch_warnings():  # fewer feasible than asked: repeated below
                warnings.simplefilter("ignore", UserWarning)
                if kind == "antipodal":
                    from mjx_pick.core.antipodal import generate_antipodal

                    base = scene_of(obj, Settings(gripper, ContactParams(), solver, grasp))
                    picks = generate_antipodal(base, n_max, seed=seed)
                else:
                    picks = pp.generate_normal(obj, gripper, n_max, seed=seed, grasp=grasp)
            # the generator stops at its candidate limit: repeat the set (each is
            # simulated on its own, so a repeat costs what a new one would)
            sets[kind] = (tile_picks(picks, n_max, 0) if len(picks) < n_max else picks, len(picks))
        return sets[kind]

    scenes: dict = {}  # per solver and contact variant and grasp source: (scene, inputs)

    def scene_for(spec: RunSpec):
        own = registry.entry(spec.backend).differentiable  # MJX-JAX: its own physics
        key = (spec.solver, spec.contact, own, spec.grasps)
        if key not in scenes:
            variant = dataclasses.replace(solver, **dict(spec.solver))
            contact = ContactParams(**dict(spec.contact))
            variant, contact = _physics_of(spec.backend, variant, contact)
            scene = scene_of(obj, Settings(gripper, contact, variant, grasp))
            scenes[key] = (scene, make_inputs(scene, grasp, shared(spec.grasps)[0]))
        return scenes[key]

    c_results: dict[tuple, dict] = {}  # MuJoCo C's results per contact variant
    rows = []
    # the reference first (MuJoCo C): the others' labels are compared with its
    first = registry.reference()
    order = sorted(runs, key=lambda r: r.backend != first)
    for spec in order:
        scene, inputs = scene_for(spec)
        n = min(spec.n, len(inputs))
        timing, out, backend = _timed_run(spec, scene, inputs.take(slice(0, n)), grasp)
        if spec.backend == first:
            c_results.setdefault((spec.contact, spec.grasps), out)
            reference = None
        else:
            reference = c_results.get((spec.contact, spec.grasps))
        row = {
            "object": obj_name,
            "run": spec.label,
            "backend": backend.name,
            "device": backend.device,
            "n": n,
            "grasps": spec.grasps,
            "distinct_picks": min(n, shared(spec.grasps)[1]),
        }
        row.update(_run_fields(backend, out, n, timing))
        row.update(_buffer_fields(backend, n))
        row.update(_agreement_with_c(reference, out, n))
        row.update(
            {
                "timestep_s": scene.solver.timestep_s,
                "cone": scene.solver.cone,
                "impratio": scene.solver.impratio,
                "pad_margin_mm": round(scene.contact.pad_margin_m * 1e3, 6),
                "iterations": scene.solver.iterations,
                "ls_iterations": scene.solver.ls_iterations,
                "tolerance": scene.solver.tolerance,
                "shrink_levels": getattr(backend, "shrink_levels", None),
                "devices": len(getattr(backend, "devices", [])) or None,
            }
        )
        rows.append(row)
        if on_row is not None:
            on_row(row)
    return rows


def _timed_run(spec: RunSpec, scene, inputs, grasp) -> tuple[dict, dict, object]:
    """One RunSpec on inputs: its backend built, warmed up and timed on one backend
    call (one chunk: a refilled pool runs it whole). Returns (its timing and step
    counts for :func:`_run_fields`, the results, the backend)."""
    n_sub = grasp.substeps(scene.solver)
    full_steps = grasp.n_ticks() * n_sub
    n = len(inputs)
    t_build = time.perf_counter()
    runner = Runner(spec.backend, spec.batch, **spec.backend_options(scene, grasp))
    backend = runner.make(scene, grasp)
    build_s = time.perf_counter() - t_build
    warm_s = 0.0
    if spec.warmup:
        warm = inputs.take(slice(0, min(spec.warmup, n)))
        warm_s = runner.run(backend, warm, chunk_size=len(warm)).timing.wall_s
    pool = getattr(backend, "pool_stats", None)
    before = dataclasses.replace(pool) if pool is not None else None
    compile_before = backend.stats.compile_s
    timed = runner.run(backend, inputs, chunk_size=n)
    refilled = pool is not None and pool.rounds > before.rounds
    if refilled:
        slot_ticks = pool.slot_ticks - before.slot_ticks
        pick_ticks = pool.pick_ticks - before.pick_ticks
        device_steps = slot_ticks * n_sub
        steps_per_pick = pick_ticks * n_sub / n
        occupancy = pick_ticks / slot_ticks
    elif registry.entry(spec.backend).stops_finished:
        device_steps = steps_per_pick = occupancy = None
    else:
        padded = -(-n // backend.batch_size) * backend.batch_size
        device_steps = padded * full_steps
        steps_per_pick = full_steps
        occupancy = n / padded
    timing = {
        "build_s": build_s,
        "compile_before": compile_before,
        "warm_s": warm_s,
        "run_s": timed.timing.run_s,
        "wall_s": timed.timing.wall_s,
        "device_steps": device_steps,
        "steps_per_pick": steps_per_pick,
        "full_steps": full_steps,
        "occupancy": occupancy,
        "peak": None if _on_cpu(spec.backend) else peak_bytes(backend),
    }
    if pool is not None and hasattr(pool, "steps_converged"):
        steps = pool.steps - before.steps
        timing["solver"] = {
            "steps_all_converged": round((pool.steps_converged - before.steps_converged) / steps, 4)
            if steps
            else None,
            "solver_iterations_median": pool.iteration_quantile(0.5),
            "solver_iterations_p99": pool.iteration_quantile(0.99),
            "solver_iterations_max": int(np.flatnonzero(pool.solver_iterations).max(initial=0)),
        }
    return timing, timed.results, backend


def _on_cpu(backend: str) -> bool:
    """Whether a backend runs on CPU threads (no device name, no device memory)."""
    return registry.entry(backend).device is registry.Device.CPU


def _run_fields(backend, out: dict, n: int, t: dict) -> dict:
    """A row's timing, step, memory and outcome fields (t: :func:`_timed_run`'s)."""
    run_s, device_steps, steps_per_pick = t["run_s"], t["device_steps"], t["steps_per_pick"]
    occupancy, peak = t["occupancy"], t["peak"]
    return {
        "batch": backend.batch_size,
        "setup_s": round(t["build_s"], 2),
        "compile_s": round(backend.stats.compile_s, 2),
        "compile_in_run_s": round(backend.stats.compile_s - t["compile_before"], 2),
        "warmup_s": round(t["warm_s"], 2),
        "run_s": round(run_s, 3),
        "wall_s": round(t["wall_s"], 3),
        "picks_per_s": round(n / run_s, 1),
        "physics_steps_per_s": round(device_steps / run_s) if device_steps else None,
        "steps_per_pick": round(steps_per_pick, 1) if steps_per_pick else None,
        "full_steps_per_pick": t["full_steps"],
        "occupancy": round(occupancy, 4) if occupancy is not None else None,
        "peak_mem_mb_per_pick": round(peak / backend.batch_size / 2**20, 3) if peak else None,
        "success_rate": round(float(np.mean(out["success"])), 4),
        "diverged": int(np.sum(out["diverged"])),
        **t.get("solver", {}),
    }


def _buffer_fields(backend, n: int) -> dict:
    """Warp's contact and constraint buffers and what the run used of them ({} for a
    backend without them)."""
    buffers = getattr(backend, "buffers", None)
    if buffers is None:
        return {}
    diag = backend.last_diagnostics
    return {
        "buffer_contacts": buffers.contacts,
        "buffer_rows": buffers.rows,
        "measured_contacts_c": buffers.measured_contacts,
        "measured_rows_c": buffers.measured_rows,
        "max_rows_used": int(diag.nefc_max.max()),
        "max_contacts_used_per_world": round(
            float(diag.nacon_max.max()) / backend.pool_size(n)
            if getattr(backend, "refill", True)
            else float(diag.nacon_max.max()) / backend.batch_size,
            2,
        ),
        "buffer_growths": backend.growths,
    }


def _agreement_with_c(c: dict | None, out: dict, n: int) -> dict:
    """The run's labels (success, failure reason) against MuJoCo C's results c (the
    first C run with the same contact settings) on the pick-points both ran ({} without
    one, or for a C run)."""
    if c is None:
        return {}
    m = min(n, len(c["success"]))
    return {
        "labels_vs_c_n": m,
        "labels_agree_vs_c": round(float(np.mean(out["success"][:m] == c["success"][:m])), 4),
        "failure_agree_vs_c": round(float(np.mean(out["failure"][:m] == c["failure"][:m])), 4),
    }


def plot_throughput(rows: list[dict], path) -> None:
    """Pick-points per second against batch size, one line per (object, backend, device),
    with the paper's figures as horizontal lines (log scales)."""
    from mjx_pick.outputs.plots import new_figure, save_png

    fig, ax = new_figure(figsize=(7, 4.5))
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
