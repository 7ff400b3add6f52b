"""Tab 4's 3-D replay in Chromium: the simulated bodies in three.js, moved by the time
slider (their positions in the page are the trace's), the force plot's marker under
it, play and pause, a failure drawn in the failure colour. The harness (server,
browser, page) is tests/test_gui.py's."""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
import test_gui

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.outputs.plots import FAILURE_COLOUR
from mjx_pick.outputs.reporting import Run

# test_gui's fixtures: one GUI server for this module, one browser, a page per test
server, browser, page = test_gui.server, test_gui.browser, test_gui.page

FAST = GraspConfig(close_timeout_s=1.0, lift_height_mm=20.0, hold_s=0.1)
# the page holds poses and times as float32
PAGE_TOL_M = 1e-6


@pytest.fixture(scope="module")
def replay_run(server, door_opener):
    """An evaluate folder in the server's work folder with two traced pick-points: the
    door opener centred across the pads (it holds) and the same part 80 mm beside
    them (the pads close on nothing: no_contact)."""
    _, work = server
    gripper = mp.load_gripper("robotiq-2f85")
    checker = pp.FeasibilityChecker(door_opener, gripper, pp.PickConfig(), FAST)
    held = checker(np.array([0.0]), np.array([0.0]), np.array([90.0]))
    assert pp.REASONS[int(held["reason"][0])] == "feasible"
    picks = pp.GraspBatch(
        pick_id=np.array([0, 1]),
        x_mm=np.array([0.0, 0.0]),
        y_mm=np.array([0.0, 80.0]),
        yaw_deg=np.array([90.0, 0.0]),
        opening_mm=np.repeat(held["opening_mm"], 2),
        coverage=np.array([float(held["coverage"][0]), 0.0]),
        gap_left_mm=np.repeat(held["gap_left_mm"], 2),
        gap_right_mm=np.repeat(held["gap_right_mm"], 2),
        rejected={},
        n_candidates=2,
        mode="user",
    )
    out = work / "replay-run"
    mp.evaluate(
        door_opener, gripper, picks=picks, grasp=FAST, backend="mujoco", out=out, n_traces=1
    )
    run = Run.load(out)
    assert run.row(0)["success"] and run.row(1)["failure"] == "no_contact"
    return run


def bodies(pg) -> dict:
    """{body name: (position [x, y, z] m, colour '#rrggbb')} of the replay in the page."""
    scene = pg.get_by_test_id("replay-scene").get_attribute("id")
    return pg.evaluate(
        """(id) => {
            const root = window['scene_' + id].getObjectByName('pick-replay');
            return Object.fromEntries(root.children.map((b) => [b.name, [
                b.position.toArray(), '#' + b.children[0].material.color.getHexString()]]));
        }""",
        scene,
    )


def marker_s(pg) -> float:
    """The time the force chart's marker line shows, s."""
    chart = pg.locator(".nicegui-echart").filter(visible=True).get_attribute("id")
    return pg.evaluate(
        "(id) => getElement(id.slice(1)).chart.getOption().series[0].markLine.data[0].xAxis",
        chart,
    )


def open_and_select(pg, run: Run, rank: int) -> None:
    pg.get_by_text("4 Analyze results").click()
    if pg.get_by_test_id("run-dir").input_value() != str(run.path):
        pg.get_by_test_id("run-dir").fill(str(run.path))
        pg.get_by_test_id("open-run").click()
    rows = pg.get_by_test_id("picks-table").locator("tbody tr")
    rows.nth(rank - 1).locator(".q-checkbox").click()
    pg.get_by_test_id("pick-detail").filter(has_text=f"(rank {rank})").wait_for()


def test_the_replay_shows_the_bodies_and_the_slider_moves_them(page, replay_run):
    from playwright.sync_api import expect

    run = replay_run
    trace = run.trace(0)
    t = trace["t_s"]
    open_and_select(page, run, 1)
    page.get_by_test_id("replay-clock").filter(has_text="t = 0.000 s").wait_for()
    page.wait_for_function(
        "(id) => window['scene_' + id]?.getObjectByName('pick-replay')?.children.length === 5",
        arg=page.get_by_test_id("replay-scene").get_attribute("id"),
    )
    shown = bodies(page)
    assert set(shown) == {"world", "object", "gripper", "finger_left", "finger_right"}
    start = {name: np.array(p) for name, (p, _) in shown.items()}
    np.testing.assert_allclose(
        start["object"], [trace[f"object_{c}_m"][0] for c in "xyz"], atol=PAGE_TOL_M
    )
    assert shown["object"][1] == "#3373cc"  # its own colour (rgba .2 .45 .8): a success
    assert "outcome: success" in page.get_by_test_id("replay-outcome").inner_text()
    box = page.get_by_test_id("replay-scene").locator("canvas").bounding_box()
    assert box["width"] > 300 and box["height"] > 300  # drawn at its size, not hidden

    # the slider to its end from the keyboard (10 rows a PageUp; not a click at a pixel,
    # which the force plot above can move as it appears): every body at the last row
    slider = page.get_by_test_id("replay-time")
    handle = slider.locator("[tabindex]").first
    for _ in range(-(-len(t) // 10)):
        handle.press("PageUp")
    expect(slider).to_have_attribute("aria-valuenow", f"{round(float(t[-1]), 6)}")
    page.get_by_test_id("replay-clock").filter(has_text=f"t = {t[-1]:.3f} s").wait_for()
    end = {name: np.array(p) for name, (p, _) in bodies(page).items()}
    np.testing.assert_allclose(
        end["object"], [trace[f"object_{c}_m"][-1] for c in "xyz"], atol=PAGE_TOL_M
    )
    lifted = trace["lift_m"][-1] - trace["lift_m"][0]
    assert lifted == pytest.approx(FAST.lift_height_mm * 1e-3, abs=1e-3)
    np.testing.assert_allclose(end["gripper"] - start["gripper"], [0, 0, lifted], atol=PAGE_TOL_M)
    closed = trace["finger_left_m"][-1] - trace["finger_left_m"][0]
    assert closed > 1e-3  # the pads closed on the part
    moved = end["finger_left"] - start["finger_left"]
    np.testing.assert_allclose(moved, [closed, 0, lifted], atol=PAGE_TOL_M)
    np.testing.assert_allclose(end["world"], 0.0)
    assert marker_s(page) == pytest.approx(t[-1], abs=1e-6)  # the plot's marker followed

    # a step back: the row before the last, and the marker with it
    handle.press("ArrowLeft")
    page.get_by_test_id("replay-clock").filter(has_text=f"t = {t[-2]:.3f} s").wait_for()
    assert marker_s(page) == pytest.approx(t[-2], abs=1e-6)
    test_gui.shot(page, "replay_3d")


def test_play_advances_time_and_pause_stops_it(page, replay_run):
    run = replay_run
    t = run.trace(0)["t_s"]
    open_and_select(page, run, 1)
    clock = page.get_by_test_id("replay-clock")
    clock.filter(has_text="t = 0.000 s").wait_for()
    slider = page.get_by_test_id("replay-time")

    def now() -> float:
        return float(slider.get_attribute("aria-valuenow"))

    page.get_by_test_id("replay-play").click()
    page.wait_for_function(
        "(el) => Number(el.getAttribute('aria-valuenow')) > 0.1",
        arg=slider.element_handle(),
    )
    page.get_by_test_id("replay-play").click()  # pause
    page.get_by_test_id("replay-play").and_(page.locator('[aria-label="play"]')).wait_for()
    paused = now()
    assert 0.1 < paused <= t[-1]
    # the bodies are where the slider's row is, and they stay there
    k = int(np.argmin(np.abs(t.astype(np.float32) - paused)))
    obj = np.array(bodies(page)["object"][0])
    trace = run.trace(0)
    np.testing.assert_allclose(obj, [trace[f"object_{c}_m"][k] for c in "xyz"], atol=PAGE_TOL_M)
    time.sleep(0.5)
    assert now() == paused


def test_a_failed_pick_point_is_drawn_in_the_failure_colour(page, replay_run):
    run = replay_run
    open_and_select(page, run, 2)
    # the outcome in words, not the results label no_contact
    page.get_by_test_id("replay-outcome").filter(has_text="outcome: no contact").wait_for()
    page.wait_for_function(
        """([id, colour]) => {
            const root = window['scene_' + id]?.getObjectByName('pick-replay');
            const part = root?.getObjectByName('object');
            return part && '#' + part.children[0].material.color.getHexString() === colour;
        }""",
        arg=[page.get_by_test_id("replay-scene").get_attribute("id"), FAILURE_COLOUR],
    )
    shown = bodies(page)
    assert shown["finger_left"][1] != FAILURE_COLOUR  # only the part
    trace = run.trace(1)
    np.testing.assert_allclose(
        shown["object"][0], [trace[f"object_{c}_m"][0] for c in "xyz"], atol=PAGE_TOL_M
    )


def test_the_slider_follows_a_mouse_click_and_a_drag(page, replay_run):
    """The time slider as a user moves it, with the mouse: a click on its track sets
    the time there and a drag follows the pointer -- no error in the page (its min,
    max and step reach Quasar as numbers), and the page still answers after the drag."""
    from playwright.sync_api import expect

    errors = []
    page.on("pageerror", lambda err: errors.append(str(err)))
    page.on("console", lambda m: errors.append(m.text) if m.type == "error" else None)
    received = []  # the sizes of the server's messages to the page

    def websocket(ws) -> None:
        ws.on("framereceived", lambda f: received.append(len(f)))

    page.on("websocket", websocket)
    page.reload()
    run = replay_run
    trace = run.trace(0)
    t = trace["t_s"]
    open_and_select(page, run, 1)
    clock = page.get_by_test_id("replay-clock")
    clock.filter(has_text="t = 0.000 s").wait_for()
    slider = page.get_by_test_id("replay-time")
    slider.scroll_into_view_if_needed()  # the mouse reaches only what the window shows
    box = slider.bounding_box()
    y = box["y"] + box["height"] / 2

    def at(fraction: float) -> float:
        return box["x"] + fraction * box["width"]

    def now() -> float:
        return float(slider.get_attribute("aria-valuenow"))

    # a click halfway along the track: the time there, within a row
    page.mouse.click(at(0.5), y)
    page.wait_for_function(
        "(el) => Number(el.getAttribute('aria-valuenow')) > 0",
        arg=slider.element_handle(),
        timeout=10_000,
    )
    assert now() == pytest.approx(0.5 * float(t[-1]), abs=0.05 * float(t[-1]))
    k = int(np.argmin(np.abs(t - now())))
    clock.filter(has_text=f"t = {t[k]:.3f} s").wait_for()
    np.testing.assert_allclose(
        bodies(page)["object"][0], [trace[f"object_{c}_m"][k] for c in "xyz"], atol=PAGE_TOL_M
    )

    # a drag from a quarter to four fifths, in small moves as a hand makes them, once the
    # page is at rest (under load the selection's chart and track, ~100 kB, can still be
    # on their way after the click's answer)
    for _ in range(50):
        seen = len(received)
        page.wait_for_timeout(300)
        if len(received) == seen:
            break
    received.clear()
    page.mouse.move(at(0.25), y)
    page.mouse.down()
    for i in range(1, 31):
        page.mouse.move(at(0.25 + 0.55 * i / 30), y)
    page.mouse.up()
    page.wait_for_function(
        "([el, v]) => Math.abs(Number(el.getAttribute('aria-valuenow')) - v) < 0.05 * v",
        arg=[slider.element_handle(), 0.8 * float(t[-1])],
        timeout=10_000,
    )
    k = int(np.argmin(np.abs(t - now())))
    clock.filter(has_text=f"t = {t[k]:.3f} s").wait_for(timeout=10_000)
    np.testing.assert_allclose(
        bodies(page)["object"][0], [trace[f"object_{c}_m"][k] for c in "xyz"], atol=PAGE_TOL_M
    )
    # each move answered by a few bytes (the clock), never the force chart's options
    assert received and max(received) < 10_000, sorted(received)[-3:]
    # the page answers: play runs the slider to the trace's end, a tab opens
    page.get_by_test_id("replay-play").click(timeout=10_000)
    expect(slider).to_have_attribute("aria-valuenow", f"{round(float(t[-1]), 6)}", timeout=10_000)
    page.get_by_text("1 Import object model").click(timeout=10_000)
    expect(page.get_by_test_id("import")).to_be_visible(timeout=10_000)
    assert not errors, errors


@pytest.fixture(scope="module")
def grasp_run(server, block):
    """An evaluate folder of three antipodal grasps on the block (grasps given as poses,
    tilted), its best and worst traced: one is simulated on demand in the page."""
    _, work = server
    out = work / "grasp-run"
    mp.evaluate(
        block, "robotiq-2f85", n=3, grasps="antipodal", grasp=FAST, backend="mujoco", out=out,
        n_traces=1,
    )  # fmt: skip
    run = Run.load(out)
    assert {"tilt_deg", "height_mm", "grasp_pose"} <= set(run.table.column_names)
    return run


def quaternions(pg) -> dict:
    """{body name: its quaternion (w, x, y, z)} of the replay in the page."""
    scene = pg.get_by_test_id("replay-scene").get_attribute("id")
    xyzw = pg.evaluate(
        """(id) => Object.fromEntries(window['scene_' + id].getObjectByName('pick-replay')
            .children.map((b) => [b.name, b.quaternion.toArray()]))""",
        scene,
    )
    return {name: np.array([q[3], q[0], q[1], q[2]]) for name, q in xyzw.items()}


def tilt_of(quat_wxyz) -> float:
    """The angle between a body's z axis (the gripper's up) and the world's, deg."""
    w, x, y, z = quat_wxyz
    return float(np.degrees(np.arccos(np.clip(1 - 2 * (x * x + y * y), -1, 1))))


def test_a_grasp_run_shows_its_grasps_and_the_replay_turns_the_gripper(page, grasp_run):
    """Tab 4 on a run of grasps given as poses: each grasp's tilt and height in the
    table, no pick-point map (a vertical approach) but why, the report's vertical-only
    files not offered; the replay's gripper turned by the grasp's own tilt (the page's
    three.js bodies against the trace's kinematics), lifted straight up; a grasp the run
    did not trace simulated as the same pose; its grasps exported as a grasp file."""
    from mjx_pick.gui.replay3d import SceneReplay
    from mjx_pick.outputs.reporting.body_poses import body_track

    run = grasp_run
    test_gui.import_shipped(page)  # the run's object: its untraced grasp is simulated here
    page.get_by_text("4 Analyze results").click()
    page.get_by_test_id("run-dir").fill(str(run.path))
    page.get_by_test_id("open-run").click()
    rows = page.get_by_test_id("picks-table").locator("tbody tr")
    rows.first.wait_for()
    heads = page.get_by_test_id("picks-table").locator("th").all_inner_texts()
    heads = [h.removesuffix("arrow_upward") for h in heads]  # the sort icon's name
    assert "tilt from vertical (deg)" in heads and "grasp centre above the table (mm)" in heads
    assert "3 grasps" in page.get_by_test_id("run-info").inner_text()
    page.get_by_test_id("map-note").filter(has_text="Grasps given as poses: tilted").wait_for()
    assert not page.get_by_test_id("score-map").is_visible()

    ranked = ranked_ids(run)
    traced = {pid for pid, _ in run.traced()}
    rank = max(
        (r for r, pid in enumerate(ranked, 1) if pid in traced),
        key=lambda r: run.row(ranked[r - 1])["tilt_deg"],
    )  # the most tilted of the traced grasps
    pid = ranked[rank - 1]
    tilt = run.row(pid)["tilt_deg"]
    assert tilt > 5.0, tilt  # a grasp that is not a pick-point
    rows.nth(rank - 1).locator(".q-checkbox").click()  # with the mouse, as a user selects
    detail = page.get_by_test_id("pick-detail")
    detail.filter(has_text=f"grasp {pid} (rank {rank}): approach tilted {tilt:.1f} deg").wait_for()
    page.get_by_test_id("replay-outcome").filter(has_text=f"tilted {tilt:.1f} deg").wait_for()
    scene = page.get_by_test_id("replay-scene").get_attribute("id")
    page.wait_for_function(
        "(id) => window['scene_' + id]?.getObjectByName('pick-replay')?.children.length === 5",
        arg=scene,
    )
    # the page's bodies are the trace's kinematics with the gripper turned as simulated
    trace = run.trace(pid)
    replay = SceneReplay(run.path / "scene.xml", run.gripper)
    vertical = replay.model.body_quat.copy()
    track = body_track(replay.model, trace, replay.shapes, run.gripper)
    # the shared model is left as the scene has it: two replays at once never mix tilts
    np.testing.assert_array_equal(replay.model.body_quat, vertical)
    gripper = track.bodies.index("gripper")
    shown = quaternions(page)["gripper"]
    assert tilt_of(shown) == pytest.approx(tilt, abs=0.05)
    np.testing.assert_allclose(
        np.abs(shown @ track.quat_wxyz[0, gripper]), 1.0, atol=1e-5
    )  # the same rotation (q and -q alike)
    start = np.array(bodies(page)["gripper"][0])
    np.testing.assert_allclose(start, track.position_m[0, gripper], atol=PAGE_TOL_M)
    # the slider dragged past its end with the mouse: the last row, the gripper lifted
    # straight up, still tilted
    slider = page.get_by_test_id("replay-time")
    slider.scroll_into_view_if_needed()
    box = slider.bounding_box()
    y = box["y"] + box["height"] / 2
    page.mouse.move(box["x"] + box["width"] / 2, y)
    page.mouse.down()
    for i in range(1, 11):
        page.mouse.move(box["x"] + box["width"] * (0.5 + 0.06 * i), y)
    page.mouse.up()
    t = trace["t_s"]
    page.get_by_test_id("replay-clock").filter(has_text=f"t = {t[-1]:.3f} s").wait_for()
    lifted = trace["lift_m"][-1] - trace["lift_m"][0]
    end = np.array(bodies(page)["gripper"][0])
    np.testing.assert_allclose(end - start, [0, 0, lifted], atol=PAGE_TOL_M)
    assert tilt_of(quaternions(page)["gripper"]) == pytest.approx(tilt, abs=0.05)
    test_gui.shot(page, "replay_3d_tilted")

    # a grasp the run did not trace: simulated now as the same pose, the gripper tilted
    rank = next(r for r, p in enumerate(ranked, 1) if p not in traced)
    pid = ranked[rank - 1]
    rows.nth(rank - 1).locator(".q-checkbox").click()
    detail.filter(has_text="simulated now with the run's settings").wait_for(
        timeout=test_gui.TIMEOUT_MS
    )
    assert f"score {run.row(pid)['score']:.3f}" in detail.inner_text()
    page.get_by_test_id("replay-outcome").filter(
        has_text=f"tilted {run.row(pid)['tilt_deg']:.1f} deg"
    ).wait_for()
    page.wait_for_function(
        """([id, tilt]) => {
            const g = window['scene_' + id]?.getObjectByName('pick-replay')
                ?.getObjectByName('gripper');
            if (!g) return false;
            const up = new g.up.constructor(0, 0, 1).applyQuaternion(g.quaternion);
            return Math.abs(Math.acos(Math.min(1, up.z)) * 180 / Math.PI - tilt) < 0.05;
        }""",
        arg=[scene, run.row(pid)["tilt_deg"]],
    )

    # the grasps as a grasp file: exported, offered for download, read back
    page.get_by_test_id("export-grasps").click()
    assert test_gui.wait_job(page, f"export {run.path.name} (graspgen)").startswith("complete")
    button = page.get_by_test_id("download-grasps_graspgen.json")
    with page.expect_download() as info:
        button.click()
    from mjx_pick.outputs.exchange import read_labels

    saved = info.value.path()
    labels = read_labels(Path(saved).rename(Path(saved).with_suffix(".json")))
    assert len(labels.transforms) == 3
    # the report: its page and the robot's file (whole poses) offered, no template, and why
    test_gui.number(page, "n best and n worst", 1)
    page.get_by_test_id("export").click()
    assert test_gui.wait_job(page, f"report {run.path.name}").startswith("complete")
    page.get_by_test_id("download-report.html").wait_for()
    page.get_by_test_id("downloads-note").filter(has_text="No printed template").wait_for()
    assert not (run.path / "template_a4.pdf").exists()
    assert not page.get_by_test_id("download-template_a4.pdf").count()
    page.get_by_test_id("download-robot_picks.json").wait_for()
    robot = json.loads((run.path / "robot_picks.json").read_text())
    for entry in robot["picks"]:  # each grasp's tilt kept: the angle of its z from the table's z
        z = np.asarray(entry["gripper_pose"]["matrix"])[2, 2]
        assert np.degrees(np.arccos(z)) == pytest.approx(
            run.row(entry["pick_id"])["tilt_deg"], abs=0.05
        )


def ranked_ids(run: Run) -> list[int]:
    """The run's pick ids best score first, as the table ranks them."""
    score = np.asarray(run.table["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, -score), kind="stable")
    return [int(run.table["pick_id"][int(i)].as_py()) for i in order]
