"""Pictures the GUI shows, as PNG/GIF bytes: drawn by the project's own plotting code.

Nothing here simulates: the outline is the ObjectModel's, the pick-point map is
``plots.draw_candidates``, the force plot ``report.force_plot`` and, for the 3-D
replay, the forces as ECharts options.
"""

from __future__ import annotations

import base64
import tempfile
from pathlib import Path

import numpy as np

from mjx_pick.core.objects import ObjectModel, segment_image
from mjx_pick.core.pickpoints import PickBatch
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


def picks_png(obj: ObjectModel, picks: PickBatch) -> tuple[bytes, np.ndarray]:
    """Generated pick-points on the silhouette: gripper centres and closing axes (object
    frame), and the (N, 2) pixel position of each pick-point in the PNG (NaN: not drawn)."""
    drawn = {}

    def draw(path):
        drawn["pixels"] = plots.draw_candidates(obj, picks.x_mm, picks.y_mm, picks.yaw_deg, path)

    return _render(draw), drawn["pixels"]


def score_map_png(run) -> tuple[bytes, np.ndarray]:
    """A run's pick-points on its outline by outcome, the successes coloured by score
    (gripper centres, object frame), and each pick-point's pixel in the PNG (rows in
    the run table's order)."""
    t = run.table
    x, y, yaw = (np.asarray(t[c], float) for c in ("x_mm", "y_mm", "yaw_deg"))
    score = np.nan_to_num(np.asarray(t["score"], float), nan=0.0)
    success = np.asarray(t["success"], bool)
    drawn = {}

    def draw(path):
        drawn["pixels"] = plots.draw_candidates(
            run.outline,
            x,
            y,
            yaw,
            path,
            values=score,
            success=success,
            title=plots.outcome_title(len(x)),
        )

    return _render(draw), drawn["pixels"]


def highlighted(png: bytes, pixel) -> bytes:
    """png with a red ring around pixel (column, row): the selected pick-point."""
    import cv2

    img = cv2.imdecode(np.frombuffer(png, np.uint8), cv2.IMREAD_COLOR)
    if pixel is not None and np.all(np.isfinite(pixel)):
        centre = (int(round(pixel[0])), int(round(pixel[1])))
        cv2.circle(img, centre, 11, (0, 0, 220), 3, lineType=cv2.LINE_AA)
    ok, out = cv2.imencode(".png", img)
    return out.tobytes()


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
