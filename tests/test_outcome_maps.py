"""The pick-point maps of tab 4 and of the report mark failures apart from successes:
successes are dots coloured by score (the colour bar spans the successes' scores),
failures red crosses."""

import io
import types

import numpy as np
import pyarrow as pa
import pytest
from matplotlib.colors import to_rgb
from PIL import Image
from shapely.geometry import box

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.gui import views
from mjx_pick.outputs import plots
from mjx_pick.outputs.reporting.figures import maps

# six pick-points far apart on a 120 x 80 mm plate, yaw 0: the gripper centre on the
# part is (-x, -y)
X = np.array([-40.0, 0.0, 40.0, -40.0, 0.0, 40.0])
Y = np.array([-25.0, -25.0, -25.0, 25.0, 25.0, 25.0])
SUCCESS = np.array([True, False, True, False, True, False])
SCORE = np.array([0.91, 0.42, 0.99, 0.30, 0.95, np.nan])  # the last one diverged
FAILURE = ["success", "dropped_in_hold", "success", "rotated", "success", "diverged"]


def fake_run():
    table = pa.table(
        {
            "pick_id": np.arange(6),
            "x_mm": X,
            "y_mm": Y,
            "yaw_deg": np.zeros(6),
            "opening_mm": np.full(6, 60.0),
            "score": SCORE,
            "success": SUCCESS,
            "failure": FAILURE,
        }
    )
    return types.SimpleNamespace(table=table, outline=box(-60, -40, 60, 40), gripper=GripperSpec())


def test_outcome_scatter_draws_successes_by_score_and_failures_as_crosses():
    fig, ax = plots.new_figure()
    centre = np.column_stack([-X, -Y])
    dots, crosses = plots.outcome_scatter(ax, centre, SCORE, SUCCESS, "score")
    np.testing.assert_allclose(dots.get_offsets(), centre[SUCCESS])
    np.testing.assert_allclose(dots.get_array(), SCORE[SUCCESS])
    # the colour scale is the successes' (0.91-0.99), not pulled down by the failures'
    assert dots.get_clim() == pytest.approx((0.91, 0.99))
    np.testing.assert_allclose(crosses.get_offsets(), centre[~SUCCESS])
    np.testing.assert_allclose(crosses.get_facecolor()[0][:3], to_rgb(plots.FAILURE_COLOUR))
    labels = [t.get_text() for t in ax.get_legend().get_texts()]
    assert labels == ["success (3)", "failure (3)"]
    # all held: no crosses, and nothing to cross
    fig, ax = plots.new_figure()
    dots, crosses = plots.outcome_scatter(ax, centre, SCORE, np.ones(6, bool), "score")
    assert crosses is None and len(dots.get_offsets()) == 6


def colour_at(png: bytes, pixel) -> np.ndarray:
    img = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), float) / 255
    col, row = (int(round(v)) for v in pixel)
    return img[row, col]


def is_failure_red(rgb) -> bool:
    return np.linalg.norm(rgb - np.array(to_rgb(plots.FAILURE_COLOUR))) < 0.15


def test_tab_4s_map_marks_each_failure_red(tmp_path):
    png, pixels = views.score_map_png(fake_run())
    assert pixels.shape == (6, 2) and np.isfinite(pixels).all()
    for k in range(6):
        assert is_failure_red(colour_at(png, pixels[k])) == (not SUCCESS[k]), k


def test_the_reports_score_map_marks_each_failure_red(tmp_path):
    out = maps(fake_run(), tmp_path)
    png = out["score_map"].read_bytes()
    # the same drawing as draw_candidates by outcome: its pixels tell where each is
    pixels = plots.draw_candidates(
        box(-60, -40, 60, 40),
        X,
        Y,
        np.zeros(6),
        tmp_path / "again.png",
        values=np.nan_to_num(SCORE),
        success=SUCCESS,
        title=plots.outcome_title(6),
    )
    for k in range(6):
        assert is_failure_red(colour_at(png, pixels[k])) == (not SUCCESS[k]), k


@pytest.mark.parametrize("pose", [None, 4])
def test_a_gripper_frame_map_draws_each_pick_point_at_its_own_values(tmp_path, pose):
    """The page's maps and its values share one frame: a pick-point's mark lies at its
    (x_mm, y_mm) on equal, upright axes (x right, y up), whatever its yaw -- so a value
    read off the map is the value in the table -- and drawing one whole (its pose)
    moves no mark."""
    rng = np.random.default_rng(3)
    x, y, yaw = rng.uniform(-30, 30, 40), rng.uniform(-20, 20, 40), rng.uniform(0, 360, 40)
    pose_arg = None if pose is None else (pose, 50.0)
    pixels = plots.draw_gripper_frame(
        box(-20, -10, 20, 10), GripperSpec(), x, y, yaw, tmp_path / "m.png", pose=pose_arg
    )
    # column = a x + b, row = -a y + c: one scale for both axes, y up
    fit = np.linalg.lstsq(np.column_stack([x, np.ones(40)]), pixels[:, 0], rcond=None)[0]
    a = fit[0]
    assert a > 0
    np.testing.assert_allclose(pixels[:, 0], a * x + fit[1], atol=0.5)
    np.testing.assert_allclose(pixels[:, 1], -a * y + np.mean(pixels[:, 1] + a * y), atol=0.5)
    bare = plots.draw_gripper_frame(
        box(-20, -10, 20, 10), GripperSpec(), x, y, yaw, tmp_path / "bare.png"
    )
    np.testing.assert_allclose(pixels, bare)
