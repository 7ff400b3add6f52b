"""The GUI's second routes, in Chromium: a refused upload, a gripper's name, a folder
outside the work folder -- each refused in the page's words, nothing silently reused.
The harness (server, browser, page) is tests/test_gui.py's."""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import numpy as np
import test_gui
from test_gui import (
    BLOCK,
    TIMEOUT_MS,
    choose,
    click_answered,
    import_shipped,
    number,
    short_procedure,
    shown_field_messages,
    start_short_batch,
    wait_job,
)

from mjx_pick.gui.app import TABS

# test_gui's fixtures: one GUI server for this module, one browser, a page per test
server, browser, page = test_gui.server, test_gui.browser, test_gui.page


def upload_object(page, path) -> None:
    page.get_by_test_id("object-upload").locator("input[type=file]").set_input_files(str(path))


def test_a_refused_upload_is_not_replaced_by_the_one_before(page, tmp_path):
    page.get_by_text("1 Import object model").click()
    upload_object(page, BLOCK)
    page.get_by_text("uploaded block.png").wait_for()
    page.get_by_label("image scale (px per mm)", exact=True).fill("10")
    page.get_by_label("thickness (mm)", exact=True).fill("20")
    page.get_by_label("mass (g)", exact=True).fill("43.2")
    page.get_by_test_id("import").click()
    page.get_by_test_id("object-info").filter(has_text="outline").wait_for(timeout=60_000)
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    upload_object(page, empty)
    page.get_by_test_id("upload-error").filter(has_text="empty.png").wait_for()
    assert "No object imported" in page.get_by_test_id("object-info").inner_text()
    page.get_by_test_id("import").click()  # the earlier file is not taken in its place
    page.get_by_test_id("import-error").filter(has_text="upload an image").wait_for()
    assert "No object imported" in page.get_by_test_id("object-info").inner_text()
    assert "empty.png" in page.get_by_test_id("upload-error").inner_text()  # still said


def test_a_gripper_name_is_any_text_but_never_a_path(page, server, tmp_path):
    from playwright.sync_api import expect

    _, work = server
    import_shipped(page)
    page.get_by_text("2 Set gripper parameters").click()
    base = (BLOCK.parents[2] / "assets" / "grippers" / "robotiq-2f85.toml").read_text()
    evil = tmp_path / "evil.toml"
    evil.write_text(base.replace('name = "robotiq-2f85"', 'name = "../../etc/g"'))
    upload = page.get_by_test_id("gripper-upload").locator("input[type=file]")
    upload.set_input_files(str(evil))
    page.get_by_test_id("toml-error").filter(has_text="is not allowed").wait_for()
    smile = tmp_path / "smile.toml"
    smile.write_text(base.replace('name = "robotiq-2f85"', 'name = "grip 😀"'), "utf-8")
    upload.set_input_files(str(smile))
    expect(page.get_by_test_id("toml-error")).to_have_text("")  # taken: the refusal is gone
    page.get_by_label("lift height (mm)", exact=True).fill("5")
    page.get_by_label("hold (s)", exact=True).fill("0.05")
    page.get_by_text("3 Generate input data").click()
    page.get_by_label("pick-points", exact=True).fill("2")
    page.get_by_label("run folder name").fill("smile")
    page.get_by_test_id("start-batch").click()
    status = wait_job(page, "evaluate smile")
    assert status.startswith("complete"), status
    config = json.loads((work / "smile" / "config.json").read_text(encoding="utf-8"))
    assert config["gripper"]["name"] == "grip 😀"
    assert not (work.parent / "etc").exists()


def test_tab_4_opens_only_folders_inside_the_work_folder(page, tmp_path):
    page.get_by_text("4 Analyze").first.click()
    for outside in ("/etc", "../..", str(tmp_path)):
        page.get_by_test_id("run-dir").fill(outside)
        page.get_by_test_id("open-run").click()
        error = page.get_by_test_id("analyze-error")
        # this folder's refusal, not the one before it still shown
        error.filter(has_text=f"{outside}: only run folders inside the work folder").wait_for()


def test_a_sweep_takes_its_parameters_own_range_and_says_its_size(page):
    from playwright.sync_api import expect

    import_shipped(page)
    page.get_by_text("Parameter sweep").click()
    select = page.get_by_label("parameter", exact=True)
    # parameters in words: the form's labels, or a section and meaning -- no keys
    expect(select).to_have_value("pad friction")
    select.fill("finger")
    width = page.get_by_role("option", name="finger width (mm)", exact=True)
    width.wait_for()
    options = page.get_by_role("option").all_inner_texts()
    assert "gripper: mass of one finger (g)" in options, options
    assert not [o for o in options if "_" in o or "gripper." in o], options
    width.click()
    # the finger's own range (around its 22 mm), not the friction's 0.4-1.0
    expect(page.get_by_label("start", exact=True)).to_have_value("11")
    expect(page.get_by_label("end", exact=True)).to_have_value("33")
    count = page.get_by_test_id("sweep-count")
    box = page.get_by_label("simulations per value", exact=True)
    box.fill("1000000")
    box.blur()
    expect(count).to_have_text("5 values x 1,000,000 pick-points = 5,000,000 simulations")
    box.fill("3000000")
    box.blur()
    page.get_by_label("run folder name").last.fill("huge")
    page.get_by_test_id("start-sweep").click()
    page.locator(".q-field__messages").filter(has_text="at most 10,000,000").wait_for()
    assert not page.get_by_test_id("job-title").is_visible()


def test_compare_says_when_grippers_ran_at_different_forces(page, server):
    import_shipped(page)
    page.get_by_text("2 Set gripper parameters").click()
    page.get_by_label("lift height (mm)", exact=True).fill("5")
    page.get_by_label("hold (s)", exact=True).fill("0.05")  # F_d stays 50 N: above the RG2's
    page.get_by_text("Studies", exact=True).click()
    page.get_by_label("pick-points", exact=True).filter(visible=True).first.fill("2")
    page.get_by_label("run folder name").filter(visible=True).first.fill("forces")
    page.get_by_test_id("start-compare").click()
    status = wait_job(page, "compare forces")
    assert re.match(r"complete, (\d+)/\1 simulations", status), status  # a count
    # the table's headings in words with their units, no key ("grip force n" once)
    heads = page.get_by_test_id("compare-table").locator("th").all_inner_texts()
    assert "grip force (N)" in heads and not [h for h in heads if "_" in h], heads
    note = page.get_by_test_id("compare-note")
    note.filter(has_text="different grip forces").wait_for()
    assert "onrobot-rg2 at 40 N" in note.inner_text()
    assert "robotiq-2f85 at 50 N" in note.inner_text()


def test_a_runs_settings_load_from_its_folder_into_a_fresh_page(page, server, browser):
    from playwright.sync_api import expect

    url, _ = server
    import_shipped(page)
    page.get_by_text("2 Set gripper parameters").click()
    page.get_by_label("lift height (mm)", exact=True).fill("6")
    page.get_by_label("hold (s)", exact=True).fill("0.05")
    page.get_by_label("pad friction", exact=True).fill("0.7")
    page.get_by_text("3 Generate input data").click()
    page.get_by_label("pick-points", exact=True).fill("3")
    page.get_by_label("seed", exact=True).fill("5")
    page.get_by_label("run folder name").fill("remembered")
    page.get_by_test_id("start-batch").click()
    assert wait_job(page, "evaluate remembered").startswith("complete")
    # another browser: a page that knows nothing of the run until it reads its folder
    fresh = browser.new_context().new_page()
    fresh.goto(url)
    import_shipped(fresh)
    fresh.get_by_text("3 Generate input data").click()
    fresh.get_by_label("run folder name").fill("remembered")
    fresh.get_by_test_id("load-run").click()
    expect(fresh.get_by_label("pick-points", exact=True)).to_have_value("3")
    expect(fresh.get_by_label("seed", exact=True)).to_have_value("5")
    fresh.get_by_text("2 Set gripper parameters").click()
    expect(fresh.get_by_label("lift height (mm)", exact=True)).to_have_value("6")
    expect(fresh.get_by_label("pad friction", exact=True)).to_have_value("0.7")
    fresh.context.close()


def test_a_second_browser_tab_follows_a_run_to_its_end(page, server, browser):
    """Tab 4 of another browser tab, asked for a folder still being written, follows
    that run and opens it when it completes: never 'still running' after its end."""
    from playwright.sync_api import expect

    url, _ = server
    start_short_batch(page, url, "followed", 40, chunk=2)
    page.get_by_test_id("job-title").filter(has_text="evaluate followed").wait_for()
    other = browser.new_context(viewport={"width": 1500, "height": 1000}).new_page()
    try:
        other.goto(url)
        other.get_by_text("4 Analyze results").click()
        other.get_by_test_id("run-dir").fill("followed")
        other.get_by_test_id("open-run").click()
        error = other.get_by_test_id("analyze-error")
        error.filter(has_text="followed is still running").wait_for()
        assert wait_job(page, "evaluate followed").startswith("complete")
        rows = other.get_by_test_id("picks-table").locator("tbody tr")
        expect(rows.first).to_be_visible(timeout=TIMEOUT_MS)
        expect(error).to_have_text("")
        assert "pick-points, success rate" in other.get_by_test_id("run-info").inner_text()
    finally:
        other.context.close()


# the page's fields and labels, tab by tab, at a laptop's width
CLIPPED = """() => [...document.querySelectorAll(
    '.q-field__label, .q-tab__label, .q-btn__content, .q-checkbox__label, th, '
    + '.q-select .q-field__native > span, input.q-field__native:not(.q-select input)')]
  .filter(e => e.getClientRects().length && e.scrollWidth > e.clientWidth + 1)
  .map(e => (e.innerText || e.value || e.getAttribute('aria-label') || '').slice(0, 60))"""


def test_no_label_or_value_is_clipped(browser, server):
    url, _ = server
    context = browser.new_context(viewport={"width": 1280, "height": 900})
    try:
        page = context.new_page()
        page.goto(url)
        page.get_by_text("1 Import object model").wait_for()
        clipped = {}
        for _, label in TABS:
            page.get_by_text(label, exact=True).first.click()
            if label == "Studies":  # every study's form open
                for study in ("Robustness of the best", "Calibrate contact parameters"):
                    page.get_by_text(study).click()
            page.wait_for_timeout(500)  # the tab's panel drawn
            found = page.evaluate(CLIPPED)
            if found:
                clipped[label] = found
        assert not clipped
    finally:
        context.close()


def test_an_object_the_libraries_cannot_build_is_refused_in_the_users_words(page):
    """A thickness no mesh can be extruded from and a scale that makes the part a
    speck: the field's own rule and the tab's words, no library's text, no path of
    the software's files, no CLI flag."""
    page.get_by_text("1 Import object model").click()
    number(page, "thickness (mm)", 0.000001)
    page.get_by_test_id("import").click()
    field = page.locator("label.q-field").filter(has=page.get_by_label("thickness (mm)"))
    field.locator(".q-field__messages").filter(has_text="a number from 0.1 to 1,000").wait_for()
    number(page, "thickness (mm)", 20)
    number(page, "image scale (px per mm)", 1000)  # the 40 mm block becomes 0.4 mm
    page.get_by_test_id("import").click()
    error = page.get_by_test_id("import-error")
    error.filter(has_text="block.png").wait_for()
    text = page.locator("body").inner_text()
    assert "check image scale (px per mm)" in error.inner_text()
    for raw in ("Height must be nonzero", str(BLOCK.parent), "--px-per-mm", "px_per_mm"):
        assert raw not in text


def test_a_long_pick_point_search_shows_its_progress_and_stops(page):
    """A minimum coverage few poses meet (0.97): Generate says how far its search is
    and why candidates are rejected, and Stop ends it with what it found; one that a
    few meet (0.71) is warned of by its reason, never as a part wider than the stroke."""
    import_shipped(page)
    page.get_by_text("2 Set gripper parameters").click()
    number(page, "minimum coverage", 0.97)
    page.get_by_text("3 Generate input data").click()
    number(page, "pick-points", 200)
    page.get_by_test_id("generate").click()
    line = page.get_by_test_id("picks-search")
    line.filter(has_text="of at most 1,000,000 checked").wait_for()
    assert "the object fills too little of the region between the pads" in line.inner_text()
    page.get_by_test_id("picks-search-stop").click()
    line.filter(has_text="stopped after").wait_for()
    assert "feasible (rejected:" in line.inner_text()
    assert not page.get_by_test_id("picks-map").is_visible()
    assert not page.get_by_test_id("picks-search-stop").is_visible()
    # 0.71: a few poses meet it; the warning names the coverage, not the part's width
    number(page, "pick-points", 3)  # here, not in a tab still sliding in
    page.get_by_text("2 Set gripper parameters").click()
    number(page, "minimum coverage", 0.71)
    page.get_by_text("3 Generate input data").click()
    page.get_by_test_id("generate").click()
    page.get_by_test_id("picks-info").filter(has_text="3 feasible pick-points").wait_for()
    warned = page.get_by_test_id("picks-warning").inner_text()
    assert "the object fills too little of the region between the pads" in warned, warned
    assert "lower the minimum coverage, now 0.71" in warned
    assert "wider than the stroke" not in warned and "larger stroke" not in warned


def field_message(page, label: str):
    """The messages line Quasar shows under the (visible) field labelled label."""
    field = page.locator("label.q-field").filter(visible=True)
    return field.filter(has=page.get_by_label(label, exact=True)).locator(".q-field__messages")


def test_tab_3s_traces_and_chunk_size_keep_the_number_rule(page):
    """Traced best and worst -1 or 2.5, a chunk of 0, -3 or 2.5 pick-points: refused
    under the field in its words, the value left as typed, no run -- never changed to
    0, 1 or 2 and started. An empty chunk size is the page's own choice."""
    from playwright.sync_api import expect

    import_shipped(page)
    page.get_by_text("3 Generate input data").click()
    number(page, "pick-points", 3)
    page.get_by_label("run folder name").fill("numbers")
    for label, value, rule in (
        ("traced best and worst (force plots)", "-1", "a whole number from 0 to 10,000"),
        ("traced best and worst (force plots)", "2.5", "a whole number from 0 to 10,000"),
        ("pick-points per saved chunk", "0", "a whole number from 1 to 100,000,000, or empty"),
        ("pick-points per saved chunk", "-3", "a whole number from 1 to 100,000,000, or empty"),
        ("pick-points per saved chunk", "2.5", "a whole number from 1 to 100,000,000, or empty"),
    ):
        number(page, label, value)
        page.get_by_test_id("start-batch").click()
        expect(field_message(page, label)).to_have_text(rule, timeout=10_000)
        expect(page.get_by_label(label, exact=True)).to_have_value(value)
        assert not page.get_by_test_id("job-title").is_visible()
        number(page, label, 1)  # the message goes with the next check
    page.get_by_label("pick-points per saved chunk", exact=True).fill("")
    page.get_by_test_id("start-batch").click()
    status = wait_job(page, "evaluate numbers")
    assert status.startswith("complete, 3/3"), status


def small_run(out, block, n: int = 2) -> None:
    """An evaluate folder of n pick-points of the block (the library, no page), its
    best and worst traced."""
    import mjx_pick as mp
    from mjx_pick.core.procedure import GraspConfig

    grasp = GraspConfig(close_timeout_s=1.0, lift_height_mm=5.0, hold_s=0.05)
    gripper = mp.load_gripper("robotiq-2f85")
    mp.evaluate(block, gripper, n=n, grasp=grasp, backend="mujoco", out=out, n_traces=1)


def test_no_file_is_read_listed_or_served_through_a_link_out_of_the_work_folder(
    page, server, tmp_path, block
):
    """Links in the work folder: a report file that leads to /etc/passwd is not served
    (the refusal names it), a run folder holding a link out is not opened, a link to a
    run folder outside is neither listed nor opened -- each said by its name."""
    from playwright.sync_api import expect

    _, work = server
    secret = tmp_path / "secret.txt"
    secret.write_text("not for the browser\n")
    run = work / "linked-files"
    small_run(run, block)
    (run / "report.html").write_text("<html>the run's report</html>")
    outside = tmp_path / "outside-run"
    small_run(outside, block)
    (work / "linked-run").symlink_to(outside, target_is_directory=True)

    downloads = []
    page.on("download", lambda d: downloads.append(d.suggested_filename))
    page.get_by_text("4 Analyze results").click()
    page.get_by_test_id("run-dir").fill("linked-files")
    page.get_by_test_id("open-run").click()
    report = page.get_by_test_id("download-report.html")
    report.wait_for()
    with page.expect_download() as got:  # a file inside: served, its own bytes
        report.click()
    assert got.value.suggested_filename == "report.html"
    assert Path(got.value.path()).read_bytes() == b"<html>the run's report</html>"
    downloads.clear()
    # made after the run was opened: the file is checked when it is asked for
    (run / "report.html").unlink()
    (run / "report.html").symlink_to("/etc/passwd")
    report.click()
    error = page.get_by_test_id("analyze-error")
    error.filter(has_text="leads outside the work folder").wait_for(timeout=10_000)
    assert error.inner_text().startswith("linked-files/report.html: a link that leads outside")
    assert "to /etc/passwd" in error.inner_text()
    page.wait_for_timeout(1000)
    assert not downloads

    # a run folder that holds a link out is not opened: its tables and scene are not read
    (run / "report.html").unlink()
    (run / "summary.json").rename(run / "summary-real.json")
    (run / "summary.json").symlink_to(secret)
    page.get_by_test_id("open-run").click()
    error.filter(has_text="linked-files/summary.json: a link that leads outside").wait_for()
    assert "not for the browser" not in page.locator("body").inner_text()

    # a run folder outside, reached through a link: not listed, not opened
    page.get_by_test_id("run-dir").fill("linked-run")
    page.get_by_test_id("open-run").click()
    error.filter(has_text="linked-run: only run folders inside the work folder").wait_for()
    page.get_by_label("runs in the work folder", exact=True).click()
    options = page.get_by_role("option").all_inner_texts()
    assert not [o for o in options if "linked-run" in o], options
    page.keyboard.press("Escape")
    expect(page.get_by_test_id("runs-unlisted")).to_contain_text(
        "linked-run: a link that leads outside the work folder"
    )


def test_a_file_the_browser_refuses_replaces_the_upload_before_it(page, tmp_path):
    """An SVG or a 60 MB mesh, refused by the browser itself (the upload's accept and
    size): said by its name and why, it stays said, and Import takes no earlier upload
    in its place; so for an outcomes CSV before a calibration."""
    from playwright.sync_api import expect

    page.get_by_text("1 Import object model").click()
    upload_object(page, BLOCK)
    page.get_by_text("uploaded block.png").wait_for()
    page.get_by_test_id("import").click()
    page.get_by_test_id("object-info").filter(has_text="outline").wait_for(timeout=60_000)
    refused = page.get_by_test_id("upload-error")
    svg = tmp_path / "drawing.svg"
    svg.write_text('<svg xmlns="http://www.w3.org/2000/svg"/>')
    big = tmp_path / "big.stl"
    with big.open("wb") as fh:
        fh.truncate(60 * 2**20)
    for path, why in (
        (svg, "drawing.svg: not an image (.png, "),
        (big, "big.stl: 60 MB is too large (at most 50 MB)"),
    ):
        upload_object(page, path)
        expect(refused).to_contain_text(why, timeout=30_000)
        expect(page.get_by_test_id("object-info")).to_have_text("No object imported.")
        page.get_by_test_id("import").click()
        page.get_by_test_id("import-error").filter(has_text="upload an image").wait_for()
        expect(refused).to_contain_text(why)  # still said
        expect(page.get_by_test_id("object-info")).to_have_text("No object imported.")

    import_shipped(page)  # a shipped object: another choice, the refusal is history
    expect(refused).to_have_text("")
    page.get_by_text("Studies", exact=True).click()
    page.get_by_text("Calibrate contact parameters").click()
    outcomes = BLOCK.parents[1] / "outcomes" / "block_1kg_rg2.csv"
    csv_upload = page.get_by_test_id("outcomes-upload").locator("input[type=file]")
    csv_upload.set_input_files(str(outcomes))
    page.get_by_test_id("calibrate-info").filter(has_text="24 tested pick-points").wait_for()
    sheet = tmp_path / "outcomes.xlsx"
    sheet.write_bytes(b"PK\x03\x04 a spreadsheet")
    csv_upload.set_input_files(str(sheet))
    csv_refused = page.get_by_test_id("outcomes-error")
    expect(csv_refused).to_have_text("outcomes.xlsx: not a .csv file", timeout=30_000)
    expect(page.get_by_test_id("calibrate-info")).to_have_text("")
    page.get_by_label("run folder name").filter(visible=True).last.fill("no-outcomes")
    # a click the browser sent no event for, under load, is clicked again (click_answered)
    error = page.get_by_test_id("calibrate-error").filter(has_text="upload an outcomes CSV")
    click_answered(page, "start-calibrate", error, "refused for want of outcomes")
    error.wait_for()
    expect(csv_refused).to_have_text("outcomes.xlsx: not a .csv file")
    assert not page.get_by_test_id("job-title").is_visible()


def test_a_reload_shows_a_stopped_run_as_its_folder_records_it_and_start_resumes(page, server):
    """A run of 40 pick-points, seed 7, 2 traced, chunks of 2, cancelled; each reload
    shows tab 3 as the run's folder records it -- not the page's defaults -- and its
    time as it ran, not growing; a change is refused in the page's words; Start then
    continues it to its end."""
    from playwright.sync_api import expect

    url, work = server
    import_shipped(page)
    short_procedure(page)
    page.get_by_text("3 Generate input data").click()
    recorded = {
        "pick-points": "40",
        "seed": "7",
        "traced best and worst (force plots)": "2",
        "pick-points per saved chunk": "2",
    }
    for label, value in recorded.items():
        number(page, label, value)
    page.get_by_label("run folder name").fill("reloaded")
    page.get_by_test_id("start-batch").click()
    status = page.get_by_test_id("job-status")
    status.filter(has_text=re.compile(r"^running, ([2-9]|[1-3]\d)/40 pick-points")).wait_for(
        timeout=TIMEOUT_MS
    )
    page.get_by_role("button", name="Cancel").click()
    ended = wait_job(page, "evaluate reloaded")
    assert ended.startswith("cancelled"), ended
    took = re.search(r", (\d+) s,", ended).group(1)

    for _ in range(2):  # each reload: the same record, the same time
        page.wait_for_timeout(2500)
        page.reload()
        page.get_by_test_id("job-title").filter(has_text="evaluate reloaded").wait_for()
        expect(status).to_contain_text(f", {took} s,")
        page.get_by_text("3 Generate input data").click()
        for label, value in recorded.items():
            expect(page.get_by_label(label, exact=True)).to_have_value(value)
        expect(page.get_by_label("run folder name")).to_have_value("reloaded")
        resume = page.get_by_role("checkbox", name="resume an interrupted run of this folder")
        expect(resume).to_be_checked()

    # another seed: the CLI's refusal in the page's words -- no key, no flag
    number(page, "seed", 8)
    page.get_by_test_id("start-batch").click()
    status.filter(has_text=re.compile(r"^failed")).wait_for(timeout=TIMEOUT_MS)
    refused = status.inner_text()
    assert "changed: seed: 7 -> 8" in refused, refused
    assert not re.search(r"--[a-z]|\bn:|mjx-pick|details", refused), refused
    assert "'Load this run folder's settings' in tab 3" in refused, refused
    page.get_by_test_id("load-run").click()
    expect(page.get_by_label("seed", exact=True)).to_have_value("7")
    page.get_by_test_id("start-batch").click()
    page.get_by_test_id("job-status").filter(has_text="running").wait_for()
    done = wait_job(page, "evaluate reloaded")
    assert done.startswith("complete, 40/40"), done
    assert (work / "reloaded" / "results.parquet").is_file()


def two_bodies_obj(path) -> None:
    """An OBJ of two disjoint 20 mm cubes (a mesh of several bodies)."""
    import trimesh

    a = trimesh.creation.box((20, 20, 20))
    b = trimesh.creation.box((20, 20, 20))
    b.apply_translation((60, 0, 0))
    trimesh.util.concatenate([a, b]).export(path)


def test_messages_speak_the_pages_words_not_the_programs(page, server, block, tmp_path):
    """Refusals that named a flag the page has not (--largest-body), a key
    (grasp.grip_force_n, mass_g), a backend this machine cannot run, an outcome's label
    (no_contact): each in the page's words, and the page has the control it names."""
    from playwright.sync_api import expect

    from mjx_pick.gui import forms

    program = re.compile(r"--[a-z]|\b[a-z]+_[a-z_]+\b|details|pip install")
    # a mesh of two bodies: the refusal names the page's box, which takes it
    mesh = tmp_path / "two_cubes.obj"
    two_bodies_obj(mesh)
    upload_object(page, mesh)
    page.get_by_text("uploaded two_cubes.obj").wait_for()
    page.get_by_test_id("import").click()
    error = page.get_by_test_id("import-error")
    error.filter(has_text="disconnected bodies").wait_for(timeout=60_000)
    assert "'largest body only' ticked (tab 1)" in error.inner_text(), error.inner_text()
    assert not program.search(error.inner_text().replace("two_cubes.obj", "")), error.inner_text()
    page.get_by_test_id("largest-body").click()
    page.get_by_test_id("import").click()
    page.get_by_test_id("object-info").filter(has_text="outline").wait_for(timeout=60_000)

    # a setting out of the gripper's range: its label, not its key, no details line
    page.get_by_text("2 Set gripper parameters").click()
    number(page, "grip force F_d (N)", 300)
    page.get_by_test_id("test-pick").click()
    said = field_message(page, "grip force F_d (N)")
    said.filter(has_text="out of range").wait_for()
    assert not program.search(said.inner_text()), said.inner_text()
    # only backends this machine runs are offered; the others said with why
    page.get_by_label("backend", exact=True).click()
    offered = page.get_by_role("option").all_inner_texts()
    page.keyboard.press("Escape")
    assert offered == forms.backend_choices(), offered
    for name, why in forms.backend_problems().items():
        assert name not in offered
        expect(page.get_by_test_id("backend-note")).to_contain_text(f"{name} ({why})")

    # tab 4: an untraced pick of a run of another object (mass); outcomes in words
    small_run(server[1] / "other-mass", block, n=3)
    import_shipped(page)  # the block, 43.2 g: the run's is 43.2 g too; now another mass
    number(page, "mass (g)", 1000)
    page.get_by_test_id("import").click()
    page.get_by_test_id("object-info").filter(has_text="mass 1000.0 g").wait_for()
    page.get_by_text("4 Analyze results").click()
    page.get_by_test_id("run-dir").fill("other-mass")
    page.get_by_test_id("open-run").click()
    rows = page.get_by_test_id("picks-table").locator("tbody tr")
    expect(rows).to_have_count(3)
    outcomes = [r.locator("td").nth(8).inner_text() for r in rows.all()]
    assert outcomes and not [o for o in outcomes if "_" in o], outcomes
    untraced = rows.filter(has_not_text="yes").first
    untraced.locator(".q-checkbox").click()
    detail = page.get_by_test_id("pick-detail")
    detail.filter(has_text="cannot be simulated here").wait_for()
    text = detail.inner_text()
    assert "they differ in mass (g)" in text, text
    assert "import the object it was made with in tab 1" in text, text
    assert not re.search(r"--[a-z]|mass_g|outline_wkt|height_mm", text), text


def test_a_search_that_finds_nothing_says_why_truly_and_ends_its_line(page):
    """Minimum coverage 0.99 on the 40 mm block, 85 mm stroke: no pose is feasible.
    The refusal says why in true words (the fingers cannot reach around an off-centre
    part -- the part is not wider than the stroke), and the search's line says it ended
    -- not "0 of 50 feasible so far" as if it still ran."""
    from playwright.sync_api import expect

    import_shipped(page)
    page.get_by_text("2 Set gripper parameters").click()
    number(page, "minimum coverage", 0.99)
    page.get_by_text("3 Generate input data").click()
    number(page, "pick-points", 50)
    page.get_by_test_id("generate").click()
    error = page.get_by_test_id("generate-error")
    error.filter(has_text="no feasible pick-point").wait_for(timeout=TIMEOUT_MS)
    said = error.inner_text()
    assert "the object fills too little of the region between the pads" in said, said
    assert "cannot reach around the part at that offset" in said, said
    assert "wider than the stroke" not in said, said
    line = page.get_by_test_id("picks-search")
    expect(line).to_contain_text("the search ended after 1,003,520 (all it draws, at most")
    assert "0 of 50 feasible" in line.inner_text()
    assert "so far" not in line.inner_text()
    expect(page.get_by_test_id("picks-search-stop")).to_be_hidden()


def test_two_browser_tabs_starting_one_run_name_at_once_start_it_once(page, server, browser):
    """Two browser tabs click Start with the same run name at the same moment (each then
    counts its pick-points for the progress bar): one runs, the other is refused at
    once in its own words -- never both "running", the second showing the first's
    progress until its process finds the folder locked."""
    from playwright.sync_api import expect

    url, work = server
    other = browser.new_context(viewport={"width": 1500, "height": 1000}).new_page()
    try:
        other.goto(url)
        tabs = (page, other)
        for pg in tabs:
            import_shipped(pg)
            short_procedure(pg, 5, 0.05)
            pg.get_by_text("3 Generate input data").click()
            number(pg, "pick-points", 4)
            pg.get_by_label("run folder name").fill("twin")
        at = 1000 * time.time() + 1500  # one moment for both clicks, in each page's clock
        click = """(t) => setTimeout(
            () => document.querySelector('[data-testid="start-batch"]').click(),
            t - Date.now())"""
        for pg in tabs:
            pg.evaluate(click, at)
        ran, refused = [], []
        deadline = time.monotonic() + TIMEOUT_MS / 1000
        while len(ran) + len(refused) < 2 and time.monotonic() < deadline:
            ran = [pg for pg in tabs if pg.get_by_test_id("job-title").is_visible()]
            refused = [
                pg
                for pg in tabs
                if "is writing this folder now" in pg.get_by_test_id("generate-error").inner_text()
                or "already exists" in " ".join(shown_field_messages(pg))
            ]
            time.sleep(0.2)
        assert len(ran) == 1 and len(refused) == 1 and ran != refused, (ran, refused)
        assert wait_job(ran[0], "evaluate twin").startswith("complete, 4/4")
        expect(refused[0].get_by_test_id("job-title")).to_be_hidden()
        said = refused[0].get_by_test_id("generate-error").inner_text()
        assert not said or "(another browser tab's) is writing this folder now" in said, said
        assert len(list((work / "logs").glob("twin*.log"))) == 1  # one run, one log
    finally:
        other.context.close()


def grasp_rows(path: Path) -> list[dict]:
    """The rows of a CSV of grasp poses (``export --format csv``)."""
    import csv

    with path.open(newline="") as fh:
        return list(csv.DictReader(fh))


def write_grasps(path: Path, rows: list[dict], columns: list[str]) -> Path:
    lines = [",".join(columns)] + [",".join(r[c] for c in columns) for r in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


def upload_grasps(page, path: Path) -> None:
    page.get_by_test_id("grasps-upload").locator("input[type=file]").set_input_files(str(path))


def test_grasps_antipodal_and_from_a_file_run_through_the_cli(page, server, tmp_path):
    """Tab 3's grasp sources, chosen with the mouse: antipodal grasps on the block run
    as ``evaluate --grasps antipodal`` (no map: it draws top-down pick-points); its
    grasps exported as a CSV of poses and uploaded -- a text file, a file in another
    unit and one without its depth refused first, each in the page's words -- run as
    ``evaluate --grasps FILE``: the same grasps, the same labels."""
    import pyarrow.parquet as pq
    from playwright.sync_api import expect

    from mjx_pick.gui.grasp_input import SOURCES
    from mjx_pick.outputs.exchange import export_labels

    _, work = server
    import_shipped(page)
    short_procedure(page, 5, 0.05)
    page.get_by_text("3 Generate input data").click()
    choose(page, "grasps from", SOURCES["antipodal"])
    expect(page.get_by_test_id("generate")).to_be_hidden()  # the map is of pick-points
    page.get_by_test_id("grasp-source-note").filter(has_text="antipodal grasps").wait_for()
    number(page, "grasps", 3)  # the count, named for what it counts
    number(page, "traced best and worst (force plots)", 0)
    page.get_by_label("run folder name").fill("antipodal")
    page.get_by_test_id("start-batch").click()
    status = wait_job(page, "evaluate antipodal")
    assert status.startswith("complete, 3/3"), status
    shown = page.locator("code").filter(has_text="mjx-pick evaluate").first.inner_text()
    assert "--grasps antipodal --n 3" in shown, shown
    drawn = pq.read_table(work / "antipodal" / "results.parquet")
    assert drawn.num_rows == 3 and max(drawn["tilt_deg"].to_pylist()) > 1.0

    written = export_labels(work / "antipodal", "csv", tmp_path / "grasps.csv")
    rows = grasp_rows(written["labels"])
    choose(page, "grasps from", SOURCES["file"])
    expect(page.get_by_label("grasps", exact=True)).to_be_hidden()  # the file's count
    # a file of another kind: said by its name, by the upload's own rule
    notes = tmp_path / "notes.txt"
    notes.write_text("not grasps")
    upload_grasps(page, notes)
    page.get_by_test_id("grasps-file-error").filter(has_text="notes.txt: not a grasp").wait_for()
    # poses in mm read as metres: refused before any work, the distance named
    far = [dict(r) for r in rows]
    for r in far:
        pose = [float(v) for v in r["grasp_pose"].split()]
        for i in (3, 7, 11):
            pose[i] *= 1000.0
        r["grasp_pose"] = " ".join(f"{v:.9g}" for v in pose)
    upload_grasps(page, write_grasps(tmp_path / "in_mm.csv", far, ["grasp_pose", "depth_mm"]))
    page.get_by_test_id("grasps-file-info").filter(has_text="in_mm.csv: 3 grasps").wait_for()
    page.get_by_label("run folder name").fill("from-file")
    page.get_by_test_id("start-batch").click()
    error = page.get_by_test_id("grasps-file-error")
    error.filter(has_text="in_mm.csv: 3 of 3 grasp centres lie more than 200 mm").wait_for()
    assert "unit or frame disagrees" in error.inner_text()
    assert str(work) not in error.inner_text()  # the file by its name, not where it is kept
    # no depth in the file, none given: asked for under its field
    upload_grasps(page, write_grasps(tmp_path / "no_depth.csv", rows, ["grasp_pose"]))
    info = page.get_by_test_id("grasps-file-info")
    info.filter(has_text="3 without a depth: give the grasp depth below").wait_for()
    page.get_by_test_id("start-batch").click()
    message = field_message(page, "grasp depth (mm): base to grasp centre")
    expect(message).to_contain_text("3 of the 3 grasps of no_depth.csv do not say")
    assert not page.get_by_test_id("job-title").filter(has_text="from-file").count()
    # the exported file: every grasp simulated as the antipodal run simulated it
    upload_grasps(page, written["labels"])
    info.filter(has_text="grasps.csv: 3 grasps (each gives its depth)").wait_for()
    page.get_by_test_id("start-batch").click()
    status = wait_job(page, "evaluate from-file")
    assert status.startswith("complete, 3/3"), status
    shown = page.locator("code").filter(has_text="mjx-pick evaluate").first.inner_text()
    assert "--grasps" in shown and "grasps.csv" in shown and "--n " not in shown, shown
    again = pq.read_table(work / "from-file" / "results.parquet")
    assert again["pick_id"].to_pylist() == drawn["pick_id"].to_pylist()
    assert again["success"].to_pylist() == drawn["success"].to_pylist()
    np.testing.assert_allclose(again["tilt_deg"], drawn["tilt_deg"], atol=1e-6)
    # a run's grasps come back with its settings: the antipodal count, then the file
    page.get_by_label("run folder name").fill("antipodal")
    page.get_by_test_id("load-run").click()
    expect(page.get_by_label("grasps from", exact=True)).to_have_value(SOURCES["antipodal"])
    expect(page.get_by_label("grasps", exact=True)).to_have_value("3")
    page.get_by_label("run folder name").fill("from-file")
    page.get_by_test_id("load-run").click()
    expect(page.get_by_label("grasps from", exact=True)).to_have_value(SOURCES["file"])
    info.filter(has_text="grasps.csv: the run's grasp file").wait_for()


def test_a_long_run_is_asked_about_before_it_starts(page, server):
    """A run estimated longer than a few minutes on this machine (studies.duration, the
    CLI's estimate) is said in a dialog before anything starts: 'Not now' starts
    nothing and leaves its name free; 'Start it' starts it with --yes (cancelled here)."""
    from playwright.sync_api import expect

    _, work = server
    import_shipped(page)
    page.get_by_text("3 Generate input data").click()
    number(page, "pick-points", 1_000_000)  # hours on any machine of a few cores
    page.get_by_label("run folder name").fill("long")
    page.get_by_test_id("start-batch").click()
    question = page.get_by_test_id("long-run-question")
    question.filter(has_text="This evaluate would take about").wait_for()
    assert "1,000,000 simulations" in question.inner_text()
    assert "--yes" not in question.inner_text()  # the page's words: start it, or smaller
    test_gui.shot(page, "long_run_question")
    page.get_by_test_id("long-run-no").click()
    page.get_by_test_id("generate-error").filter(has_text="not started: this evaluate").wait_for()
    expect(page.get_by_test_id("job-title")).to_be_hidden()
    assert not (work / "long").exists() and not (work / "logs" / "long.log").exists()
    page.get_by_test_id("start-batch").click()
    question.filter(has_text="This evaluate would take about").wait_for()
    page.get_by_test_id("long-run-yes").click()
    page.get_by_test_id("job-title").filter(has_text="evaluate long").wait_for()
    shown = page.locator("code").filter(has_text="mjx-pick evaluate").first.inner_text()
    assert shown.rstrip().endswith("--yes"), shown
    page.get_by_text("Cancel", exact=True).click()
    status = wait_job(page, "evaluate long")
    assert status.startswith("cancelled"), status


def trials_zip(path: Path, rows: list[tuple[float, str, str]], extra: dict | None = None) -> Path:
    """A zip of a TRIALS.csv and its mesh, a 30 mm cube (3 g, abb-yumi-smart, resting
    on a face): rows (grasp centre's x offset in mm, success, trial id) of vertical grasps
    through the cube's centre; extra: {member name: bytes} added."""
    import zipfile

    import trimesh

    grasp = np.diag([1.0, -1.0, -1.0, 1.0])  # E's axes: approach +z (down), closing along x
    lines = ["object,mass_g,gripper,object_pose,grasp_pose,depth_mm,success,trial"]
    for x_mm, success, trial in rows:
        pose = grasp.copy()
        pose[0, 3] = x_mm * 1e-3
        cells = " ".join(f"{v:g}" for v in pose.ravel())
        lines.append(f"cube.obj,3,abb-yumi-smart,,{cells},0,{success},{trial}")
    cube = trimesh.creation.box((0.03, 0.03, 0.03)).export(file_type="obj")
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("cube_trials/TRIALS.csv", "\n".join(lines) + "\n")
        z.writestr("cube_trials/cube.obj", cube)
        for name, data in (extra or {}).items():
            z.writestr(name, data)
    return path


def test_validate_on_uploaded_trials_shows_its_figures(page, server, tmp_path):
    """Physical trials in the Studies tab: a zip whose member would land outside its
    folder refused before anything is written, a CSV naming a mesh outside the work
    folder refused; then a zip of a TRIALS.csv and its cube (three trials of one grasp
    through the cube, one grasp beside it) validated through the CLI child, and
    validation.json's figures shown: the four with their intervals, the confusion
    matrix, per object, the checks' rejection."""
    import json

    from playwright.sync_api import expect

    _, work = server
    page.get_by_text("Studies", exact=True).click()
    page.get_by_text("Validate against physical trials").click()
    upload = page.get_by_test_id("trials-upload").locator("input[type=file]")
    error = page.get_by_test_id("trials-error")
    rows = [(0.0, "1", "a0"), (0.0, "1", "a1"), (0.0, "0", "a2"), (60.0, "0", "b0")]
    upload.set_input_files(str(trials_zip(tmp_path / "evil.zip", rows, {"../evil.txt": b"x"})))
    error.filter(has_text="evil.zip: '../evil.txt' would be written outside").wait_for()
    assert not (work / "inputs" / "trials").exists()  # nothing unpacked
    # a TRIALS.csv in the work folder that names a mesh outside it: never read
    outside = tmp_path / "elsewhere"
    outside.mkdir()
    (outside / "far.obj").write_text("v 0 0 0\n")
    mine = work / "mine"
    mine.mkdir()
    pose = " ".join(f"{v:g}" for v in np.diag([1.0, -1.0, -1.0, 1.0]).ravel())
    text = "object,mass_g,gripper,grasp_pose,success,trial\n"
    text += f"{outside / 'far.obj'},3,abb-yumi-smart,{pose},1,t\n"
    (mine / "TRIALS.csv").write_text(text)
    page.get_by_label("or a TRIALS.csv in the work folder").fill("mine/TRIALS.csv")
    page.get_by_test_id("trials-use").click()
    error.filter(has_text="its mesh far.obj lies outside the work folder").wait_for()

    upload.set_input_files(str(trials_zip(tmp_path / "cube.zip", rows)))
    info = page.get_by_test_id("trials-info")
    info.filter(has_text="cube.zip: TRIALS.csv: 4 trials of 2 grasps on cube.obj").wait_for()
    expect(error).to_have_text("")
    page.get_by_label("run folder name").filter(visible=True).last.fill("validated")
    page.get_by_test_id("start-validate").click()
    status = wait_job(page, "validate validated")
    assert status.startswith("complete"), status
    report = json.loads((work / "validated" / "validation.json").read_text())
    c = report["confusion"]
    assert c["tp"] + c["fp"] + c["fn"] + c["tn"] == 4
    assert report["checks"]["rejected_trials"] == 1  # the grasp beside the cube
    figures = page.get_by_test_id("validate-figures").locator("tbody tr")
    expect(figures).to_have_count(4)
    f1 = report["f1"]
    expect(figures.nth(3)).to_contain_text(f"{f1['value']:.3f}")
    lo, hi = f1["ci95"]
    expect(figures.nth(3)).to_contain_text(f"{lo:.3f}-{hi:.3f}")
    confusion = page.get_by_test_id("validate-confusion").locator("tbody tr")
    assert confusion.nth(0).inner_text().split()[-2:] == [str(c["tp"]), str(c["fn"])]
    assert confusion.nth(1).inner_text().split()[-2:] == [str(c["fp"]), str(c["tn"])]
    expect(page.get_by_test_id("validate-objects").locator("tbody tr")).to_have_count(1)
    checks = page.get_by_test_id("validate-checks")
    expect(checks).to_contain_text("The checks rejected 1 trial before simulating it")
    expect(checks).to_contain_text("1: nothing lies between the pads (0 held on the robot)")
    test_gui.shot(page, "validate")


def test_compare_and_sweep_draw_antipodal_grasps(page, server):
    """The Studies tab's comparison and the sweep tab draw their grasps as tab 3 does:
    antipodal grasps on the part's surface, run as ``--grasps antipodal``, the count
    named for what it counts."""
    import pyarrow.parquet as pq
    from playwright.sync_api import expect

    from mjx_pick.gui.grasp_input import SOURCES

    _, work = server
    import_shipped(page)
    short_procedure(page, 5, 0.05)
    page.get_by_text("Studies", exact=True).click()
    page.get_by_test_id("compare-grasps").click()
    page.get_by_role("option", name=SOURCES["antipodal"], exact=True).click()
    count = page.get_by_label("grasps", exact=True).filter(visible=True)
    expect(count).to_have_count(1)  # the comparison's count, named for what it counts
    count.fill("2")
    page.get_by_label("run folder name").filter(visible=True).first.fill("compare-antipodal")
    page.get_by_test_id("start-compare").click()
    status = wait_job(page, "compare compare-antipodal")
    assert status.startswith("complete"), status
    shown = page.locator("code").filter(has_text="mjx-pick compare").first.inner_text()
    assert "--grasps antipodal --n 2" in shown, shown
    table = pq.read_table(work / "compare-antipodal" / "results.parquet")
    assert "grasp_pose" in table.column_names and table.num_rows >= 2

    page.get_by_text("Parameter sweep").click()
    page.get_by_test_id("sweep-grasps").click()
    page.get_by_role("option", name=SOURCES["antipodal"], exact=True).click()
    number(page, "start", 0.5)
    number(page, "end", 0.9)
    number(page, "step", 0.4)
    number(page, "simulations per value", 2)
    expect(page.get_by_test_id("sweep-count")).to_have_text("2 values x 2 grasps = 4 simulations")
    page.get_by_label("run folder name").filter(visible=True).last.fill("sweep-antipodal")
    page.get_by_test_id("start-sweep").click()
    status = wait_job(page, "sweep sweep-antipodal")
    assert status.startswith("complete, 4/4"), status
    shown = page.locator("code").filter(has_text="mjx-pick sweep").first.inner_text()
    assert "--grasps antipodal" in shown, shown
