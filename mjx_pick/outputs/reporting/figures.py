"""Figures of a run: force traces with their phases (the paper's Fig. 8) and maps of
score and success over the object."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from mjx_pick.kernels import types as kt
from mjx_pick.outputs.plots import draw_candidates, new_figure, outcome_title, save_png
from mjx_pick.outputs.reporting.run import Run

__all__ = ["PHASE_COLOURS", "phase_events", "force_plot", "maps"]

PHASE_COLOURS = {
    "settle": "#999999",
    "close": "#1f77b4",
    "dwell": "#9467bd",
    "lift": "#2ca02c",
    "hold": "#ff7f0e",
    "done": "#444444",
}


def phase_events(t: np.ndarray, phase: np.ndarray) -> list[tuple[float, str]]:
    """(time, phase entered) at every change of phase along a trace."""
    change = np.flatnonzero(phase[1:] != phase[:-1]) + 1
    return [(float(t[i]), str(phase[i])) for i in change]


def force_plot(trace: dict, grip_force_n: float, path, title: str = "") -> None:
    """The forces of one traced pick-point and, below them on the same time axis, the
    lift: the gripper's and the object's height above their start, mm -- where the
    object's curve falls behind the gripper's, the part slips (the gap is shaded).

    Top panel: left and right pad force and the object-table force, N, F_d dashed.
    Both panels mark the phase changes.
    """
    t = trace["t_s"]
    fig, (ax, lift_ax) = new_figure(
        2, 1, figsize=(8, 5.6), sharex=True, gridspec_kw={"height_ratios": [2, 1]}
    )
    ax.plot(t, trace["force_left_n"], label="left finger", color="#1f77b4")
    ax.plot(t, trace["force_right_n"], label="right finger", color="#d62728", ls="-.")
    ax.plot(t, trace["force_table_n"], label="object-table", color="#7f7f7f")
    ax.axhline(grip_force_n, color="k", ls="--", lw=1, label=f"F_d = {grip_force_n:g} N")
    top = max(grip_force_n, float(np.nanmax(trace["force_left_n"]))) * 1.15
    events = phase_events(t, trace["phase"])
    for when, name in events:
        for a in (ax, lift_ax):
            a.axvline(when, color=PHASE_COLOURS.get(name, "k"), lw=0.8, ls=":")
        ax.text(
            when,
            top,
            f" {name}",
            rotation=90,
            va="top",
            fontsize=8,
            color=PHASE_COLOURS.get(name, "k"),
        )
    ax.set_ylim(min(0.0, float(np.nanmin(trace["force_table_n"]))) - 1, top * 1.05)
    ax.set_ylabel("force, N")
    ax.set_title(title, fontsize=10)
    ax.legend(loc="center right", fontsize=8)
    ax.grid(alpha=0.3)

    gripper = (np.asarray(trace["lift_m"]) - trace["lift_m"][0]) * 1e3
    obj = (np.asarray(trace["object_z_m"]) - trace["object_z_m"][0]) * 1e3
    lift_ax.plot(t, obj, color="#2ca02c", lw=2, label="object")
    lift_ax.plot(t, gripper, color="k", lw=1, ls="--", label="gripper")
    lift_ax.fill_between(
        t, obj, gripper, where=gripper > obj, color="#d62728", alpha=0.25, label="slip"
    )
    lift_ax.set_xlabel("time, s")
    lift_ax.set_ylabel("lift, mm")
    lift_ax.legend(loc="upper left", fontsize=8)
    lift_ax.grid(alpha=0.3)
    fig.tight_layout()
    save_png(fig, path)


def maps(run: Run, out_dir: Path, yaw_bins: int = 4) -> dict[str, Path]:
    """score_map, success_by_yaw, score_hist and failures PNGs."""
    t = run.table
    x, y, yaw = (np.asarray(t[c], float) for c in ("x_mm", "y_mm", "yaw_deg"))
    score = np.nan_to_num(np.asarray(t["score"], float), nan=0.0)
    success = np.asarray(t["success"], bool)
    out = {}
    draw_candidates(
        run.outline,
        x,
        y,
        yaw,
        out_dir / "score_map.png",
        values=score,
        success=success,
        title=outcome_title(len(x)),
    )
    out["score_map"] = out_dir / "score_map.png"

    _success_by_yaw(x, y, yaw, success, yaw_bins, out_dir / "success_by_yaw.png")
    out["success_by_yaw"] = out_dir / "success_by_yaw.png"
    _score_hist(np.asarray(t["score"], float), success, out_dir / "score_hist.png")
    out["score_hist"] = out_dir / "score_hist.png"
    failures = np.asarray(t["failure"].to_pylist(), dtype=object)
    _failures_chart(failures, out_dir / "failures.png")
    out["failures"] = out_dir / "failures.png"
    return out


def _success_by_yaw(x, y, yaw, success, yaw_bins: int, path: Path) -> None:
    """One success-rate map over the offsets (x, y mm, (N,)) per bin of yaw (deg, folded
    to 0-180: the gripper is symmetric, yaw and yaw + 180 are the same grasp)."""
    folded = np.mod(yaw, 180.0)
    edges = np.linspace(0.0, 180.0, yaw_bins + 1)
    fig, axes = new_figure(1, yaw_bins, figsize=(3.6 * yaw_bins, 3.6), squeeze=False)
    lim = max(np.abs(x).max(), np.abs(y).max(), 1.0)
    bins = np.linspace(-lim, lim, 13)
    for k, ax in enumerate(axes[0]):
        m = (folded >= edges[k]) & (folded < edges[k + 1])
        n, _, _ = np.histogram2d(x[m], y[m], bins=[bins, bins])
        s, _, _ = np.histogram2d(x[m], y[m], bins=[bins, bins], weights=success[m])
        rate = np.where(n > 0, s / np.maximum(n, 1), np.nan)
        im = ax.imshow(
            rate.T, origin="lower", extent=(-lim, lim, -lim, lim), vmin=0, vmax=1, cmap="RdYlGn"
        )
        ax.set_title(f"yaw {edges[k]:.0f}-{edges[k + 1]:.0f} deg ({int(m.sum())})", fontsize=9)
        ax.set_xlabel("x offset, mm")
        if k == 0:
            ax.set_ylabel("y offset, mm")
    fig.colorbar(im, ax=axes[0].tolist(), label="success rate", shrink=0.8)
    save_png(fig, path)


def _score_hist(raw: np.ndarray, success: np.ndarray, path: Path) -> None:
    """Histogram of the scores (N,) over 0-1, successes and failures stacked; diverged
    pick-points (no score: NaN) left out."""
    fig, ax = new_figure(figsize=(6, 3.5))
    scored = np.isfinite(raw)
    ax.hist(
        [raw[scored & success], raw[scored & ~success]],
        bins=np.linspace(0, 1, 26),
        stacked=True,
        color=["#2ca02c", "#d62728"],
        label=["success", "failure"],
    )
    ax.set_xlabel("score, eq. (2)")
    ax.set_ylabel("pick-points")
    ax.legend()
    fig.tight_layout()
    save_png(fig, path)


def _failures_chart(failures: np.ndarray, path: Path) -> None:
    """Bar chart of how many pick-points ended in each outcome (failures: (N,) names)."""
    names = list(kt.FAILURES)
    counts = [int(np.sum(failures == name)) for name in names]
    fig, ax = new_figure(figsize=(6, 3.5))
    ax.barh(
        names[::-1],
        counts[::-1],
        color=["#2ca02c" if n == kt.SUCCESS else "#d62728" for n in names[::-1]],
    )
    for i, c in enumerate(counts[::-1]):
        ax.text(c, i, f" {c}", va="center", fontsize=8)
    ax.set_xlabel("pick-points")
    ax.set_title("outcome: success, or why it failed")
    fig.tight_layout()
    save_png(fig, path)
