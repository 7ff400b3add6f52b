"""The evaluate run a trials folder starts from, and the simulations it re-runs."""

from __future__ import annotations

import json
from pathlib import Path
from typing import NamedTuple

import jax
import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import (
    ConfigError,
)
from mjx_pick.core.objects import ObjectModel, check_same_object
from mjx_pick.core.settings import Settings
from mjx_pick.engine.inputs import pick_inputs, scene_of
from mjx_pick.engine.registry import AUTO
from mjx_pick.engine.runner import Runner
from mjx_pick.kernels import types as kt
from mjx_pick.outputs.rundir import read_manifest
from mjx_pick.studies.calibration.parameters import (
    ParamSpace,
    row_inputs,
)
from mjx_pick.studies.calibration.trials.sheet import PLAN
from mjx_pick.studies.recorded import settings_of


class RunSource(NamedTuple):
    """A finished evaluate folder: its results table, configuration and settings."""

    path: Path
    table: pa.Table
    config: dict
    settings: Settings
    pick_config: pp.PickConfig


def read_run(run_dir, obj: ObjectModel) -> RunSource:
    """An evaluate output folder, checked: finished, of this object, with its table."""
    path = Path(run_dir)
    if not path.is_dir():
        raise ConfigError(f"run {str(path)!r} is not a folder (give an evaluate --out folder)")
    manifest = read_manifest(path) or {}
    if manifest.get("command") not in (None, "evaluate"):
        raise ConfigError(
            f"run {path} holds the results of `mjx-pick {manifest['command']}`, not of "
            "`mjx-pick evaluate`: plan trials from an evaluate folder"
        )
    if manifest.get("status") not in (None, "complete"):
        raise ConfigError(
            f"run {path} did not finish (status {manifest['status']}): finish it with "
            "`mjx-pick evaluate ... --resume` first"
        )
    missing = [n for n in ("results.parquet", "config.json") if not (path / n).is_file()]
    if missing:
        raise ConfigError(f"run {path} is not an evaluate output folder: no {', '.join(missing)}")
    config = json.loads((path / "config.json").read_text())
    check_same_object(config.get("object") or {}, obj, f"run {path}")
    table = pq.read_table(path / "results.parquet")
    need = ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "success", "score", "failure")
    absent = [c for c in need if c not in table.column_names]
    if absent:
        raise ConfigError(f"run {path}: results.parquet has no column(s) {', '.join(absent)}")
    settings, picks = settings_of(config, f"run {path}/config.json")
    return RunSource(path, table, config, settings, picks)


class Simulations:
    """One compiled scene of base settings; each parameter vector is per-row data,
    mapped as a fit maps it (``parameters.row_inputs``: contact through
    ``physics.mujoco_contact``, F_d + force offset), so draws and fits simulate alike."""

    def __init__(self, obj: ObjectModel, settings: Settings, backend: str = AUTO, batch_size=None):
        s = settings
        self.object, self.settings = obj, s
        self.scene = scene_of(obj, s)
        self.runner = Runner(backend, batch_size)
        self._backend = None

    def run(self, picks: pp.GraspBatch, values: list[dict]) -> dict[str, np.ndarray]:
        """Simulate every pick-point (N) under each parameter vector (V dicts, name ->
        natural value; {} is the base settings) in ONE runner call.

        Returns (V, N) arrays: success (bool), score, failure (code, ``kernels.types.FAILURES``),
        diverged (bool), lift_height_mm."""
        if self._backend is None:
            self._backend = self.runner.make(self.scene, self.settings.grasp)
        n = len(picks)
        s = self.settings
        base = pick_inputs(self.scene, s, picks)
        force = np.full(n, s.grasp.grip_force_n)
        parts = [row_inputs(base, self.scene, s, force, v) for v in values]
        inputs = jax.tree.map(lambda *a: np.concatenate(a), *parts)
        out = self.runner.run(self._backend, inputs).results
        keys = ("success", "score", "failure", "diverged", "lift_height_mm")
        return {k: np.asarray(out[k]).reshape(len(values), n) for k in keys}

    @property
    def simulations(self) -> int:
        return self.runner.rollouts


def entropy_bits(p) -> np.ndarray:
    """Binary entropy of success probabilities p (any shape), bits; 0 at 0 and 1."""
    p = np.clip(np.asarray(p, float), 0.0, 1.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        h = -(p * np.log2(p) + (1 - p) * np.log2(1 - p))
    return np.nan_to_num(h, nan=0.0)


def parameter_draws(
    space: ParamSpace, count: int, seed: int, centre_z=None, sd_z=None
) -> np.ndarray:
    """(count, P) natural parameter values: a Latin hypercube through a Gaussian in each
    parameter's z (value, or log value), truncated to its bounds. Default centre and
    spread: the prior's; after a fit, the fitted value and its interval's."""
    from scipy.stats import qmc, truncnorm

    centre = space.prior_mean if centre_z is None else np.asarray(centre_z, float)
    sd = space.prior_sd if sd_z is None else np.asarray(sd_z, float)
    sd = np.maximum(sd, 1e-9)
    u = qmc.LatinHypercube(d=len(space.names), seed=seed).random(count)
    a, b = (space.z_lo - centre) / sd, (space.z_hi - centre) / sd
    z = centre + sd * truncnorm.ppf(u, a, b)
    return np.asarray(space.natural(np.clip(z, space.z_lo, space.z_hi)), float)


class Information(NamedTuple):
    """What the simulation says about K candidate pick-points.

    success, score, failure (K,): at the template pose under the nominal parameters
    (the prediction); p_nominal (K,): the fraction of R placements that succeed under
    them; p_draws (S, K): the same under each parameter draw; bits (K,): the expected
    information of one trial about the parameters (module docstring)."""

    success: np.ndarray
    score: np.ndarray
    failure: np.ndarray
    p_nominal: np.ndarray
    p_draws: np.ndarray
    bits: np.ndarray


def information(
    sims: Simulations,
    picks: pp.GraspBatch,
    nominal: dict,
    draws: list[dict],
    *,
    placements: int,
    jitter_mm: float,
    jitter_deg: float,
    seed: int,
    pick_config: pp.PickConfig | None = None,
) -> Information:
    """Simulate K candidates at `placements` placements each -- the template pose and
    placements - 1 Gaussian draws around it (jitter_mm on x and y, jitter_deg on yaw;
    the fingers open as planned for the template pose) -- under the nominal parameters
    and each draw: one runner call of at most (1 + S) x K x placements simulations (a
    placement where a finger lands on the object or nothing lies between the fingers
    fails unsimulated)."""
    from mjx_pick.studies.robust import placements as place

    k = len(picks)
    ok = np.ones((k, placements), bool)
    batch = picks
    if placements > 1:
        placed = place(
            sims.object,
            picks,
            sims.settings,
            placements - 1,
            jitter_mm,
            jitter_deg,
            seed,
            pick_config,
        )
        ok[:, 1:] = placed.ok.reshape(k, placements - 1)
        if len(placed.draws):
            batch = pp.concat([picks, placed.draws])
    out = sims.run(batch, [nominal, *draws])
    at = np.zeros((1 + len(draws), k, placements), bool)
    at[:, :, 0] = out["success"][:, :k]
    jittered = np.zeros((1 + len(draws), k, placements - 1), bool)
    jittered[:, ok[:, 1:]] = out["success"][:, k:]
    at[:, :, 1:] = jittered
    p = at.mean(axis=-1)
    p_draws = p[1:]
    bits = entropy_bits(p_draws.mean(axis=0)) - entropy_bits(p_draws).mean(axis=0)
    failure = np.asarray(kt.FAILURES, dtype=object)[out["failure"][0, :k]]
    return Information(
        out["success"][0, :k].astype(bool),
        np.asarray(out["score"][0, :k], float),
        failure,
        p[0],
        p_draws,
        np.maximum(bits, 0.0),
    )


def plan_settings(plan: dict, folder) -> tuple[Settings, pp.PickConfig]:
    return settings_of(plan["settings"], f"{Path(folder) / PLAN}")
