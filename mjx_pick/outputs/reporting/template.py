"""The printable 1:1 positioning template (PDF, one page per pick-point)."""

from __future__ import annotations

import io
import os

import shapely
import shapely.affinity

from mjx_pick.core.config import ConfigError, write_atomic
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.outputs.plots import add_polygon

__all__ = ["PAPERS_MM", "SCALE_BAR_COLOUR", "page_misfit", "positioning_template"]

PAPERS_MM = {"a4": (210.0, 297.0), "letter": (215.9, 279.4)}


SCALE_BAR_COLOUR = "#010203"  # a colour nothing else uses: tests find the bar by it


def _pose(x_mm: float, y_mm: float, yaw_deg: float, outline: shapely.Polygon):
    return shapely.affinity.translate(
        shapely.affinity.rotate(outline, yaw_deg, origin=(0, 0)), x_mm, y_mm
    )


# mm of the page's shorter side kept free around the part (title lines, scale bar)
MARGIN_MM = 30.0


def page_misfit(outline: shapely.Polygon, picks: list[dict], paper: str) -> str | None:
    """Why the part, posed as each of picks, does not fit a `paper` page at 1:1 (None:
    every pose fits). The part is drawn about the page's centre, within its shorter
    side less MARGIN_MM."""
    if paper not in PAPERS_MM:
        raise ConfigError(f"paper = {paper!r} is not allowed: choose {', '.join(PAPERS_MM)}")
    room = min(PAPERS_MM[paper]) - MARGIN_MM
    extent = max(
        (
            max(b[2] - b[0], b[3] - b[1])
            for b in (_pose(p["x_mm"], p["y_mm"], p["yaw_deg"], outline).bounds for p in picks)
        ),
        default=0.0,
    )
    if extent <= room:
        return None
    return f"the object ({extent:.0f} mm) does not fit {paper} paper at 1:1 (at most {room:.0f} mm)"


def positioning_template(
    outline: shapely.Polygon,
    gripper: GripperSpec,
    picks: list[dict],
    path: str | os.PathLike,
    paper: str = "a4",
    title: str = "",
) -> int:
    """Printable 1:1 template, one page per pick-point; returns the page count.

    picks: dicts with x_mm, y_mm, yaw_deg, opening_mm and a label. Page coordinates
    are millimetres (the axes fill the page), so the drawing is at true scale when
    printed at 100 % ("actual size").
    """
    from matplotlib.backends.backend_pdf import PdfPages

    misfit = page_misfit(outline, picks, paper)
    if misfit:
        raise ConfigError(misfit)
    pw, ph = PAPERS_MM[paper]
    buf = io.BytesIO()
    with PdfPages(buf) as pdf:
        for number, pick in enumerate(picks, start=1):
            pdf.savefig(_template_page(outline, gripper, pick, (pw, ph), number, title))
    write_atomic(path, buf.getvalue())
    return len(picks)


def _template_page(outline, gripper: GripperSpec, pick: dict, page_mm, number: int, title: str):
    """One template page (a matplotlib Figure of page_mm = (width, height) mm, axes in
    mm filling it): the part posed as pick about the gripper centre, the fingers open to
    its opening, and the captions with the scale bar."""
    from matplotlib.figure import Figure

    pw, ph = page_mm
    cx, cy = pw / 2, ph / 2 + 15
    fig = Figure(figsize=(pw / 25.4, ph / 25.4))
    ax = fig.add_axes((0, 0, 1, 1))
    ax.set_xlim(0, pw)
    ax.set_ylim(0, ph)
    ax.set_axis_off()
    posed = shapely.affinity.translate(
        _pose(pick["x_mm"], pick["y_mm"], pick["yaw_deg"], outline), cx, cy
    )
    add_polygon(ax, posed, fc="#cfe0f5", ec="k", lw=1.2)
    _draw_gripper(ax, gripper, 0.5 * pick["opening_mm"], cx, cy)
    _draw_captions(ax, pick, pw, ph, number, title)
    return fig


def _draw_gripper(ax, gripper: GripperSpec, half: float, cx: float, cy: float) -> None:
    """The two fingers half (mm) either side of the gripper centre (cx, cy) (mm on the
    page), its crosshair and the closing axis marked."""
    from matplotlib.patches import Circle, Rectangle

    d, w = gripper.finger_depth_mm, gripper.finger_width_mm
    for x0 in (cx - half - d, cx + half):
        ax.add_patch(Rectangle((x0, cy - w / 2), d, w, fc="#333333", alpha=0.55, ec="k", lw=0.8))
    ax.plot([cx - 12, cx + 12], [cy, cy], color="r", lw=0.6)
    ax.plot([cx, cx], [cy - 12, cy + 12], color="r", lw=0.6)
    ax.add_patch(Circle((cx, cy), 2.0, fill=False, ec="r", lw=0.6))
    ax.annotate(
        "",
        xy=(cx + half + d + 10, cy + w / 2 + 8),
        xytext=(cx + half + d - 10, cy + w / 2 + 8),
        arrowprops={"arrowstyle": "<->", "lw": 0.6},
    )
    ax.text(cx + half + d, cy + w / 2 + 10, "closing axis (gripper x)", fontsize=6, ha="center")


def _draw_captions(ax, pick: dict, pw: float, ph: float, number: int, title: str) -> None:
    """The page's title, the pick-point's number, label and pose, and a 100 mm scale bar
    (page of pw x ph mm)."""
    ax.text(pw / 2, ph - 15, f"{title}", ha="center", fontsize=11)
    ax.text(pw / 2, ph - 23, f"{number}. {pick['label']}", ha="center", fontsize=10)
    ax.text(
        pw / 2,
        ph - 30,
        f"object at x = {pick['x_mm']:.1f} mm, y = {pick['y_mm']:.1f} mm, yaw = "
        f"{pick['yaw_deg']:.1f} deg from the gripper centre (crosshair); "
        f"opening {pick['opening_mm']:.1f} mm",
        ha="center",
        fontsize=7,
    )
    ax.plot([20, 120], [20, 20], color=SCALE_BAR_COLOUR, lw=2, solid_capstyle="butt")
    for xt in (20, 70, 120):
        ax.plot([xt, xt], [18, 22], color=SCALE_BAR_COLOUR, lw=0.8)
    ax.text(
        70, 24, "100 mm: check it measures 100 mm (print at actual size)", ha="center", fontsize=7
    )
