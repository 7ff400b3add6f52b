"""Parameter sweeps: pick-points x parameter values, on a grid or at random.

Details: docs/studies.md (studies/sweeps.py).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import time
import typing
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjx_pick.core import numbers
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
    Number,
    describe_fields,
    to_dict,
    write_json,
    write_parquet,
)
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.metrics import rate_summary, results_table
from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.procedure import GraspConfig, check_clearance
from mjx_pick.core.settings import Settings
from mjx_pick.engine.simulator import Simulator, showing_progress
from mjx_pick.outputs.rundir import portable_object
from mjx_pick.studies.options import RunOptions

SECTIONS = {
    "contact": ContactParams,
    "grasp": GraspConfig,
    "gripper": GripperSpec,
    "solver": SolverParams,
}
ALIASES = {
    "controller.force_n": "grasp.grip_force_n",
    "controller.kp": "grasp.kp_mm_s_per_n",
    "controller.v_close": "grasp.closing_speed_mm_s",
    "controller.v_open": "grasp.opening_speed_mm_s",
}


def numeric_fields(cls) -> list[str]:
    """The fields of a settings dataclass that hold one number (sweepable)."""
    hints = typing.get_type_hints(cls)
    return [
        f.name
        for f in dataclasses.fields(cls)
        if hints[f.name] in (float, int, float | None, int | None)
    ]


def sweepable() -> list[str]:
    """Every parameter name a sweep accepts (aliases included)."""
    names = [f"{s}.{f}" for s, cls in SECTIONS.items() for f in numeric_fields(cls)]
    return sorted(names) + sorted(ALIASES)


def describe_params(prefix: str = "") -> list[dict]:
    """What ``mjx-pick params`` shows: for each parameter a sweep accepts (and the
    pick-point settings, which are set per run and not swept), its name, unit, default,
    allowed range and meaning -- read from the settings dataclasses' field declarations
    (``config.setting``), whose ranges are the ones their checks enforce. A sweep's
    value must also pass the checks between fields and against the gripper (e.g.
    grasp.grip_force_n within the gripper's force range).

    prefix: only names that start with it ("contact", "grasp.lift"); aliases are listed
    under the parameter they stand for. Each entry: name, unit, default, range,
    meaning, aliases (list), sweepable (bool).
    """
    aliases: dict[str, list[str]] = {}
    for alias, target in sorted(ALIASES.items()):
        aliases.setdefault(target, []).append(alias)
    rows = []
    sections = {**SECTIONS, "picks": pp.PickConfig}
    for section, cls in sections.items():
        numeric = set(numeric_fields(cls))
        for info in describe_fields(cls):
            if info["name"] not in numeric:
                continue
            name = f"{section}.{info['name']}"
            if not (
                name.startswith(prefix) or any(a.startswith(prefix) for a in aliases.get(name, []))
            ):
                continue
            rows.append(
                {
                    **info,
                    "name": name,
                    "aliases": aliases.get(name, []),
                    "sweepable": section in SECTIONS,
                }
            )
    if not rows:
        known = ", ".join([*sections, *sorted({a.partition(".")[0] for a in ALIASES})])
        raise ConfigError(f"no parameter starts with {prefix!r}: sections are {known}")
    return rows


def canonical(name: str) -> str:
    """'controller.force_n' -> 'grasp.grip_force_n'; checks that the name exists."""
    full = ALIASES.get(name, name)
    section, _, field = full.partition(".")
    if section not in SECTIONS or field not in numeric_fields(SECTIONS[section]):
        raise ConfigError(
            f"unknown parameter {name!r}: use section.field with a numeric field of "
            f"{', '.join(SECTIONS)} (e.g. contact.pad_friction, grasp.grip_force_n, "
            "gripper.finger_width_mm); `mjx-pick params` lists them all"
        )
    return full


def apply(settings: Settings, name: str, value: float) -> Settings:
    """Settings with one parameter changed (validated: a bad value is a ConfigError)."""
    section, _, field = canonical(name).partition(".")
    sub = getattr(settings, section)
    if isinstance(getattr(sub, field), int) and not isinstance(getattr(sub, field), bool):
        if float(value) != int(value):
            raise ConfigError(f"{name} = {value!r} must be a whole number")
        value = int(value)
    else:
        value = float(value)
    return dataclasses.replace(settings, **{section: dataclasses.replace(sub, **{field: value})})


@dataclasses.dataclass(frozen=True)
class ParamSpec:
    """One swept parameter: its values (grid or list) or its range (random)."""

    name: str  # canonical section.field
    label: str  # as the user wrote it
    values: tuple[float, ...] = ()
    low: float = math.nan
    high: float = math.nan
    log: bool = False

    @classmethod
    def parse(cls, text: str) -> ParamSpec:
        """'contact.pad_friction=0.4:1.0:7', '...=0.4,0.6,0.8', '...=0.4:1.0' (random)."""
        label, sep, spec = text.partition("=")
        label, spec = label.strip(), spec.strip()
        if not sep or not spec:
            raise ConfigError(
                f"--param {text!r}: write NAME=LO:HI:N, NAME=A,B,C or NAME=LO:HI (random)"
            )
        name = canonical(label)
        where = f"--param {text!r}: "
        value = Number()  # a swept value: any finite number (its field checks it)
        try:
            if ":" in spec:
                parts = spec.split(":")
                log = parts[-1] == "log"
                if log:
                    parts = parts[:-1]
                if len(parts) not in (2, 3):
                    raise ValueError("write LO:HI:N, LO:HI:N:log or LO:HI (random)")
                lo, hi = value.parse("LO", parts[0], where), value.parse("HI", parts[1], where)
                if len(parts) == 2:
                    return cls(name, label, (), lo, hi, log)
                n = numbers.INPUTS["grid_points"].parse("N", parts[2], where)
                if log and (lo <= 0 or hi <= 0):
                    raise ValueError("a log range needs positive ends")
                grid = np.geomspace(lo, hi, n) if log else np.linspace(lo, hi, n)
                return cls(name, label, tuple(float(v) for v in grid), lo, hi, log)
            cells = spec.split(",")
            numbers.INPUTS["grid_points"].check("the number of values", len(cells), where)
            values = tuple(value.parse("a value", v, where) for v in cells)
        except ValueError as err:
            if isinstance(err, ConfigError):
                raise
            raise ConfigError(f"{where}{err}") from err
        return cls(name, label, values, min(values), max(values))

    def draw(self, rng: np.random.Generator, n: int) -> np.ndarray:
        if not (math.isfinite(self.low) and math.isfinite(self.high)):
            raise ConfigError(f"--param {self.label}: a random sweep needs a range LO:HI")
        if self.log:
            return np.exp(rng.uniform(math.log(self.low), math.log(self.high), n))
        return rng.uniform(self.low, self.high, n)


def variants(params: list[ParamSpec], random: int | None = None, seed: int = 0) -> list[dict]:
    """Parameter combinations: the grid's cartesian product, or `random` uniform draws."""
    if not params:
        raise ConfigError("a sweep needs at least one --param")
    if len({p.name for p in params}) != len(params):
        raise ConfigError("each parameter may be swept once: " + ", ".join(p.label for p in params))
    if random is not None:
        random = numbers.check("random", random)
        rng = np.random.default_rng(seed)
        draws = {p.name: p.draw(rng, random) for p in params}
        return [{k: float(v[i]) for k, v in draws.items()} for i in range(random)]
    for p in params:
        if not p.values:
            raise ConfigError(f"--param {p.label}: a grid sweep needs LO:HI:N or A,B,C")
    sizes = [len(p.values) for p in params]
    most = int(numbers.INPUTS["variants"].hi)
    if math.prod(sizes) > most:  # counted before the product is made
        raise ConfigError(
            f"the grid has {math.prod(sizes)} variants ({' x '.join(map(str, sizes))} values); "
            f"at most {most}: use fewer values, or --random K variants"
        )
    return [
        dict(zip([p.name for p in params], combo, strict=True))
        for combo in itertools.product(*(p.values for p in params))
    ]


def _refuse_impossible(obj, combos: list[dict], settings: list, pick_config) -> None:
    """Refuse a sweep one of whose variants its gripper cannot run (a grip force or
    closing speed outside the gripper's range, ``check_gripper``) or no pick-point can
    fit (``stroke_refusal``), naming the variant: found now, before the folder is
    claimed -- not by the simulator after it, nor after drawing max_candidates."""
    seen: dict = {}
    for combo, s in zip(combos, settings, strict=True):
        values = ", ".join(f"{k}={v:g}" for k, v in combo.items())
        try:
            s.grasp.check_gripper(s.gripper)
            check_clearance(obj, s.grasp)
        except ConfigError as err:
            raise ConfigError(f"sweep variant {values}: {err}") from None
        key = (s.gripper, s.grasp)
        if key not in seen:
            seen[key] = pp.stroke_refusal(obj, s.gripper, pick_config, s.grasp)
        if seen[key] is not None:
            raise ConfigError(f"sweep variant {values}: {seen[key]}")


@dataclasses.dataclass
class SweepResult:
    table: pa.Table  # one row per pick-point x variant, with one column per parameter
    variants: list[dict]  # per variant: parameter values and rate_summary()
    timing: dict  # simulations, scenes built, compile_s apart from run_s, per second
    out_dir: Path | None
    # resume found the sweep already complete: read back, nothing simulated
    already_complete: bool = False


def sweep(
    obj: ObjectModel,
    params: list[ParamSpec],
    base: Settings | None = None,
    options: RunOptions | None = None,
    *,
    random: int | None = None,
    simulator: Simulator | None = None,
    **run,
) -> SweepResult:
    """Simulate n pick-points (default 200) under every parameter variant; see the
    module docstring.

    options (or its fields as keywords: n, seed, pick_config, backend, batch_size, out,
    overwrite, resume, ray, progress; ``options.RunOptions``): out is the folder for the
    results (refused before any simulation when another command wrote it, unless
    overwrite); finished chunks are saved there as the sweep goes
    (``engine.chunks.ChunkStore``) and removed once its outputs are written. resume:
    continue an interrupted sweep of this configuration in out from its chunks (on a
    complete one: read it back, simulate nothing). ray: run the variants on a Ray
    cluster ("auto" or "HOST:PORT"; mjx_pick.engine.cluster), this process writing out.
    progress: a progress bar of the simulations on stderr. simulator: run through this
    one (kept open; backend, batch_size and ray are then its own).
    """
    opts = RunOptions.of(options, **run)
    base = base or Settings()
    n, seed, pick_config = opts.n_or(200), opts.seed, opts.picks
    request = {"object": portable_object(obj.summary()), "base": to_dict(base)}
    request.update(params=to_dict(params), n=n, seed=seed, random=random)
    request.update(picks=to_dict(pick_config))
    combos = variants(params, random, seed)
    settings = [_variant_settings(base, combo) for combo in combos]
    _refuse_impossible(obj, combos, settings, pick_config)  # before any draw or folder
    numbers.check("sweep_simulations", len(combos) * n, "variants x pick-points")
    with opts.opening("sweep", obj, request, simulator) as study:
        if study.complete:
            return _read_sweep(study.out_dir)
        jobs = _jobs(obj, settings, n, seed, pick_config, opts)
        sim = study.sim
        before, t0 = sim.runner.timing, time.perf_counter()
        desc = f"sweep: {len(jobs)} variants ({sim.runner.backend_name})"
        with showing_progress(sim.runner, desc, "sim", opts.progress):
            outs = sim.run(jobs, study.store)
        timing = _timing(sim, sim.runner.timing - before, time.perf_counter() - t0, jobs)
        if study.store is not None:
            timing["chunks_resumed"] = study.store.read_chunks  # read back, not simulated
        table, summaries = _variant_tables(jobs, outs, combos)
        if study.out_dir is not None:
            config = {"object": obj.summary(), "base": to_dict(base)}
            config.update(params=[to_dict(p) for p in params], random=random, n=n, seed=seed)
            config.update(picks=to_dict(pick_config))
            meta = {
                "backend": sim.backends[0].name if sim.backends else opts.backend,
                "device": sim.backends[0].device if sim.backends else None,
                "timing": timing,
            }
            _write_sweep(study.out_dir, {**config, **meta}, table, summaries, params)
            study.close(config, meta)
        return SweepResult(table, summaries, timing, study.out_dir)


def _variant_settings(base: Settings, combo: dict) -> Settings:
    """A variant's settings (:func:`_settings`); a value its settings refuse is a
    ConfigError naming the variant as well as the field."""
    try:
        return _settings(base, combo)
    except ConfigError as err:
        values = ", ".join(f"{k}={v:g}" for k, v in combo.items())
        raise ConfigError(f"sweep variant {values}: {err}") from None


def _settings(base: Settings, combo: dict) -> Settings:
    """base with one variant's parameter values (``apply``: each by its name)."""
    s = base
    for name, value in combo.items():
        s = apply(s, name, value)
    return s


def _jobs(obj, settings: list[Settings], n, seed, pick_config, opts) -> list[tuple]:
    """(settings, grasps) per variant: the same grasps for every variant of one gripper
    (drawn once per gripper, from opts' grasp source: ``grasp_sources``)."""
    from mjx_pick.studies.grasp_sources import draw_grasps

    picks_for: dict[GripperSpec, pp.GraspBatch] = {}
    for s in settings:
        if s.gripper not in picks_for:
            picks_for[s.gripper] = draw_grasps(
                obj,
                s,
                n,
                seed,
                pick_config,
                opts.grasps,
                antipodal=opts.antipodal,
                depth_mm=opts.depth_mm,
            )
    return [(s, picks_for[s.gripper]) for s in settings]


def _timing(sim, spent, wall: float, jobs) -> dict:
    """A sweep's timing: its own compiles and runs (spent: the runner's timing since it
    began), scenes and programs, simulations per second."""
    n_sims = sum(len(p) for _, p in jobs)
    return {
        "simulations": n_sims,
        "scenes": sim.scenes,  # compiled MuJoCo models
        "programs": len(sim.backends),  # backends (compiled programs on MJX/Warp)
        "compile_s": round(spent.compile_s, 3),
        "run_s": round(spent.run_s, 3),
        "wall_s": round(wall, 3),
        "simulations_per_s": round(n_sims / spent.run_s, 2) if spent.run_s > 0 else None,
    }


def _write_sweep(out_dir: Path, config: dict, table, summaries, params) -> None:
    """A sweep's outputs: its configuration, results, variants and picture."""
    write_json(out_dir / "config.json", config)
    write_parquet(out_dir / "results.parquet", table)
    write_json(out_dir / "variants.json", summaries)
    plot_sweep(summaries, table, [p.name for p in params], out_dir / "sweep.png")


def _variant_tables(jobs, outs, combos) -> tuple[pa.Table, list[dict]]:
    """The sweep's table (one row per pick-point x variant, with the variant's index and
    parameter values as columns) and one summary per variant (rates, diverged runs)."""
    tables, summaries = [], []
    for v, ((variant, picks), out_v, combo) in enumerate(zip(jobs, outs, combos, strict=True)):
        extra = {"variant": np.full(len(picks), v)}
        extra.update({name: np.full(len(picks), value) for name, value in combo.items()})
        tables.append(results_table(picks, out_v, variant.gripper, extra))
        summaries.append(
            {
                "variant": v,
                **combo,
                **rate_summary(out_v["success"], out_v["score"]),
                "diverged": int(np.sum(out_v["diverged"])),
            }
        )
    return pa.concat_tables(tables), summaries


def _read_sweep(out_dir: Path) -> SweepResult:
    """A complete sweep's folder read back (resume has nothing to do)."""
    import json

    import pyarrow.parquet as pq

    table = pq.read_table(out_dir / "results.parquet")
    summaries = json.loads((out_dir / "variants.json").read_text())
    timing = json.loads((out_dir / "config.json").read_text()).get("timing", {})
    return SweepResult(table, summaries, timing, out_dir, already_complete=True)


def marginal(table: pa.Table, name: str) -> list[dict]:
    """Success rate and mean score against one parameter, pooled over the others."""
    values = np.asarray(table[name], float)
    success = np.asarray(table["success"], bool)
    score = np.asarray(table["score"], float)
    return [
        {"value": float(v), **rate_summary(success[values == v], score[values == v])}
        for v in np.unique(values)
    ]


def plot_sweep(
    summaries: list[dict], table: pa.Table, names: list[str], path, labels: dict | None = None
) -> None:
    """Success rate (Wilson 95%) and mean score (95%) against each parameter, PNG;
    labels: each parameter's axis label (default: its name, as the command took it)."""
    from mjx_pick.outputs.plots import new_figure, save_png

    fig, axes = new_figure(len(names), 2, figsize=(9, 3.2 * len(names)), squeeze=False)
    for row, name in zip(axes, names, strict=True):
        m = marginal(table, name)
        x = np.array([r["value"] for r in m])
        for ax, key, ci, label in (
            (row[0], "success_rate", "success_ci", "success rate"),
            (row[1], "score_mean", "score_ci", "mean score, eq. (2)"),
        ):
            y = np.array([r[key] for r in m])
            # intervals clipped to [0, 1] (a single sample's interval is infinite)
            lo = np.clip(np.array([r[ci][0] for r in m]), 0.0, y)
            hi = np.clip(np.array([r[ci][1] for r in m]), y, 1.0)
            if len(x) > 12:  # random sweep: points, not a line
                ax.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o", ms=3, alpha=0.6)
            else:
                ax.errorbar(x, y, yerr=[y - lo, hi - y], fmt="o-", capsize=3)
            ax.set_xlabel((labels or {}).get(name, name))
            ax.set_ylabel(label)
            ax.set_ylim(-0.02, 1.02)
            ax.grid(alpha=0.3)
    fig.suptitle(f"sweep: {len(summaries)} variants, {table.num_rows} simulations")
    fig.tight_layout()
    save_png(fig, path)
