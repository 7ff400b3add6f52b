"""Pick-point generation: the three checks on known answers, reference agreement, modes."""

import math

import numpy as np
import pytest
import shapely
from shapely.geometry import Point, box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.kernels import feasibility as fk

GRIPPER = mp.GripperSpec()  # Robotiq 2F-85: stroke 85, width 22, depth 8


def rect(w_x=20.0, h_y=40.0):
    return mp.object_from_polygon(
        box(-w_x / 2, -h_y / 2, w_x / 2, h_y / 2),
        thickness_mm=10,
        mass_g=20,
        name=f"rect{w_x}x{h_y}",
    )


def test_centred_rectangle_coverage_by_hand():
    # 20 (x) by 40 (y) at yaw 0: pads start 5 mm outside x = +-10 -> opening 30 mm;
    # the 22 mm band is fully inside the rectangle's 40 mm: covered 20 x 22 of 30 x 22
    checker = pp.FeasibilityChecker(rect(), GRIPPER)
    res = checker([0.0], [0.0], [0.0])
    assert res["reason"][0] == fk.FEASIBLE
    assert res["opening_mm"][0] == pytest.approx(30.0, abs=0.5)
    assert res["coverage"][0] == pytest.approx(20 * 22 / (30 * 22), abs=0.02)
    assert res["gap_left_mm"][0] == pytest.approx(5.0, abs=0.5)


def test_turned_rectangle_wider_than_stroke_is_too_wide():
    narrow = mp.GripperSpec(name="narrow", stroke_mm=38.0)  # shorter than the 40 mm length
    checker = pp.FeasibilityChecker(rect(), narrow)
    res = checker([0.0, 0.0], [0.0, 0.0], [0.0, 90.0])
    assert list(res["reason"]) == [fk.FEASIBLE, fk.TOO_WIDE]


def test_candidate_off_the_object():
    checker = pp.FeasibilityChecker(rect(), GRIPPER)
    res = checker([0.0], [60.0], [0.0])  # band misses the rectangle entirely
    assert res["reason"][0] == fk.OFF_OBJECT


def test_finger_inside_ring_hole_fails_clearance():
    # the 24 mm hole is taller than the 22 mm fingers, so the band sees a 9.6 mm gap in
    # it; the right finger starts in that gap but needs 5 + 8 mm: it lands on the rim
    ring = mp.object_from_polygon(
        Point(0, 0).buffer(30, quad_segs=64).difference(Point(0, 0).buffer(12, quad_segs=64)),
        thickness_mm=6,
        mass_g=15,
        name="ring24",
    )
    checker = pp.FeasibilityChecker(ring, GRIPPER)
    res = checker([40.0], [0.0], [0.0])
    assert res["reason"][0] == fk.CLEARANCE
    ref = fk.reference_check(ring.polygon, checker.band, 40.0, 0.0, 0.0)
    assert ref[0] == fk.CLEARANCE


def test_low_coverage_rejected():
    thin = mp.object_from_polygon(box(-2, -20, 2, 20), thickness_mm=5, mass_g=5, name="thin")
    checker = pp.FeasibilityChecker(thin, GRIPPER, pp.PickConfig(min_coverage=0.35))
    res = checker([0.0], [0.0], [0.0])  # 4 mm of 14 mm between the pads
    assert res["reason"][0] == fk.COVERAGE
    assert res["coverage"][0] == pytest.approx(4 / 14, abs=0.04)


def assert_agrees_with_reference(checker, polygon, x, y, yaw, res):
    """The kernel's results `res` against the exact reference at (x, y, yaw): every
    disagreement must come from the 0.5 mm raster -- flip back under a half-pixel nudge
    of the pose or a 1 mm change of the band -- and at most 5 % disagree."""
    n = len(x)
    mismatches = 0
    for i in range(n):
        reason, opening, coverage = fk.reference_check(
            polygon, checker.band, x[i], y[i], math.radians(yaw[i])
        )
        if reason != res["reason"][i]:
            mismatches += 1
            nudged = {
                fk.reference_check(
                    polygon,
                    checker.band._replace(finger_width_mm=22 + dw),
                    x[i] + dx,
                    y[i] + dy,
                    math.radians(yaw[i]),
                )[0]
                for dw in (-1, 0, 1)
                for dx in (-0.5, 0, 0.5)
                for dy in (-0.5, 0, 0.5)
            }
            assert res["reason"][i] in nudged
        elif reason == fk.FEASIBLE:
            # each side's extent: one 0.5 mm pixel, half a yaw bin of arc at the rim
            # (<= 0.25 mm) and the reference's own 0.1 mm sampling -> 2 x 0.85 mm
            assert res["opening_mm"][i] == pytest.approx(opening, abs=1.7)
            assert res["coverage"][i] == pytest.approx(coverage, abs=0.05)
    assert mismatches <= 0.05 * n


def test_kernel_agrees_with_reference(door_opener):
    checker = pp.FeasibilityChecker(door_opener, GRIPPER)
    rng = np.random.default_rng(3)
    n = 150
    x, y = rng.uniform(-45, 45, n), rng.uniform(-45, 45, n)
    yaw = rng.uniform(0, 360, n)
    assert_agrees_with_reference(checker, door_opener.polygon, x, y, yaw, checker(x, y, yaw))


def test_fixed_opening_detects_a_finger_landing_on_the_object(block):
    # the 40 x 20 mm block, centred at yaw 0: the plan opens 40 + 2 x 5 = 50 mm
    checker = pp.FeasibilityChecker(block, GRIPPER)
    planned = checker([0.0], [0.0], [0.0])
    assert planned["opening_mm"][0] == pytest.approx(50.0, abs=1.0)
    # the object is really 3 mm to the right: fingers 25 mm out still clear it ...
    shifted = checker([3.0], [0.0], [0.0], opening_mm=planned["opening_mm"])
    assert shifted["reason"][0] == fk.FEASIBLE
    assert shifted["opening_mm"][0] == pytest.approx(planned["opening_mm"][0])
    assert shifted["gap_right_mm"][0] == pytest.approx(2.0, abs=0.6)
    # ... 6 mm to the right, the right finger comes down on it
    landed = checker([6.0], [0.0], [0.0], opening_mm=planned["opening_mm"])
    assert landed["reason"][0] == fk.CLEARANCE
    ref = fk.reference_check(block.polygon, checker.band, 6.0, 0.0, 0.0, opening_mm=50.0)
    assert ref[0] == fk.CLEARANCE
    ref = fk.reference_check(block.polygon, checker.band, 3.0, 0.0, 0.0, opening_mm=50.0)
    assert ref[0] == fk.FEASIBLE


def test_yaw_symmetry(door_opener):
    # a symmetric gripper: (x, y, yaw + 180) is (-x, -y, yaw) with the fingers swapped.
    # The kernel stores half a turn of yaw bins and maps the other half onto it; the
    # mapped half must agree with the exact reference, which knows no such shortcut
    checker = pp.FeasibilityChecker(door_opener, GRIPPER)
    rng = np.random.default_rng(0)
    x, y, yaw = rng.uniform(-30, 30, 96), rng.uniform(-30, 30, 96), rng.uniform(0, 180, 96)
    turned = checker(-x, -y, yaw + 180)
    assert_agrees_with_reference(checker, door_opener.polygon, -x, -y, yaw + 180, turned)
    # and the fingers swap: each pad's gap is the other's
    a = checker(x, y, yaw)
    np.testing.assert_array_equal(a["reason"], turned["reason"])
    both = (a["reason"] == fk.FEASIBLE) & (turned["reason"] == fk.FEASIBLE)
    assert both.sum() >= 10
    np.testing.assert_allclose(a["gap_left_mm"][both], turned["gap_right_mm"][both], atol=1e-4)


def test_the_cropped_stack_holds_every_bins_column_counts(door_opener):
    # each yaw bin keeps only the rows and columns its silhouette occupies: any band of
    # rows of any column of the full grid still sums to what the stack's block gives
    from mjx_pick.core.objects import rasterize

    stack = pp.FeasibilityChecker(door_opener, GRIPPER).stack
    polygon = door_opener.band_outline(*pp.pad_band_mm(door_opener, GRIPPER, GraspConfig()))
    radius = float(np.hypot(*shapely.get_coordinates(polygon).T).max())
    n_bins, rng = len(stack.crops), np.random.default_rng(2)
    for k in (0, n_bins // 3, n_bins - 1):
        mask, _ = rasterize(polygon, stack.res_mm, k * math.pi / n_bins, radius_mm=radius)
        base, row0, rows, col0, cols = stack.crops[k]
        block = stack.cum[base : base + (rows + 1) * cols].reshape(rows + 1, cols)
        for _ in range(200):
            lo, hi = np.sort(rng.integers(0, stack.size + 1, 2))
            j = rng.integers(0, stack.size)
            if col0 <= j < col0 + cols:
                a, b = (np.clip(i - row0, 0, rows) for i in (lo, hi))
                got = int(block[b, j - col0]) - int(block[a, j - col0])
            else:
                got = 0
            assert got == int(mask[lo:hi, j].sum())


def test_a_candidates_result_does_not_depend_on_its_batch(door_opener):
    # candidates are checked in blocks of fk.BLOCK: one across block boundaries, fixed
    # openings mixed in, gets the result it gets alone
    checker = pp.FeasibilityChecker(door_opener, GRIPPER)
    rng = np.random.default_rng(4)
    n = 2 * fk.BLOCK + 5
    x, y, yaw = rng.uniform(-45, 45, n), rng.uniform(-45, 45, n), rng.uniform(0, 360, n)
    opening = np.where(rng.random(n) < 0.3, rng.uniform(20, 85, n), np.nan)
    whole = checker(x, y, yaw, opening)
    for i in (0, fk.BLOCK - 1, fk.BLOCK, n - 1):
        one = checker(x[i : i + 1], y[i : i + 1], yaw[i : i + 1], opening[i : i + 1])
        for k, v in whole.items():
            np.testing.assert_array_equal(one[k], v[i : i + 1], err_msg=k)
    assert len(np.unique(whole["reason"])) >= 4  # the checks were all exercised


def test_the_search_checks_blocks_side_by_side_as_one_after_the_other(door_opener):
    # generate_normal checks growing groups of blocks on threads; its picks and counts
    # are those of checking the seeded blocks one at a time
    picks = pp.generate_normal(door_opener, GRIPPER, 2500, seed=3)
    checker = pp.FeasibilityChecker(door_opener, GRIPPER)
    one_by_one, found = [], 0
    for ids, x, y, yaw in pp.candidate_blocks(checker, seed=3):
        one_by_one.append(checker.batch(ids, x, y, yaw, mode="normal"))
        found += len(one_by_one[-1])
        if found >= 2500:
            break
    ref = pp.concat(one_by_one)
    assert len(one_by_one) >= 4  # more than one group of blocks
    assert picks.n_candidates == ref.n_candidates and picks.rejected == ref.rejected
    ref = ref.take(slice(0, 2500))
    for k in ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "coverage", "gap_left_mm"):
        np.testing.assert_array_equal(getattr(picks, k), getattr(ref, k), err_msg=k)


def test_same_seed_same_picks(door_opener):
    a = pp.generate_normal(door_opener, GRIPPER, 50, seed=7)
    b = pp.generate_normal(door_opener, GRIPPER, 50, seed=7)
    c = pp.generate_normal(door_opener, GRIPPER, 50, seed=8)
    np.testing.assert_array_equal(a.x_mm, b.x_mm)
    np.testing.assert_array_equal(a.pick_id, b.pick_id)
    assert not np.array_equal(a.x_mm, c.x_mm)


def test_normal_mode_gives_n_feasible(door_opener):
    picks = pp.generate_normal(door_opener, GRIPPER, 300, seed=0)
    assert len(picks) == 300
    # feasible by the exact reference too (not by the checker that chose them), up to
    # the raster's tolerance; a sample of 60 keeps it fast
    checker = pp.FeasibilityChecker(door_opener, GRIPPER)
    s = picks.take(slice(0, 60))
    res = {"reason": np.zeros(60, int), "opening_mm": s.opening_mm, "coverage": s.coverage}
    assert_agrees_with_reference(checker, door_opener.polygon, s.x_mm, s.y_mm, s.yaw_deg, res)
    assert np.all(np.abs(picks.x_mm) <= 0.5 * door_opener.length_mm)
    assert np.all((picks.yaw_deg >= 0) & (picks.yaw_deg < 360))
    # candidates are checked in whole blocks; every rejection is counted with its reason
    assert picks.n_candidates % pp.CANDIDATE_BLOCK == 0
    assert 300 <= picks.n_candidates - sum(picks.rejected.values())
    assert picks.pick_id.max() < picks.n_candidates


def test_grid_mode_is_systematic():
    picks = pp.generate_grid(rect(), GRIPPER, x_step_mm=5, y_step_mm=5, yaw_step_deg=45)
    xs, ys, yaws = set(np.round(picks.x_mm, 6)), set(np.round(picks.y_mm, 6)), set(picks.yaw_deg)
    assert yaws <= {0.0, 45.0, 90.0, 135.0, 180.0, 225.0, 270.0, 315.0}
    assert 0.0 in xs and 0.0 in ys  # the centred pose is on the grid (range +-20 mm)
    total = len(picks) + sum(picks.rejected.values())
    assert total == picks.n_candidates == 9 * 9 * 8


def test_optimization_mode_stops_at_k_or_max():
    obj = rect()

    def score(batch):  # a stand-in for the simulator: centred pick-points score high
        return np.exp(-(batch.x_mm**2 + batch.y_mm**2) / 50.0)

    res = pp.optimize(obj, GRIPPER, score, k=5, min_score=0.8, max_n=5000, batch_size=64, seed=1)
    assert res.reached
    assert len(res.best) >= 5 and np.all(score(res.best) >= 0.8)
    assert len(res.picks) % 64 == 0 or len(res.picks) == 5000
    capped = pp.optimize(obj, GRIPPER, score, k=10**6, min_score=0.8, max_n=200, batch_size=64)
    assert not capped.reached and len(capped.picks) == 200


def test_bad_settings():
    with pytest.raises(mp.ConfigError, match="min_coverage = 1.5"):
        pp.PickConfig(min_coverage=1.5)
    with pytest.raises(mp.ConfigError, match="safety_zone_mm = -1"):
        pp.PickConfig(safety_zone_mm=-1)
    with pytest.raises(mp.ConfigError, match="safety_zone_mm = 50"):
        pp.FeasibilityChecker(rect(), GRIPPER, pp.PickConfig(safety_zone_mm=50))
    wide = mp.object_from_polygon(box(-60, -60, 60, 60), thickness_mm=5, mass_g=50, name="big")
    central = pp.PickConfig(max_candidates=5000, x_range_mm=10, y_range_mm=10)
    # every candidate: the open fingers cannot reach around it (said so: the words hold
    # for an off-centre part narrower than the stroke too, issue 56 item 9)
    with pytest.raises(mp.ConfigError, match="cannot reach around the part at that offset"):
        pp.generate_normal(wide, GRIPPER, 10, config=central)


def test_pictures(tmp_path, door_opener):
    from mjx_pick.outputs import plots

    picks = pp.generate_normal(door_opener, GRIPPER, 20, seed=0)
    plots.draw_pick(
        door_opener,
        GRIPPER,
        picks.x_mm[0],
        picks.y_mm[0],
        picks.yaw_deg[0],
        picks.opening_mm[0],
        tmp_path / "pick.png",
    )
    rng = np.random.default_rng(0)
    x, y, yaw = rng.uniform(-40, 40, 500), rng.uniform(-40, 40, 500), rng.uniform(0, 360, 500)
    reasons = np.array(fk.REASONS)[pp.FeasibilityChecker(door_opener, GRIPPER)(x, y, yaw)["reason"]]
    plots.draw_candidates(door_opener, x, y, yaw, tmp_path / "overview.png", labels=reasons)
    import matplotlib.image as mpimg

    for name in ("pick.png", "overview.png"):
        img = mpimg.imread(tmp_path / name)
        assert img.shape[0] > 300 and img.std() > 0.05  # a real picture, not blank


def test_a_long_search_reports_its_progress_and_can_be_stopped(block):
    """Few feasible poses (coverage 0.97): the search says after each block how many
    candidates it checked and why they were rejected, and stops when that callback
    raises (the GUI's Stop) -- never minutes of silence."""

    class Stop(Exception):
        pass

    seen = []

    def progress(drawn, found, rejected):
        seen.append((drawn, found, dict(rejected)))
        if len(seen) == 3:
            raise Stop

    strict = pp.PickConfig(min_coverage=0.97)
    with pytest.raises(Stop):
        pp.generate_normal(block, mp.load_gripper("robotiq-2f85"), 200, 0, strict, None, progress)
    assert [d for d, _, _ in seen] == [pp.CANDIDATE_BLOCK * k for k in (1, 2, 3)]
    drawn, found, rejected = seen[-1]
    assert found + sum(rejected.values()) == drawn and rejected["coverage"] > drawn / 2
    note = pp.search_note(drawn, 1_000_000, found, 200, rejected)
    assert note.startswith(f"checked {drawn:,} of at most 1,000,000 candidate poses")
    assert "the object fills too little of the region between the pads" in note


def test_rare_feasible_poses_are_said_by_the_reason_that_rejects_the_others(block):
    """A minimum coverage few poses meet (0.71 on the 2F-85): the warning names the
    coverage and how to change it -- never a part wider than the stroke (the reason
    only a part's width gives); one none meets (0.95) is refused first for the coverage,
    the check every candidate the others let through failed, though the width
    rejected some first."""
    from mjx_pick.core.config import PlausibilityWarning
    from mjx_pick.studies.comparison import shared_candidates

    gripper = mp.load_gripper("robotiq-2f85")
    with pytest.warns(PlausibilityWarning) as caught:
        pp.generate_normal(block, gripper, 3, 0, pp.PickConfig(min_coverage=0.71))
    (text,) = [str(w.message) for w in caught if "candidate poses are feasible" in str(w.message)]
    assert "because the object fills too little of the region between the pads" in text
    assert "lower the minimum coverage, now 0.71" in text
    for wrong in ("wider than the stroke", "larger stroke", "barely fits"):
        assert wrong not in text
    strict = pp.PickConfig(min_coverage=0.95, max_candidates=8192)
    with pytest.raises(mp.ConfigError) as refused:
        shared_candidates(block, [gripper, mp.load_gripper("onrobot-rg2")], 5, 0, strict)
    said = str(refused.value)
    # led by the check that rejected every candidate the others let through
    lead = "those that passed the other checks were all rejected: "
    assert f"robotiq-2f85: {lead}7,527 because the object fills too little" in said
    assert f"onrobot-rg2: {lead}8,165 because the object fills too little" in said
