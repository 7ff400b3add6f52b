"""Synthetic measured outcomes: simulated with hidden settings, for validating fits."""

from __future__ import annotations

import dataclasses

import numpy as np

from mjx_pick.core.objects import ObjectModel
from mjx_pick.core.settings import Settings
from mjx_pick.engine.registry import Impl
from mjx_pick.studies.calibration.data import Outcomes, make_outcomes


def synthetic_outcomes(
    obj: ObjectModel,
    hidden: Settings,
    x_mm,
    y_mm,
    yaw_deg,
    grip_force_n,
    *,
    traces: bool | tuple[str, ...] = False,
    lift_times: bool = False,
    force_offset_n: float = 0.0,
    trace_noise: dict | None = None,
    seed: int = 0,
    backend: str = Impl.MUJOCO,
) -> Outcomes:
    """Outcomes as a real cell would report them, simulated with hidden settings.

    One trial per row (the simulation is deterministic). traces: True for every kind
    (force_n, lift_mm, rotation_deg), or a tuple of kinds, from the close command on,
    every control tick; trace_noise: {kind: Gaussian sd} added to them. lift_times: the
    time F_d was reached. force_offset_n: the hidden gripper squeezes F_d + this.
    """
    from mjx_pick.studies.calibration.problem import Problem

    rows = make_outcomes(x_mm, y_mm, yaw_deg, grip_force_n)
    n = len(rows)
    problem = Problem(
        obj,
        rows,
        ["force_offset_n"],
        hidden,
        backend=backend,
        bounds={"force_offset_n": (min(-1.0, force_offset_n - 1), max(1.0, force_offset_n + 1))},
    )
    if traces:
        kinds = ("force_n", "lift_mm", "rotation_deg") if traces is True else tuple(traces)
        problem.record = True
    theta = problem.space.theta([force_offset_n])
    out = problem.simulate(theta[None])
    g = hidden.grasp
    row_traces = [None] * n
    if traces:
        row_traces = _row_traces(out, kinds, n, problem.t_ticks, trace_noise, seed)
    lift = out["t_reached_s"][0] - g.settle_s
    lift = np.where(out["t_reached_s"][0] >= 0, lift, np.nan) if lift_times else np.full(n, np.nan)
    return dataclasses.replace(
        rows,
        successes=out["success"][0].astype(float),
        lift_time_s=lift,
        traces=tuple(row_traces),
    )


def _row_traces(out: dict, kinds, n: int, t_ticks, trace_noise: dict | None, seed: int):
    """Per row of n, {kind: (T, 2) [t (s), value]} of the simulated traces out[kind] (1, R, T')
    on the ticks from the close command on (t_ticks >= 0), each with Gaussian noise of sd
    trace_noise[kind] (drawn row by row, kind by kind, from one generator of seed)."""
    keep = t_ticks >= 0
    t = t_ticks[keep]
    rng = np.random.default_rng(seed)
    row_traces = []
    for i in range(n):
        tr = {}
        for k in kinds:
            v = out[k][0, i, keep].astype(float)
            sd = (trace_noise or {}).get(k, 0.0)
            if sd:
                v = v + rng.normal(0.0, sd, v.shape)
            tr[k] = np.stack([t, v], axis=1)
        row_traces.append(tr)
    return row_traces


def synthetic_digest(obj: ObjectModel, hidden: Settings) -> str:
    """What decides synthetic outcomes besides their poses and forces, as one digest:
    the hidden settings and the simulated model (the object, gripper, contact and
    solver as MuJoCo reads them). Shipped synthetic outcomes record it, so that a test
    sees when the physics they ship with no longer made them."""
    import hashlib
    import json

    from mjx_pick.core.config import to_dict
    from mjx_pick.core.scene import build_scene

    h = hidden
    scene = build_scene(obj, h.gripper, h.contact, h.solver, h.grasp)
    settings = {k: v for k, v in to_dict(h).items()}
    settings["gripper"].pop("source", None)  # where a preset was read from
    obj_summary = {k: v for k, v in obj.summary().items() if k != "source"}
    text = json.dumps({"settings": settings, "object": obj_summary}, sort_keys=True, default=str)
    return "sha256:" + hashlib.sha256((text + scene.portable_xml()).encode()).hexdigest()[:16]
