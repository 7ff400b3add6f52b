"""A part's width against the gripper's stroke, checked from its outline before any
raster, scene or output folder (pickpoints.check_stroke): wider than the stroke in
every direction is refused with the numbers; a fit only without the safety zone, or at
few yaws, is a warning with the numbers."""

import dataclasses
import re
import warnings
from pathlib import Path

import pytest
import trimesh
from shapely.geometry import box

from mjx_pick.cli import main
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import ConfigError, PlausibilityWarning
from mjx_pick.core.gripper import load_gripper, preset_names
from mjx_pick.core.objects import asset_names, load_asset, load_object, object_from_polygon
from mjx_pick.core.physics import ContactParams
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.studies import evaluation

DISC_PNG = Path(__file__).resolve().parents[1] / "mjx_pick/assets/objects/disc.png"  # 50 mm


class Reached(Exception):
    """Raised by a stand-in for work that must not start."""


@pytest.fixture()
def no_work(monkeypatch):
    """Rasterising the silhouette or building a scene fails the test: the check must
    come before both."""

    def refuse(*args, **kwargs):
        raise Reached("work started")

    monkeypatch.setattr(pp.fk, "packed_bins", refuse)
    monkeypatch.setattr(evaluation, "scene_of", refuse)


def disc_photo(diameter_mm: float):
    """The shipped 50 mm disc photo at the scale that makes it diameter_mm across."""
    return load_object(
        DISC_PNG, px_per_mm=10.0 * 50.0 / diameter_mm, thickness_mm=8, density_kg_m3=7850
    )


def box_mesh(tmp_path, side_mm: float):
    path = tmp_path / f"box{side_mm:g}.stl"
    trimesh.creation.box([side_mm, side_mm, 20.0]).export(path)
    return load_object(path, unit="mm", density_kg_m3=2700)


def bar_mesh(tmp_path):
    path = tmp_path / "bar.stl"
    trimesh.creation.box([200.0, 30.0, 10.0]).export(path)
    return load_object(path, unit="mm", density_kg_m3=2700)


def test_a_mesh_wider_than_an_mjcf_grippers_stroke_is_refused_before_any_work(tmp_path, no_work):
    linkage = load_gripper("robotiq-2f85-linkage")  # stroke measured from its model
    out = tmp_path / "run"
    with pytest.raises(ConfigError) as err:
        evaluation.evaluate(box_mesh(tmp_path, 200.0), linkage, n=8, out=out)
    text = str(err.value)
    assert re.search(r"robotiq-2f85-linkage \(stroke 8\d(\.\d+)? mm\)", text)
    assert "wider than the stroke, so no pick-point can be feasible" in text
    width = float(text.split("at least ")[1].split(" mm")[0])
    assert 90.0 < width < 100.0  # a 200 mm square's corner sections are ~100 mm
    assert not out.exists()


def test_a_photo_that_fits_only_without_the_safety_zone_is_refused_with_the_numbers(
    tmp_path, no_work
):
    # 200 mm across: a finger-wide section of the disc that fills 35 % of the pads'
    # region is wider than 75 mm (the 85 mm stroke less two 5 mm safety zones)
    out = tmp_path / "run"
    with pytest.raises(ConfigError) as err:
        evaluation.evaluate(disc_photo(200.0), "robotiq-2f85", n=8, out=out)
    text = str(err.value)
    assert "robotiq-2f85 (stroke 85 mm)" in text and "5 mm safety zone" in text
    width = float(text.split("at least ")[1].split(" mm")[0])
    need = float(text.split("fingers need ")[1].split(" mm")[0])
    assert 75.0 < width < 85.0 and need == pytest.approx(width + 10.0, abs=0.06)
    assert "lower --safety-zone-mm" in text and not out.exists()
    # with the smaller safety zone it names, the check lets it through
    below = float(text.split("below ")[1].split(",")[0])
    fit = pp.check_stroke(disc_photo(200.0), load_gripper("robotiq-2f85"),
                          pp.PickConfig(safety_zone_mm=below - 0.1))  # fmt: skip
    assert fit is not None and fit.narrowest_mm == pytest.approx(width, abs=0.06)


def test_the_cli_refuses_it_before_the_folder_is_claimed(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(
        ["evaluate", str(DISC_PNG), "--px-per-mm", "2.5", "--thickness-mm", "8",
         "--density-kg-m3", "7850", "--n", "4", "--out", str(out)]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "no pick-point can be feasible" in err and "stroke 85 mm" in err
    assert not out.exists()


def test_a_fit_at_few_of_the_configured_yaws_is_a_warning_with_the_fraction(tmp_path, no_work):
    # a 200 x 30 mm bar closed along its length (yaw within 5 deg of 0) never fits
    # the 2F-85; across it, it does: not refused, but the yaw range is worth a word
    bar = bar_mesh(tmp_path)
    along = pp.PickConfig(yaw_min_deg=-5, yaw_max_deg=5)
    with pytest.warns(PlausibilityWarning, match=r"at least \d+\.\d mm.* at only 0 % of the yaws"):
        with pytest.raises(Reached):
            evaluation.evaluate(bar, "robotiq-2f85", n=8, pick_config=along)


def test_the_width_is_local_a_frame_with_thin_arms_fits():
    # 300 mm across in every direction, but each 20 mm arm fits between the pads
    frame = box(0, 0, 300, 300).difference(box(20, 20, 300, 300))
    obj = object_from_polygon(frame, thickness_mm=5, density_kg_m3=2700, name="frame")
    gripper = load_gripper("robotiq-2f85")
    fit = pp.stroke_fit(obj, gripper)
    assert fit.narrowest_mm <= 20.0 and fit.fits == 1.0  # a bound: at most the arm's width
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)  # no refusal, no warning
        assert pp.check_stroke(obj, gripper).narrowest_mm == fit.narrowest_mm


@pytest.mark.parametrize("asset", asset_names())
def test_every_shipped_asset_fits_every_preset_without_a_word(asset):
    obj = load_asset(asset)
    for name in preset_names():
        with warnings.catch_warnings():
            warnings.simplefilter("error", PlausibilityWarning)  # shown only, elsewhere
            # None: the whole part fits between the pads at enough yaws to say nothing;
            # else its sections fit at enough yaws (a 50 mm stroke takes the door opener
            # across, not whole): no refusal, no warning either way
            fit = pp.check_stroke(obj, load_gripper(name))
            assert fit is None or fit.fits >= pp.STROKE_FEW_YAWS, (asset, name)


def test_the_gui_checks_with_the_same_function_before_sampling(tmp_path, no_work, monkeypatch):
    from mjx_pick.gui import forms, jobs
    from mjx_pick.gui.page.generate_tab import sample_picks

    settings = forms.Settings(
        load_gripper("robotiq-2f85"), pp.PickConfig(), GraspConfig(), ContactParams()
    )
    with pytest.raises(ConfigError, match="no pick-point can be feasible"):
        jobs.feasible_estimate(disc_photo(200.0), settings, 100, 0)  # before a run starts
    with pytest.raises(ConfigError, match="no pick-point can be feasible"):
        sample_picks(disc_photo(200.0), settings, 100, 0)  # tab 3's map
    # a warning goes to the page with the numbers, then sampling starts
    monkeypatch.setattr(pp, "generate_normal", lambda *args, **kw: "sampled")
    along = dataclasses.replace(settings, picks=pp.PickConfig(yaw_min_deg=-5, yaw_max_deg=5))
    picks, warned = sample_picks(bar_mesh(tmp_path), along, 100, 0)
    assert picks == "sampled" and any("at only 0 % of the yaws" in w for w in warned)


def test_pads_that_miss_the_part_are_left_to_the_feasibility_checks_message():
    # the fingertips at the block's top: the pads meet no outline (no traceback here;
    # the checker that follows says what to change)
    obj = load_asset("block", pick_height_mm=20)
    gripper = load_gripper("robotiq-2f85")
    assert pp.check_stroke(obj, gripper) is None
    assert pp.stroke_fit(obj, gripper).narrowest_mm == float("inf")
    with pytest.raises(ConfigError, match="lower pick_height_mm"):
        pp.FeasibilityChecker(obj, gripper)
