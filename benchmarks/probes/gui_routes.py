"""Probe the GUI's second routes (issue 49, cases 12, 19 and 20) with values of their own,
in headless Chromium through Playwright, as a user would click them.

Starts ``mjx-pick gui`` on a free port with an empty work folder (the tests' harness,
tests/test_gui.py) and runs one probe after another, each classified as

* refused: the page says what is wrong with the input, in its words, before any work;
* handled: the page does the right thing (a long search shows its progress and stops; a
  rare feasible share is warned of by its reason; a second browser tab follows a run to
  its end; a study's run counts its simulations; a sweep's parameters are in words; a
  map's pick-point is the value it shows);
* wrong: anything else -- a hang, a raw library message, a path of the software's own
  files, a CLI flag or argument name, a traceback, a clipped label, a wrong number.

Run from the repository root with the GUI extra and Chromium installed:

    PYTHONPATH=$PWD python benchmarks/probes/gui_routes.py [--only 19]

It prints one line per probe and the counts per family, and writes gui_probes.csv in
--out. About 5-10 minutes on a 2-core CPU.
"""

from __future__ import annotations

import re
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tests"))  # the GUI tests' harness and steps
sys.path.insert(0, str(Path(__file__).resolve().parent))  # second_routes' counting
from second_routes import ProbeList  # noqa: E402
from test_gui import choose, import_shipped, number, start_short_batch  # noqa: E402

# what a GUI user must never read: a library's own words, the software's files, a CLI
# flag or an argument's internal name
RAW = (
    "Traceback",
    "Height must be nonzero",
    "site-packages",
    str(ROOT / "mjx_pick"),
    "--px-per-mm",
    "--thickness-mm",
    "--mass-g",
    "px_per_mm",
    "thickness_mm",
    "mass_g",
)


def raw_text(page) -> str | None:
    """The first thing of RAW the page's visible text shows, or None."""
    text = page.locator("body").inner_text()
    return next((r for r in RAW if r in text), None)


def fresh(browser, url: str, width: int = 1500):
    page = browser.new_context(viewport={"width": width, "height": 1000}).new_page()
    page.set_default_timeout(60_000)
    page.goto(url)
    page.get_by_text("1 Import object model").wait_for()
    return page


def probes(browser, url: str, work: Path, tmp: Path) -> list[tuple[str, str, Callable]]:
    """(family, name, probe) for each probe; each probe returns its (class, note)."""
    out = ProbeList()
    add = out.add

    # 12: searches for feasible pick-points that take long: shown as they go, stoppable
    for obj, coverage, n, button in (
        ("block", 0.97, 200, "generate"),
        ("block", 0.99, 50, "generate"),
        ("block", 1.0, 10, "generate"),
        ("door_opener", 0.95, 500, "generate"),
        ("block", 0.98, 300, "start-batch"),
    ):

        @add("12 long searches", f"{obj} coverage {coverage} n {n} ({button})")
        def _(obj=obj, coverage=coverage, n=n, button=button):
            page = fresh(browser, url)
            try:
                import_shipped(page, obj)
                page.get_by_text("2 Set gripper parameters").click()
                number(page, "minimum coverage", coverage)
                number(page, "lift height (mm)", 5)
                number(page, "hold (s)", 0.05)
                page.get_by_text("3 Generate input data").click()
                number(page, "pick-points", n)
                page.get_by_label("run folder name").fill(f"search-{obj}-{coverage}-{n}")
                t0 = time.monotonic()
                page.get_by_test_id(button).click()
                line = page.get_by_test_id("picks-search")
                done = page.get_by_test_id("picks-info").filter(has_text="feasible pick-points")
                refused = page.get_by_test_id("generate-error").filter(has_text="no feasible")
                for _ in range(200):  # 20 s: a line that says how far, or an answer
                    if "of at most" in line.inner_text() or done.count() or refused.count():
                        break
                    page.wait_for_timeout(100)
                else:
                    return "wrong", "20 s without progress or answer"
                if done.count() or refused.count():
                    return ("refused" if refused.count() else "handled"), (
                        f"answered in {time.monotonic() - t0:.0f} s"
                    )
                shown = line.inner_text()
                page.get_by_test_id("picks-search-stop").click()
                line.filter(has_text="stopped after").wait_for(timeout=20_000)
                if button == "start-batch":
                    page.get_by_test_id("generate-error").filter(has_text="not started").wait_for(
                        timeout=5_000
                    )
                raw = raw_text(page)
                if raw:
                    return "wrong", f"shows {raw!r}"
                return "handled", shown[:110]
            finally:
                page.context.close()

    # 12: coverages a few poses meet: the warning names the coverage, never the stroke
    for obj, coverage, n in (
        ("block", 0.66, 4),
        ("block", 0.74, 2),
        ("door_opener", 0.8, 3),
    ):

        @add("12 rare coverage", f"{obj} coverage {coverage} n {n}")
        def _(obj=obj, coverage=coverage, n=n):
            page = fresh(browser, url)
            try:
                import_shipped(page, obj)
                page.get_by_text("2 Set gripper parameters").click()
                number(page, "minimum coverage", coverage)
                page.get_by_text("3 Generate input data").click()
                number(page, "pick-points", n)
                page.get_by_test_id("generate").click()
                info = page.get_by_test_id("picks-info").filter(has_text="feasible pick-points")
                refused = page.get_by_test_id("generate-error").filter(has_text="no feasible")
                for _ in range(1200):  # 120 s
                    if info.count() or refused.count():
                        break
                    page.wait_for_timeout(100)
                # the reason a warning or refusal gives first: the one that rejected most
                # (the info line's counts may name the stroke for the few it rejected)
                if refused.count():
                    said = page.get_by_test_id("generate-error").inner_text()
                elif info.count():
                    said = page.get_by_test_id("picks-warning").inner_text()
                else:
                    return "wrong", "no answer in 120 s"
                first = said.split(" because ", 1)[1] if " because " in said else ""
                rare = refused.count() or "candidate poses are feasible" in said
                if rare and ("barely fits" in said or not first.startswith("the object fills")):
                    return "wrong", said[:110]
                if refused.count():
                    return "refused", said[:110]
                return "handled", (said or page.get_by_test_id("picks-info").inner_text())[:110]
            finally:
                page.context.close()

    # 19: a study's run counts its simulations; the sweep's parameters are in words
    for i, (study, setting) in enumerate(
        (
            ("sweep", ("grasp.hold_s", "hold", "0.05", "0.15", "0.05", 3)),
            ("sweep", ("contact.table_friction", "table friction", "0.3", "0.5", "0.2", 2)),
            ("compare", 3),
        )
    ):

        @add("19 study counts", f"{study} {setting[0] if study == 'sweep' else setting}")
        def _(study=study, setting=setting, name=f"count-{i}"):
            page = fresh(browser, url)
            try:
                import_shipped(page)
                page.get_by_text("2 Set gripper parameters").click()
                number(page, "lift height (mm)", 5)
                number(page, "hold (s)", 0.05)
                if study == "sweep":
                    _key, words, start, end, step, n = setting
                    page.get_by_text("Parameter sweep").click()
                    select = page.get_by_label("parameter", exact=True)
                    select.fill(words)
                    option = page.get_by_role("option", name=words, exact=False).first
                    option.click()
                    for label, value in (("start", start), ("end", end), ("step", step)):
                        number(page, label, value)
                    number(page, "simulations per value", n)
                    page.get_by_label("run folder name").last.fill(name)
                    page.get_by_test_id("start-sweep").click()
                else:
                    page.get_by_text("Studies", exact=True).click()
                    page.get_by_label("pick-points", exact=True).filter(visible=True).first.fill(
                        str(setting)
                    )
                    page.get_by_label("run folder name").filter(visible=True).first.fill(name)
                    page.get_by_test_id("start-compare").click()
                page.get_by_test_id("job-title").filter(has_text=name).wait_for()
                status = page.get_by_test_id("job-status")
                status.filter(has_text=re.compile(r"^(complete|failed|cancelled)")).wait_for(
                    timeout=300_000
                )
                line = status.inner_text()
                counted = re.match(r"complete, (\d+)/\1 simulations", line)
                return ("handled" if counted else "wrong"), line[:110]
            finally:
                page.context.close()

    for typed in ("friction", "stiff", "time", "iterations", "mass"):

        @add("19 sweep names", f"typed {typed!r}")
        def _(typed=typed):
            page = fresh(browser, url)
            try:
                import_shipped(page)
                page.get_by_text("Parameter sweep").click()
                page.get_by_label("parameter", exact=True).fill(typed)
                page.get_by_role("option").first.wait_for(timeout=10_000)
                options = page.get_by_role("option").all_inner_texts()
                keys = [o for o in options if "_" in o or re.search(r"\b[a-z]+\.[a-z]", o)]
                if keys:
                    return "wrong", f"keys shown: {keys[:3]}"
                return "handled", "; ".join(options)[:110]
            finally:
                page.context.close()

    # 19: a second browser tab follows a run to its end, whichever tab started it
    for n, cancel in ((12, False), (30, False), (60, True)):

        @add("19 second tab", f"evaluate n {n}" + (", cancelled" if cancel else ""))
        def _(n=n, cancel=cancel):
            first, second = fresh(browser, url), fresh(browser, url)
            name = f"second-{n}-{int(cancel)}"
            try:
                start_short_batch(first, url, name, n, chunk=2)
                first.get_by_test_id("job-title").filter(has_text=name).wait_for()
                second.get_by_text("4 Analyze results").click()
                second.get_by_test_id("run-dir").fill(name)
                second.get_by_test_id("open-run").click()
                error = second.get_by_test_id("analyze-error")
                error.filter(has_text="still running").wait_for(timeout=30_000)
                if cancel:
                    first.get_by_text("Cancel", exact=True).click()
                    error.filter(has_text="was stopped before it finished").wait_for(
                        timeout=120_000
                    )
                    return "handled", error.inner_text()[:110]
                rows = second.get_by_test_id("picks-table").locator("tbody tr")
                rows.first.wait_for(timeout=300_000)
                if error.inner_text():
                    return "wrong", f"opened, still saying {error.inner_text()[:80]!r}"
                return "handled", second.get_by_test_id("run-info").inner_text()[:110]
            except Exception as err:  # noqa: BLE001 - a probe's timeout is its verdict
                return "wrong", f"{type(err).__name__}: {str(err).splitlines()[0][:100]}"
            finally:
                first.context.close()
                second.context.close()

    # 19: inputs a library cannot build an object from, refused in the tab's words
    import cv2

    line = np.full((300, 400, 3), 255, np.uint8)
    line[150, 40:360] = 0
    cv2.imwrite(str(tmp / "line.png"), line)
    cv2.imwrite(str(tmp / "white.png"), np.full((300, 400, 3), 255, np.uint8))
    flat = tmp / "flat.stl"
    flat.write_text(
        "solid f\nfacet normal 0 0 1\nouter loop\nvertex 0 0 0\nvertex 30 0 0\n"
        "vertex 0 20 0\nendloop\nendfacet\nendsolid f\n"
    )
    block_stl = tmp / "truncated.stl"
    import trimesh

    data = trimesh.creation.box([30, 20, 15]).export(file_type="stl")
    block_stl.write_bytes(data[: len(data) // 2])
    for name, upload, fields in (
        ("thickness 1e-6 mm", None, {"thickness (mm)": 1e-6}),
        ("thickness 0.05 mm", None, {"thickness (mm)": 0.05}),
        ("thickness 0 mm", None, {"thickness (mm)": 0}),
        ("thickness 5000 mm", None, {"thickness (mm)": 5000}),
        ("scale 1000 px/mm (a 0.04 mm part)", None, {"image scale (px per mm)": 1000}),
        ("scale 0.02 px/mm (a 2 m part)", None, {"image scale (px per mm)": 0.02}),
        ("mass 1e-9 g", None, {"mass (g)": 1e-9}),
        ("mass 1e7 g", None, {"mass (g)": 1e7}),
        ("a one-pixel line photo", tmp / "line.png", {}),
        ("a blank photo", tmp / "white.png", {}),
        ("a flat mesh", flat, {"mass (g)": 5}),
        ("a truncated STL", block_stl, {"mass (g)": 5}),
    ):

        @add("19 library inputs", name)
        def _(upload=upload, fields=fields):
            page = fresh(browser, url)
            try:
                page.get_by_text("1 Import object model").click()
                if upload is not None:
                    page.get_by_test_id("object-upload").locator(
                        "input[type=file]"
                    ).set_input_files(str(upload))
                    said = page.get_by_test_id("upload-error").filter(has_text=upload.name)
                    taken = page.get_by_text(f"uploaded {upload.name}")
                    for _ in range(300):
                        if said.count() or taken.count():
                            break
                        page.wait_for_timeout(100)
                    if said.count():
                        raw = raw_text(page)
                        return (
                            ("wrong", f"shows {raw!r}") if raw else ("refused", said.inner_text())
                        )
                for label, value in fields.items():
                    number(page, label, value)
                page.get_by_test_id("import").click()
                info = page.get_by_test_id("object-info")
                for _ in range(600):
                    messages = [
                        m for m in page.locator(".q-field__messages").all_inner_texts() if m.strip()
                    ]
                    error = page.get_by_test_id("import-error").inner_text()
                    if messages or error or "outline" in info.inner_text():
                        break
                    page.wait_for_timeout(100)
                raw = raw_text(page)
                if raw:
                    return "wrong", f"shows {raw!r}"
                if messages or error:
                    return "refused", (messages + [error])[0][:110]
                if "outline" in info.inner_text():
                    warning = page.get_by_test_id("import-warning").inner_text()
                    return ("handled", warning[:110]) if warning else ("wrong", "imported")
                return "wrong", "no answer in 60 s"
            finally:
                page.context.close()

    # 19: no label or value clipped, at three widths
    from test_gui_routes import CLIPPED

    from mjx_pick.gui.app import TABS

    for width in (1024, 1280, 1920):

        @add("19 clipped labels", f"{width} px wide")
        def _(width=width):
            page = fresh(browser, url, width)
            try:
                clipped = []
                for _, label in TABS:
                    page.get_by_text(label, exact=True).first.click()
                    if label == "Studies":
                        for study in ("Robustness of the best", "Calibrate contact parameters"):
                            page.get_by_text(study).click()
                    page.wait_for_timeout(500)
                    clipped += page.evaluate(CLIPPED)
                return ("wrong", f"clipped: {clipped[:3]}") if clipped else ("handled", "none")
            finally:
                page.context.close()

    # 20: a map's pick-point is the value it puts into tab 2, in one frame
    @add("20 one frame", "five clicks on tab 3's map, seed 11")
    def _():
        from mjx_pick.core.gripper import load_gripper
        from mjx_pick.core.objects import load_object
        from mjx_pick.core.pickpoints import generate_normal
        from mjx_pick.gui import views

        page = fresh(browser, url)
        try:
            import_shipped(page, "door_opener")
            page.get_by_text("3 Generate input data").click()
            number(page, "pick-points", 30)
            number(page, "seed", 11)
            page.get_by_test_id("generate").click()
            page.get_by_test_id("picks-info").filter(has_text="30 feasible").wait_for()
            obj, gripper = load_object("door_opener"), load_gripper("robotiq-2f85")
            picks = generate_normal(obj, gripper, 30, 11)
            _, pixels = views.picks_png(obj, picks, gripper)
            img = page.get_by_test_id("picks-map").locator("img")
            scale = img.bounding_box()["width"] / img.evaluate("i => i.naturalWidth")
            wrong = []
            for k in (0, 7, 13, 21, 29):
                img.click(position={"x": pixels[k, 0] * scale, "y": pixels[k, 1] * scale})
                said = f"pick-point {int(picks.pick_id[k])} of tab 3's map"  # its notice
                notice = page.locator(".q-notification").filter(has_text=said)
                try:
                    notice.wait_for(timeout=20_000)
                except Exception:  # noqa: BLE001 - the click took no pick-point
                    wrong.append(k)
                    continue
                page.get_by_text("2 Set gripper parameters").click()
                shown = [
                    float(page.get_by_label(label, exact=True).input_value())
                    for label in (
                        "object x under gripper (mm)",
                        "object y under gripper (mm)",
                        "object yaw under gripper (deg)",
                    )
                ]
                want = [picks.x_mm[k], picks.y_mm[k], picks.yaw_deg[k]]
                if not np.allclose(shown, want, atol=0.006):
                    wrong.append(k)
                page.get_by_text("3 Generate input data").click()
                img.wait_for()
                page.wait_for_timeout(800)  # the tab's slide: the map still moves
            if wrong:
                return "wrong", f"picks {wrong} put other values into tab 2"
            return "handled", "5 of 5 clicks put their own values into tab 2"
        finally:
            page.context.close()

    for gripper_name in ("robotiq-2f85-linkage", "onrobot-rg2"):

        @add("20 one frame", f"tab 2's heights, {gripper_name}")
        def _(gripper_name=gripper_name):
            from mjx_pick.core.gripper import load_gripper
            from mjx_pick.core.objects import load_object
            from mjx_pick.core.pickpoints import FeasibilityChecker
            from mjx_pick.core.procedure import GraspConfig, fingertip_height_mm
            from mjx_pick.core.scene import height_compensation_mm

            page = fresh(browser, url)
            try:
                import_shipped(page)
                page.get_by_text("2 Set gripper parameters").click()
                choose(page, "gripper preset", gripper_name)
                page.wait_for_timeout(1000)
                number(page, "lift height (mm)", 5)
                number(page, "hold (s)", 0.05)
                number(page, "object yaw under gripper (deg)", 10)
                page.get_by_test_id("test-pick").click()
                info = page.get_by_test_id("test-info")
                info.filter(has_text="height compensation").wait_for(timeout=300_000)
                text = info.inner_text()
                obj, gripper = load_object("block"), load_gripper(gripper_name)
                batch = FeasibilityChecker(obj, gripper).batch(
                    np.array([0]), np.array([0.0]), np.array([0.0]), np.array([10.0]), "user"
                )
                lift = float(height_compensation_mm(gripper, batch)[0])
                tip = fingertip_height_mm(obj, gripper, GraspConfig())
                said = re.search(r"height compensation: ([\d.]+) mm", text)
                said_tip = re.search(r"fingertip height above the table: ([\d.]+) mm", text)
                if said is None or said_tip is None:
                    return "wrong", text[:110]
                if (
                    abs(float(said.group(1)) - lift) > 0.05
                    or abs(float(said_tip.group(1)) - tip) > 0.05
                ):
                    return (
                        "wrong",
                        f"said {said.group(0)}, {said_tip.group(0)}; {lift:.1f}, {tip:.1f}",
                    )
                return "handled", f"{said.group(0)}; {said_tip.group(0)}"
            finally:
                page.context.close()

    return out


def main() -> None:
    from playwright.sync_api import sync_playwright
    from second_routes import probe_arguments, run_and_count
    from test_gui import chromium_path, start_server, stop_server

    out, only = probe_arguments(__doc__.splitlines()[0], "runs/gui_probes")
    url, proc = start_server(out / "work", out / "server.log")
    try:
        with sync_playwright() as p, tempfile.TemporaryDirectory() as tmp:
            browser = p.chromium.launch(executable_path=chromium_path(), args=["--no-sandbox"])
            found = probes(browser, url, out / "work", Path(tmp))
            run_and_count(found, only, out / "gui_probes.csv", width=20)
            browser.close()
    finally:
        stop_server(proc)


if __name__ == "__main__":
    main()
