"""A part's width against the gripper's stroke, checked from its outline before any
raster, scene or output folder (pickpoints.check_stroke): wider than the stroke in
every direction is refused with the numbers; a fit only without the safety zone, or at
few yaws, is a warning with the numbers."""

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

    monkeypatch.setattr(pp.fk, "rasterize_bins", refuse)
    monkeypatch.setattr(evaluation, "build_scene", refuse)


def disc_photo(diameter_mm: float):
    """The shipped 50 mm disc photo at the scale that makes it diameter_mm across."""
    return load_object(
        DISC_PNG, px_per_mm=10.0 * 50.0 / diameter_mm, thickness_mm=8, density_kg_m3=7850
    )


def box_mesh(tmp_path, side_mm: float):
    path = tmp_path / f"box{side_mm:g}.stl"
    trimesh.creation.box([side_mm, side_mm, 20.0]).export(path)
    return load_object(path, unit="mm", density_kg_m3=2700)


def test_a_photo_wider_than_the_stroke_everywhere_is_refused_before_any_work(tmp_path, no_work):
    out = tmp_path / "run"
    with pytest.raises(ConfigError) as err:
        evaluation.evaluate(disc_photo(200.0), "robotiq-2f85", n=8, out=out)
    text = str(err.value)
    assert "robotiq-2f85 (stroke 85 mm)" in text and "wider than the stroke" in text
    width = float(text.split("the part is ")[1].split(" mm wide")[0])
    assert 95.0 < width < 110.0  # a finger-wide chord of a 200 mm disc that fills 35 %
    assert not out.exists()


def test_a_mesh_wider_than_an_mjcf_grippers_stroke_is_refused(tmp_path, no_work):
    linkage = load_gripper("robotiq-2f85-linkage")  # stroke measured from its model
    with pytest.raises(ConfigError, match=r"robotiq-2f85-linkage \(stroke 8\d(\.\d+)? mm\)"):
        evaluation.evaluate(box_mesh(tmp_path, 200.0), linkage, n=8, out=tmp_path / "run")
    assert not (tmp_path / "run").exists()


def test_the_cli_refuses_it_before_the_folder_is_claimed(tmp_path, capsys):
    out = tmp_path / "run"
    rc = main(
        ["evaluate", str(DISC_PNG), "--px-per-mm", "2.5", "--thickness-mm", "8",
         "--density-kg-m3", "7850", "--n", "4", "--out", str(out)]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert rc == 2 and "wider than the stroke" in err and "stroke 85 mm" in err
    assert not out.exists()


def test_a_fit_only_without_the_safety_zone_is_a_warning_with_numbers(no_work):
    # 140 mm across: a 35 %-filled chord is ~83 mm, under the 85 mm stroke, but not with
    # 5 mm of safety zone on each side
    with pytest.warns(
        PlausibilityWarning, match=r"narrowest section is 8\d\.\d mm.*need 9\d\.\d mm"
    ):
        with pytest.raises(Reached):
            evaluation.evaluate(disc_photo(140.0), "robotiq-2f85", n=8)


def test_a_fit_at_few_yaws_is_a_warning_with_the_fraction(tmp_path, no_work):
    # a 125 mm square fits the 2F-85 only near its corners (about a sixth of the yaws)
    with pytest.warns(PlausibilityWarning, match=r"at only \d+ % of the yaws"):
        with pytest.raises(Reached):
            evaluation.evaluate(box_mesh(tmp_path, 125.0), "robotiq-2f85", n=8)


def test_the_width_is_local_a_frame_with_thin_arms_fits():
    # 300 mm across in every direction, but each 20 mm arm fits between the pads
    frame = box(0, 0, 300, 300).difference(box(20, 20, 300, 300))
    obj = object_from_polygon(frame, thickness_mm=5, density_kg_m3=2700, name="frame")
    fit = pp.check_stroke(obj, load_gripper("robotiq-2f85"))
    assert fit.narrowest_mm == pytest.approx(20.0, abs=1.0) and fit.fits == 1.0


@pytest.mark.parametrize("asset", asset_names())
def test_every_shipped_asset_fits_every_preset_without_a_word(asset):
    obj = load_asset(asset)
    for name in preset_names():
        with warnings.catch_warnings():
            warnings.simplefilter("error", PlausibilityWarning)  # shown only, elsewhere
            fit = pp.check_stroke(obj, load_gripper(name))
        assert fit.narrowest_mm < 60.0 and fit.fits >= 0.9, (asset, name)


def test_the_gui_checks_with_the_same_function_before_sampling(no_work, monkeypatch):
    from mjx_pick.gui import forms, jobs
    from mjx_pick.gui.page.generate_tab import sample_picks

    settings = forms.Settings(
        load_gripper("robotiq-2f85"), pp.PickConfig(), GraspConfig(), ContactParams()
    )
    with pytest.raises(ConfigError, match="wider than the stroke"):
        jobs.feasible_estimate(disc_photo(200.0), settings, 100, 0)  # before a run starts
    with pytest.raises(ConfigError, match="wider than the stroke"):
        sample_picks(disc_photo(200.0), settings, 100, 0)  # tab 3's map
    # a warning goes to the page with the numbers, then sampling starts
    monkeypatch.setattr(pp, "generate_normal", lambda *args: "sampled")
    picks, warned = sample_picks(disc_photo(140.0), settings, 100, 0)
    assert picks == "sampled" and any("safety zone" in w and " mm" in w for w in warned)
