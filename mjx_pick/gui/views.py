"""Pictures the GUI shows, as PNG/GIF bytes: drawn by the project's own plotting code.

Nothing here simulates: the outline is the ObjectModel's, the pick-point maps are
``plots.draw_gripper_frame`` (the frame of the pick-points' values), the force plot
``report.force_plot`` and, for the 3-D replay, the forces as ECharts options.
"""

from __future__ import annotations

import base64
import tempfile
from pathlib import Path

import numpy as np

from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.objects import ObjectModel, segment_image
from mjx_pick.outputs import plots


def data_uri(data: bytes, mime: str) -> str:
    return f"data:{mime};base64," + base64.b64encode(data).decode()


def _render(draw, suffix: str = ".png") -> bytes:
    """Bytes of a file that draw(path) writes (the plotting code writes files)."""
    with tempfile.TemporaryDirectory(prefix="mjx_pick_gui_") as tmp:
        path = Path(tmp) / f"view{suffix}"
        draw(path)
        return path.read_bytes()


def object_png(obj: ObjectModel, image: Path | None = None) -> bytes:
    """The segmentation (mask over the image, when there is one) and the outline in mm."""

    def draw(path):
        ncols = 2 if image is not None else 1
        fig, axes = plots.new_figure(1, ncols, figsize=(5.2 * ncols, 4.6))
        axes = np.atleast_1d(axes)
        if image is not None:
            import cv2

            img = cv2.imread(str(image), cv2.IMREAD_COLOR)
            mask = segment_image(image)
            shown = img[..., ::-1].copy()
            shown[mask] = (0.5 * shown[mask] + 0.5 * np.array([40, 160, 60])).astype(np.uint8)
            axes[0].imshow(shown)
            axes[0].set_title(f"segmentation: {int(mask.sum())} object pixels")
            axes[0].set_axis_off()
        ax = axes[-1]
        plots.add_polygon(ax, obj.polygon, fc="#cfe0f5", ec="k", lw=1.2)
        ax.plot([0], [0], "r+", ms=12)
        ax.set_aspect("equal")
        ax.set_xlabel("x, mm")
        ax.set_ylabel("y, mm")
        ax.set_title(
            f"outline: {obj.area_mm2:.0f} mm², {len(obj.polygon.exterior.coords) - 1} "
            "corners (+ centre of mass)"
        )
        fig.tight_layout()
        plots.save_png(fig, path)

    return _render(draw)


def picks_png(
    obj: ObjectModel, picks: GraspBatch, gripper, pose: int | None = None
) -> tuple[bytes, np.ndarray]:
    """Generated pick-points in the gripper frame (the frame of their values: where the
    object's centre lies under the gripper, its yaw), and the (N, 2) pixel position of
    each in the PNG (NaN: not drawn). pose: the index of one drawn whole -- the part at
    its pose, the fingers at its opening."""
    drawn = {}
    shown = None if pose is None else (pose, float(picks.opening_mm[pose]))

    def draw(path):
        drawn["pixels"] = plots.draw_gripper_frame(
            obj.polygon, gripper, picks.x_mm, picks.y_mm, picks.yaw_deg, path, pose=shown
        )

    return _render(draw), drawn["pixels"]


def pose_png(obj: ObjectModel, gripper, x: float, y: float, yaw: float, opening: float) -> bytes:
    """One pick-point in the gripper frame (the paper's Fig. 9, with the frame's axes):
    the part at its pose, the fingers at the opening, the coverage region, the stroke."""
    title = f"object x {x:.1f} mm, y {y:.1f} mm, yaw {yaw:.1f} deg (gripper frame)"
    return _render(lambda path: plots.draw_pick(obj, gripper, x, y, yaw, opening, path, title))


def score_map_png(run, pose: int | None = None) -> tuple[bytes, np.ndarray]:
    """A run's pick-points in the gripper frame by outcome, the successes coloured by
    score, and each pick-point's pixel in the PNG (rows in the run table's order).
    pose: the row of one drawn whole (its part and fingers), ringed."""
    t = run.table
    x, y, yaw = (np.asarray(t[c], float) for c in ("x_mm", "y_mm", "yaw_deg"))
    score = np.nan_to_num(np.asarray(t["score"], float), nan=0.0)
    success = np.asarray(t["success"], bool)
    shown = None if pose is None else (pose, float(t["opening_mm"][pose].as_py()))
    drawn = {}

    def draw(path):
        drawn["pixels"] = plots.draw_gripper_frame(
            run.outline,
            run.gripper,
            x,
            y,
            yaw,
            path,
            values=score,
            success=success,
            title=plots.outcome_title(len(x), "gripper frame: the object's centre"),
            pose=shown,
        )

    return _render(draw), drawn["pixels"]


def posed(run) -> bool:
    """Whether a run's grasps were given as poses (antipodal, or a grasp file): each row
    has its grasp frame (``grasp_pose``), its tilt from vertical and its height -- the
    pick-point maps and templates, drawn for a vertical approach, do not show them."""
    return "grasp_pose" in run.table.column_names


def posed_text(run) -> str:
    """What tab 4 says of a run of grasps given as poses in place of its map: how far
    they tilt and where their centres lie, and why no map or template is shown."""
    tilt = np.asarray(run.table["tilt_deg"], float)
    height = np.asarray(run.table["height_mm"], float)
    return (
        f"Grasps given as poses: tilted {np.nanmin(tilt):.1f}-{np.nanmax(tilt):.1f} deg from "
        f"vertical, their centres {np.nanmin(height):.1f}-{np.nanmax(height):.1f} mm above "
        "the table. No map: the maps (and the report's printed template and robot "
        "pick-points) draw top-down pick-points, a vertical approach; the table gives each "
        "grasp's tilt and height with its planar part, and the 3-D replay shows the "
        "gripper as it was simulated."
    )


def nearest_pick(pixels: np.ndarray, column: float, row: float, within: float = 12.0):
    """Index of the pick-point drawn nearest a click at (column, row) in the image's
    pixels, or None when none lies within `within` pixels."""
    d = np.hypot(pixels[:, 0] - column, pixels[:, 1] - row)
    if not np.isfinite(d).any():
        return None
    i = int(np.nanargmin(d))
    return i if d[i] <= within else None


def force_png(trace: dict, grip_force_n: float, title: str) -> bytes:
    from mjx_pick.outputs.reporting import force_plot

    return _render(lambda path: force_plot(trace, grip_force_n, path, title=title))


def force_chart(trace: dict, grip_force_n: float) -> dict:
    """The pad and table forces over time as ECharts options (the replay's plot; its
    markLine is the replay's time)."""
    t = [round(float(v), 4) for v in trace["t_s"]]

    def series(name, key):
        values = [round(float(v), 3) for v in trace[key]]
        data = [list(p) for p in zip(t, values, strict=True)]
        return {"name": name, "type": "line", "showSymbol": False, "data": data}

    lines = [
        series("left pad", "force_left_n"),
        series("right pad", "force_right_n"),
        series("object-table", "force_table_n"),
    ]
    lines[0]["markLine"] = {"symbol": "none", "animation": False, "data": [{"xAxis": t[0]}]}
    return {
        "animation": False,
        "legend": {"top": 0},
        "grid": {"left": 50, "right": 20, "top": 30, "bottom": 40},
        "xAxis": {
            "type": "value",
            "name": "time, s",
            "nameLocation": "middle",
            "nameGap": 25,
            "min": t[0],
            "max": t[-1],  # the slider's range: its time and the marker line up
        },
        "yAxis": {"type": "value", "name": f"force, N (F_d = {grip_force_n:g} N)"},
        "series": lines,
    }


def sweep_png(out: Path, workdir: Path, labels: dict[str, str]) -> bytes:
    """A sweep folder's picture as ``sweep.png`` draws it, each parameter's axis in the
    page's words (labels: {key: words}, ``forms.sweep_labels``) -- the CLI's picture
    names the keys its command line took. Its files read inside workdir only."""
    import pyarrow.parquet as pq

    from mjx_pick.gui import workfolder
    from mjx_pick.studies.sweeps import plot_sweep

    config = workfolder.read_json(out / "config.json", workdir)
    summaries = workfolder.read_json(out / "variants.json", workdir)
    table = pq.read_table(workfolder.confined(out / "results.parquet", workdir))
    names = [p["name"] for p in config.get("params", [])]
    return _render(lambda path: plot_sweep(summaries, table, names, path, labels))
