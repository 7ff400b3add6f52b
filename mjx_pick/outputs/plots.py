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
    frame_key(ax)
    fig.tight_layout()
    save_png(fig, path)


def frame_key(ax, corner=(0.04, 0.05), size=0.11) -> None:
    """A small drawing of the gripper frame in a corner of ax (axes fractions): x along
    the fingers' closing direction, y across it, and the sense of a positive yaw
    (counter-clockwise seen from above, z up) -- what every pick-point value means."""
    from matplotlib.patches import FancyArrowPatch

    x0, y0 = corner
    style = {"xycoords": "axes fraction", "textcoords": "axes fraction", "fontsize": 7}
    arrow = {"arrowstyle": "-|>", "color": "k", "lw": 1.2}
    ax.annotate("", (x0 + size, y0), (x0, y0), arrowprops=arrow, **style)
    ax.annotate("", (x0, y0 + size), (x0, y0), arrowprops=arrow, **style)
    ax.annotate("x: closing", (x0 + size, y0), (x0 + size + 0.01, y0 - 0.015), **style)
    ax.annotate("y", (x0, y0 + size), (x0 - 0.01, y0 + size + 0.015), **style)
    turn = FancyArrowPatch(
        (x0 + 0.45 * size, y0),
        (x0, y0 + 0.45 * size),
        connectionstyle="arc3,rad=0.5",
        arrowstyle="-|>",
        mutation_scale=7,
        color="#b5404a",
        lw=1,
        transform=ax.transAxes,
    )
    ax.add_patch(turn)
    ax.annotate("+yaw", (x0 + 0.4 * size, y0 + 0.4 * size), **style, color="#b5404a")


def posed_outline(outline, x_mm: float, y_mm: float, yaw_deg: float):
    """An outline (mm, object frame) at a pick-point's pose in the gripper frame."""
    turned = shapely.affinity.rotate(outline, yaw_deg, origin=(0, 0))
    return shapely.affinity.translate(turned, x_mm, y_mm)


def pick_on_axes(ax, obj, gripper, x_mm, y_mm, yaw_deg, opening_mm, title=None) -> None:
    """Draw one pick-point in the gripper frame on ax: the posed silhouette, its bounding
    box, the coverage region, the fingers at the starting opening, the stroke. obj: the
    object, or its silhouette polygon (mm, object frame)."""
    posed = posed_outline(getattr(obj, "polygon", obj), x_mm, y_mm, yaw_deg)
    add_polygon(ax, posed, fc="#4a78b5", ec="k", lw=1, alpha=0.9)
    x0, y0, x1, y1 = posed.bounds
    ax.add_patch(
        Rectangle(
            (x0, y0), x1 - x0, y1 - y0, fill=False, ec="red", lw=1.5, label="object bounding box"
        )
    )
    fingers_on_axes(ax, gripper, opening_mm)
    s = 0.5 * gripper.stroke_mm
    ax.axvline(-s, color="gray", ls=":", lw=1)
    ax.axvline(s, color="gray", ls=":", lw=1, label="stroke")
    ax.plot([0], [0], marker="+", color="k", ms=12, label="gripper centre")
    span = max(x1 - x0, y1 - y0, gripper.stroke_mm + 2 * gripper.finger_depth_mm) * 0.6 + 5
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


def fingers_on_axes(ax, gripper, opening_mm: float, coverage: bool = True) -> None:
    """The two fingers' footprints at an opening (gripper frame, mm), and between them
    the coverage region."""
    w, d, half = gripper.finger_width_mm, gripper.finger_depth_mm, 0.5 * opening_mm
    if coverage:
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


def outcome_title(n: int, drawn: str = "gripper centres, object frame") -> str:
    """The title of a map of n simulated pick-points by outcome (tab 4's, the report's);
    drawn: what each mark is, in which frame."""
    return f"{n} pick-points: successes by score, failures x ({drawn})"


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
    keep = _kept(n, max_points)
    fig, ax = new_figure(figsize=(7, 5.5))
    add_polygon(ax, outline, fc="#dddddd", ec="k", lw=1)
    _scatter_picks(ax, centre, keep, labels, values, success, value_label)
    seg = 3.0
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
    return _save_with_pixels(fig, ax, centre, keep, path)


def draw_gripper_frame(
    outline: shapely.Polygon,
    gripper: GripperSpec,
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
    pose: tuple[int, float] | None = None,
) -> np.ndarray:
    """Many pick-points in the gripper frame -- the frame of their values: each at
    (x, y), where the object's centre lies from the gripper's centre, with a tick along
    the object's own x axis (its yaw); the fingers fully open around the origin, and a
    drawing of the frame's axes and yaw sense (:func:`frame_key`).

    outline: the object's silhouette (mm, object frame); labels, values, success,
    value_label: as :func:`draw_candidates`. pose: (index, opening_mm) of one pick-point
    also drawn whole -- the part's outline at its pose and the fingers at its opening
    -- without moving the axes (a viewer keeps the pixels of the map without it).
    Returns: (N, 2) pixel positions of the drawn pick-points (NaN: left out), as
    :func:`draw_candidates`.
    """
    centre = np.column_stack([np.asarray(x_mm, float), np.asarray(y_mm, float)])
    yaw = np.deg2rad(np.asarray(yaw_deg, float))
    n = len(centre)
    keep = _kept(n, max_points)
    fig, ax = new_figure(figsize=(7, 5.5))
    half, d, w = 0.5 * gripper.stroke_mm, gripper.finger_depth_mm, gripper.finger_width_mm
    for left in (-half - d, half):  # fully open: where the fingers start at most
        ax.add_patch(Rectangle((left, -w / 2), d, w, fc="#e8e8e8", ec="#999999", lw=0.8))
    ax.plot([-half, half], [0, 0], color="#999999", lw=0.6, ls="--", zorder=1)
    _scatter_picks(ax, centre, keep, labels, values, success, value_label)
    seg = 3.0  # mm: the object's x axis from its centre
    c, t = centre[keep], yaw[keep]
    ax.plot(
        np.stack([c[:, 0], c[:, 0] + seg * np.cos(t)]),
        np.stack([c[:, 1], c[:, 1] + seg * np.sin(t)]),
        color="k",
        lw=0.4,
        alpha=0.5,
        zorder=2,
    )
    if pose is not None:
        i, opening = pose
        posed = posed_outline(outline, centre[i, 0], centre[i, 1], float(np.rad2deg(yaw[i])))
        add_polygon(ax, posed, fc="#4a78b5", ec="k", lw=1, alpha=0.35, zorder=1)
        fingers_on_axes(ax, gripper, opening, coverage=False)
        ax.plot(*centre[i], "o", ms=14, mfc="none", mec="#d62728", mew=2, zorder=5)
    # the same axes with or without a pose: every pose's outline lies within its centre
    # plus the outline's radius
    radius = float(np.hypot(*shapely.get_coordinates(outline).T).max())
    reach = np.abs(centre[keep]).max() if len(keep) else 0.0
    r = max(half + d, reach + radius) + 5.0
    ax.set_xlim(-r, r)
    ax.set_ylim(-r, r)
    ax.set_aspect("equal")
    ax.set_xlabel("x: along the fingers' closing direction, mm (gripper frame)")
    ax.set_ylabel("y, mm (gripper frame)")
    frame_key(ax)
    ax.set_title(
        title or f"{n} pick-points: the object's centre under the gripper, tick: its x axis",
        fontsize=10,
    )
    return _save_with_pixels(fig, ax, centre, keep, path)


def _kept(n: int, max_points: int) -> np.ndarray:
    """Indices of the pick-points a map draws: all, or max_points spread over them."""
    return np.arange(n) if n <= max_points else np.linspace(0, n - 1, max_points).astype(int)


def _scatter_picks(ax, points, keep, labels, values, success, value_label) -> None:
    """Pick-points at points (N, 2) on ax: by outcome (values and success), by value,
    or by feasibility reason label."""
    fig = ax.get_figure()
    if values is not None and success is not None:
        v = np.asarray(values, float)[keep]
        outcome_scatter(ax, points[keep], v, np.asarray(success, bool)[keep], value_label)
    elif values is not None:
        v = np.asarray(values, float)[keep]
        sc = ax.scatter(points[keep, 0], points[keep, 1], c=v, cmap="viridis", s=10, zorder=3)
        fig.colorbar(sc, ax=ax, label=value_label)
    else:
        labels = np.asarray(labels)[keep] if labels is not None else np.full(len(keep), "feasible")
        for name, colour in REASON_COLOURS.items():
            m = labels == name
            if m.any():
                ax.scatter(
                    points[keep][m, 0],
                    points[keep][m, 1],
                    s=8,
                    color=colour,
                    label=f"{name} ({int(m.sum())})",
                    zorder=3,
                )
        ax.legend(loc="upper right", fontsize=7, markerscale=2)


def _save_with_pixels(fig, ax, points, keep, path, dpi: int = 120) -> np.ndarray:
    """Save the figure (PNG) and return the (N, 2) pixel (column, row from the top
    left) of each point drawn, NaN for those left out."""
    fig.tight_layout()
    save_png(fig, path, dpi=dpi)
    shown = ax.transData.transform(points[keep]) * (dpi / fig.dpi)
    pixels = np.full((len(points), 2), np.nan)
    pixels[keep, 0] = shown[:, 0]
    pixels[keep, 1] = fig.get_figheight() * dpi - shown[:, 1]
    return pixels
