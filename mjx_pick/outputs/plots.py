"""Pictures of pick-points on the silhouette (PNG, matplotlib figures without pyplot).

Details: docs/outputs.md (outputs/plots.py).
"""

from __future__ import annotations

import math
import os

import numpy as np
import shapely
import shapely.affinity
from matplotlib.figure import Figure
from matplotlib.patches import Polygon as MplPolygon
from matplotlib.patches import Rectangle

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel

REASON_COLOURS = {
    "feasible": "#2ca02c",
    "off_object": "#bbbbbb",
    "too_wide": "#d62728",
    "clearance": "#9467bd",
    "coverage": "#ff7f0e",
}


def new_figure(nrows: int = 1, ncols: int = 1, *, figsize=None, **subplots_kw):
    """(figure, axes) without pyplot: no global backend is chosen or changed, so a
    user's interactive session keeps its own (a Figure renders to PNG by itself)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **subplots_kw)


def save_png(fig, path: str | os.PathLike, dpi: int = 120) -> None:
    """Save a figure atomically (never a half-written PNG)."""
    import io

    from mjx_pick.core.config import write_atomic

    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi)
    write_atomic(path, buf.getvalue())


def add_polygon(ax, poly, **kw):
    geoms = getattr(poly, "geoms", [poly])
    for g in geoms:
        ax.add_patch(MplPolygon(np.asarray(g.exterior.coords)[:, :2], closed=True, **kw))
        for hole in g.interiors:
            ax.add_patch(
                MplPolygon(
                    np.asarray(hole.coords)[:, :2],
                    closed=True,
                    fc="white",
                    ec=kw.get("ec", "k"),
                    lw=kw.get("lw", 1),
                )
            )


def draw_pick(
    obj: ObjectModel,
    gripper: GripperSpec,
    x_mm: float,
    y_mm: float,
    yaw_deg: float,
    opening_mm: float,
    path: str | os.PathLike,
    title: str | None = None,
) -> None:
    """One pick-point in the gripper frame (the paper's Fig. 9), saved as PNG."""
    fig, ax = new_figure(figsize=(6, 5))
    pick_on_axes(ax, obj, gripper, x_mm, y_mm, yaw_deg, opening_mm, title)
    fig.tight_layout()
    save_png(fig, path)


def pick_on_axes(ax, obj, gripper, x_mm, y_mm, yaw_deg, opening_mm, title=None) -> None:
    """Draw one pick-point in the gripper frame on ax: the posed silhouette, its bounding
    box, the coverage region, the fingers at the starting opening, the stroke."""
    posed = shapely.affinity.translate(
        shapely.affinity.rotate(obj.polygon, yaw_deg, origin=(0, 0)), x_mm, y_mm
    )
    add_polygon(ax, posed, fc="#4a78b5", ec="k", lw=1, alpha=0.9)
    x0, y0, x1, y1 = posed.bounds
    ax.add_patch(
        Rectangle(
            (x0, y0), x1 - x0, y1 - y0, fill=False, ec="red", lw=1.5, label="object bounding box"
        )
    )
    w, d, half = gripper.finger_width_mm, gripper.finger_depth_mm, 0.5 * opening_mm
    ax.add_patch(
        Rectangle(
            (-half, -w / 2),
            opening_mm,
            w,
            fc="#2ca02c",
            alpha=0.25,
            ec="#2ca02c",
            lw=1.5,
            label="coverage region",
        )
    )
    for sx in (-1, 1):
        left = half if sx > 0 else -half - d
        ax.add_patch(
            Rectangle(
                (left, -w / 2),
                d,
                w,
                fc="#1f77b4",
                alpha=0.8,
                ec="navy",
                label="fingers" if sx > 0 else None,
            )
        )
    s = 0.5 * gripper.stroke_mm
    ax.axvline(-s, color="gray", ls=":", lw=1)
    ax.axvline(s, color="gray", ls=":", lw=1, label="stroke")
    ax.plot([0], [0], marker="+", color="k", ms=12, label="gripper centre")
    span = max(x1 - x0, y1 - y0, gripper.stroke_mm + 2 * d) * 0.6 + 5
    ax.set_xlim(-span, span)
    ax.set_ylim(-span, span)
    ax.set_aspect("equal")
    ax.set_xlabel("gripper x (closing axis), mm")
    ax.set_ylabel("gripper y, mm")
    ax.set_title(
        title
        or f"x={x_mm:.1f} mm, y={y_mm:.1f} mm, yaw={yaw_deg:.1f} deg, opening={opening_mm:.1f} mm"
    )
    ax.legend(loc="upper right", fontsize=7)


def gripper_in_object_frame(x_mm, y_mm, yaw_deg):
    """Gripper centre and closing-axis direction in the object frame, (N, 2) each."""
    yaw = np.deg2rad(np.asarray(yaw_deg, float))
    c, s = np.cos(yaw), np.sin(yaw)
    x, y = np.asarray(x_mm, float), np.asarray(y_mm, float)
    # object frame point of the gripper origin: R(-yaw) (0 - t)
    gx, gy = -(c * x + s * y), -(-s * x + c * y)
    ax, ay = c, -s  # gripper x axis in the object frame: R(-yaw) e_x
    return np.column_stack([gx, gy]), np.column_stack([ax, ay])


FAILURE_COLOUR = "#d62728"


def outcome_title(n: int) -> str:
    """The title of a map of n simulated pick-points by outcome (tab 4's, the report's)."""
    return f"{n} pick-points: successes by score, failures x (gripper centres, object frame)"


def outcome_scatter(ax, centre: np.ndarray, values: np.ndarray, success: np.ndarray, label: str):
    """Pick-points by outcome on ax: successes as dots coloured by value (viridis, the
    colour bar spanning the successes' values), failures as red crosses over them.
    centre: (N, 2) mm; values, success: (N,). Returns (successes, failures): the two
    PathCollections, None where there are none."""
    fig = ax.get_figure()
    ok = np.asarray(success, bool)
    dots = crosses = None
    if ok.any():
        dots = ax.scatter(
            centre[ok, 0],
            centre[ok, 1],
            c=values[ok],
            cmap="viridis",
            s=12,
            zorder=3,
            label=f"success ({int(ok.sum())})",
        )
        fig.colorbar(dots, ax=ax, label=f"{label} (successes)")
    if (~ok).any():
        crosses = ax.scatter(
            centre[~ok, 0],
            centre[~ok, 1],
            marker="x",
            color=FAILURE_COLOUR,
            s=22,
            linewidths=1.2,
            zorder=4,
            label=f"failure ({int((~ok).sum())})",
        )
    ax.legend(loc="upper right", fontsize=7, markerscale=1.5)
    return dots, crosses


def draw_candidates(
    obj: ObjectModel | shapely.Polygon,
    x_mm,
    y_mm,
    yaw_deg,
    path: str | os.PathLike,
    labels=None,
    values=None,
    value_label: str = "score",
    title: str | None = None,
    max_points: int = 4000,
    success=None,
) -> np.ndarray:
    """Many pick-points on the silhouette (object frame): by reason label or by value.

    Each pick-point (x, y, yaw: the object's offset under the gripper, gripper frame) is
    drawn where the gripper's centre lies on the part, with its closing axis.

    obj: the object, or just its silhouette polygon (mm, object frame).
    success: (N,) bool with values: the successes are dots coloured by value (the
      colour bar spans theirs), the failures red crosses (:func:`outcome_scatter`).
    Returns: (N, 2) pixel positions (column, row from the top left) of the drawn gripper
    centres in the PNG written, NaN for those left out (beyond max_points); a viewer
    finds the pick-point under a click with them.
    """
    outline = getattr(obj, "polygon", obj)
    centre, axis = gripper_in_object_frame(x_mm, y_mm, yaw_deg)
    n = len(centre)
    keep = np.arange(n) if n <= max_points else np.linspace(0, n - 1, max_points).astype(int)
    fig, ax = new_figure(figsize=(7, 5.5))
    add_polygon(ax, outline, fc="#dddddd", ec="k", lw=1)
    seg = 3.0
    if values is not None and success is not None:
        v = np.asarray(values, float)[keep]
        outcome_scatter(ax, centre[keep], v, np.asarray(success, bool)[keep], value_label)
    elif values is not None:
        v = np.asarray(values, float)[keep]
        sc = ax.scatter(centre[keep, 0], centre[keep, 1], c=v, cmap="viridis", s=10, zorder=3)
        fig.colorbar(sc, ax=ax, label=value_label)
    else:
        labels = np.asarray(labels)[keep] if labels is not None else np.full(len(keep), "feasible")
        for name, colour in REASON_COLOURS.items():
            m = labels == name
            if m.any():
                ax.scatter(
                    centre[keep][m, 0],
                    centre[keep][m, 1],
                    s=8,
                    color=colour,
                    label=f"{name} ({int(m.sum())})",
                    zorder=3,
                )
        ax.legend(loc="upper right", fontsize=7, markerscale=2)
    c, a = centre[keep], axis[keep]
    ax.plot(
        np.stack([c[:, 0] - seg * a[:, 0], c[:, 0] + seg * a[:, 0]]),
        np.stack([c[:, 1] - seg * a[:, 1], c[:, 1] + seg * a[:, 1]]),
        color="k",
        lw=0.3,
        alpha=0.4,
        zorder=2,
    )
    x0, y0, x1, y1 = outline.bounds
    r = 0.5 * math.hypot(x1 - x0, y1 - y0) + 10
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_aspect("equal")
    ax.set_xlabel("x on the part, mm (object frame)")
    ax.set_ylabel("y on the part, mm (object frame)")
    ax.set_title(
        title
        or f"{getattr(obj, 'name', 'object')}: {n} pick-points (gripper centres on the part, "
        "closing axes)",
        fontsize=10,
    )
    fig.tight_layout()
    dpi = 120
    save_png(fig, path, dpi=dpi)
    shown = ax.transData.transform(centre[keep]) * (dpi / fig.dpi)
    pixels = np.full((n, 2), np.nan)
    pixels[keep, 0] = shown[:, 0]
    pixels[keep, 1] = fig.get_figheight() * dpi - shown[:, 1]
    return pixels
