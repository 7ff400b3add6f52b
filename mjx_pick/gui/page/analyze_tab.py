"""Tab 4, *Analyze results*: open an evaluate folder, rank its pick-points, inspect one.

Sets the page's open run (:attr:`PageState.obj` is tab 1's; :attr:`PageState.run` is
this tab's), which the robustness study reads. A selected pick-point shows its force
plot and its 3-D replay (``page.replay_view``; one the run did not trace is simulated
for them); Export runs ``mjx-pick report`` (templates, report).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.gui import jobs, views, workfolder
from mjx_pick.gui.formatting import (
    FRAME_NAME,
    MAP_HELP,
    PICK_LABELS,
    compensation_text,
    fmt,
    md_text,
    outcome_words,
)
from mjx_pick.gui.forms import page_words
from mjx_pick.gui.one_pick import simulate_untraced
from mjx_pick.gui.page.job_panel import POLL_S, JobPanel
from mjx_pick.gui.page.replay_view import ReplayView
from mjx_pick.gui.page.widgets import checked, error_label, show_picture, warning_label
from mjx_pick.gui.state import PageState

TABLE_COLUMNS = (
    ("rank", "rank"),
    ("pick_id", "pick"),
    ("x_mm", PICK_LABELS["x_mm"]),
    ("y_mm", PICK_LABELS["y_mm"]),
    ("yaw_deg", PICK_LABELS["yaw_deg"]),
    ("score", "score"),
    ("success", "success"),
    ("failure", "outcome"),
    ("label_margin", "margin"),
    ("t_grasp", "t_grasp"),
    ("phi_max_deg", "phi_max, deg"),
    ("t_grasp_nc", "t_grasp_nc"),
    ("traced", "traced"),
)
# a run of grasps given as poses: each grasp's tilt and height, after its planar part
GRASP_COLUMNS = (
    ("tilt_deg", "tilt from vertical (deg)"),
    ("height_mm", "grasp centre above the table (mm)"),
)
DOWNLOADS = (
    ("template_a4.pdf", "template (A4, PDF)"),
    ("template_letter.pdf", "template (Letter, PDF)"),
    ("report.html", "report (HTML)"),
    ("robot_picks.json", "robot pick-points (JSON)"),
)
# what the report writes for a vertical approach only: the printed 1:1 templates (a
# grasp run's report writes none; an older one's are not offered)
VERTICAL_ONLY = ("template_a4.pdf", "template_letter.pdf")
# the grasp formats a run of grasps given as poses is exported in (``mjx-pick export``)
GRASP_FORMATS = {
    "graspgen": "GraspGen (JSON)",
    "acronym": "ACRONYM (HDF5)",
    "isaac-grasp": "isaac_grasp (YAML)",
    "csv": "CSV of poses",
}


def table_columns(posed: bool) -> list[dict]:
    """The table's columns: a run of grasps given as poses adds each grasp's tilt and
    height after its planar part (x, y, yaw)."""
    keys = list(TABLE_COLUMNS)
    if posed:
        at = [k for k, _ in keys].index("yaw_deg") + 1
        keys[at:at] = GRASP_COLUMNS
    return [
        {"name": k, "label": label, "field": k, "sortable": True, "align": "left"}
        for k, label in keys
    ]


class AnalyzeTab:
    def __init__(self, state: PageState, panel: JobPanel):
        self.state, self.panel = state, panel
        panel.handle("report", self.ended)
        panel.handle("export", self.ended)
        self.map_png, self.map_pixels, self.map_ids = b"", None, []
        with ui.row().classes("w-full items-end"):
            self.run_dir = (
                ui.input("evaluate output folder")
                .classes("w-[32rem]")
                .props('data-testid="run-dir"')
            )
            ui.button("Open", on_click=self.open_run).props('data-testid="open-run"')
            self.known_runs = ui.select(
                [], label="runs in the work folder", on_change=self.on_known_run
            ).classes("w-72")
            ui.button(icon="refresh", on_click=self.refresh_runs).props("flat")
        self.unlisted = warning_label("runs-unlisted")  # folders the list leaves out
        self.error = error_label().props('data-testid="analyze-error"')
        self.run_info = ui.label("").props('data-testid="run-info"')
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-[46rem]"):
                self.table = (
                    ui.table(
                        columns=table_columns(False),
                        rows=[],
                        row_key="pick_id",
                        selection="single",
                        pagination=10,
                        on_select=self.on_select,
                    )
                    .classes("w-full")
                    .props('dense wrap-cells data-testid="picks-table"')
                )
                with ui.row().classes("items-end"):
                    self.export_n = ui.number("n best and n worst", value=3, step=1).classes("w-40")
                    self.export_anim = ui.checkbox("animations (slow)")
                    ui.button("Export template and report", on_click=self.export).props(
                        'data-testid="export"'
                    )
                with ui.row().classes("items-end") as self.grasp_export:
                    self.grasp_format = ui.select(
                        GRASP_FORMATS, value="graspgen", label="grasp file format"
                    ).classes("w-48")
                    ui.button("Export the grasps", on_click=self.export_grasps).props(
                        'data-testid="export-grasps"'
                    )
                self.grasp_export.set_visibility(False)
                self.downloads = ui.row()
                self.downloads_note = (
                    ui.label("").classes("text-xs").props('data-testid="downloads-note"')
                )
            with ui.column().classes("grow"):
                self.map_note = (
                    ui.label("").classes("text-sm max-w-xl").props('data-testid="map-note"')
                )
                self.score_map = (
                    ui.interactive_image(on_mouse=self.on_map_click, events=["click"])
                    .classes("w-full max-w-xl cursor-pointer")
                    .props('data-testid="score-map"')
                )
                self.score_map.set_visibility(False)
                self.map_help = ui.label(MAP_HELP + " It also selects it in the table.").classes(
                    "text-xs max-w-xl"
                )
                self.map_help.set_visibility(False)
                self.detail = ui.markdown("Select a pick-point.").props('data-testid="pick-detail"')
                with ui.column().classes("w-full"):
                    self.force_image = (
                        ui.image()
                        .props("no-transition no-spinner")
                        .classes("w-full max-w-2xl")
                        .props('data-testid="force-plot"')
                    )
                self.force_image.set_visibility(False)
                self.replay = ReplayView()
        self.simulated: dict = {}  # (run folder, pick id): trace of an untraced pick
        self.shown = None  # (run, pick id) the details show now
        # a folder asked for while its run was still going: followed until it ends,
        # whichever browser tab (or process) runs it, then opened
        self.awaited: Path | None = None
        ui.timer(POLL_S, self.follow)
        self.refresh_runs()

    def refresh_runs(self) -> None:
        """The evaluate folders in the work folder, for the chooser; a folder reached
        through a link that leads outside it is not read, and said."""
        workdir = self.state.workdir
        folders, left_out = workfolder.run_folders(workdir)
        names = [
            str(p)
            for p in folders
            if (workfolder.manifest(p, workdir) or {}).get("command") == "evaluate"
        ]
        self.known_runs.set_options(names)
        self.unlisted.set_text("not listed: " + "; ".join(left_out) if left_out else "")

    def on_known_run(self, _=None) -> None:
        if self.known_runs.value:
            self.open(Path(self.known_runs.value))

    def open(self, folder: Path) -> None:
        """Open an evaluate folder (a complete run of tab 3, or one chosen here)."""
        self.run_dir.value = str(folder)
        self.open_run()

    def open_run(self) -> None:
        """Open the folder of the run-dir field: the page's open run, ranked by score."""
        from mjx_pick.core.metrics import rate_text
        from mjx_pick.outputs.reporting import Run

        self.error.set_text("")
        self.awaited = None
        path = self.state.inside(self.run_dir.value)
        if path is None:
            self.error.set_text(
                f"{(self.run_dir.value or '').strip() or '(empty)'}: only run folders inside "
                f"the work folder ({self.state.workdir}) open here; give a run's name"
            )
            return
        unfinished = self.unfinished(path)
        if unfinished:
            self.error.set_text(unfinished)
            self.awaited = path
            return
        try:
            # every file the run's tables, traces, scene and downloads come from: inside
            workfolder.check_tree(path, self.state.workdir)
            opened = Run.load(path)
        except ConfigError as err:
            self.error.set_text(str(err))
            return
        except (OSError, ValueError) as err:
            self.error.set_text(f"{path}: cannot be read ({err})")
            return
        self.state.run = opened
        posed = views.posed(opened)
        s = opened.summary
        self.run_info.set_text(
            f"{s.get('object')} / {s.get('gripper')}: {s.get('n')} "
            f"{'grasps' if posed else 'pick-points'}, success rate "
            f"{rate_text(s.get('successes', 0), s.get('n', 0))}, "
            f"mean score {fmt(s.get('score_mean'))}, "
            f"F_Gmin {fmt(s.get('f_gmin_n'))} N"
        )
        self.table.columns = table_columns(posed)
        self.table.rows = ranked_rows(opened)
        self.table.selected = []
        self.table.update()
        self.map_ids = [int(v) for v in opened.table["pick_id"].to_pylist()]
        if posed:  # tilted grasps: a map of a vertical approach would mislead
            self.map_png, self.map_pixels = b"", None
            self.map_note.set_text(views.posed_text(opened))
        else:
            self.map_png, self.map_pixels = views.score_map_png(opened)
            self.score_map.set_source(views.data_uri(self.map_png, "image/png"))
            self.map_note.set_text("")
        self.score_map.set_visibility(not posed)
        self.map_help.set_visibility(not posed)
        self.grasp_export.set_visibility(posed)
        what = "grasp" if posed else "pick-point"
        self.detail.set_content(f"Select a {what} (the table is ranked by score).")
        self.force_image.set_visibility(False)
        self.replay.hide()
        self.show_downloads()
        self.refresh_runs()

    def follow(self) -> None:
        """A folder that was still running when asked for: its state as it goes, and
        opened here once it is complete (its run may be another browser tab's)."""
        path = self.awaited
        if path is None:
            return
        why = self.unfinished(path)
        if why:
            self.error.set_text(why)
            if " is still running" not in why:  # it ended without results: said, done
                self.awaited = None
            return
        self.awaited = None
        if self.state.inside(self.run_dir.value) == path:  # still the folder asked for
            self.open_run()

    def unfinished(self, path: Path) -> str:
        """Why an evaluate folder has no results to open yet ('' if it may have)."""
        workdir = self.state.workdir
        job = self.panel.runs.writing(path)
        if job is not None:
            p = job.poll()
            count = f" ({p.done}/{p.total} {p.unit})" if p.done is not None else ""
            return f"{path.name} is still running{count}: it opens here when it is complete"
        m = workfolder.manifest(path, workdir) or {}
        if m.get("command") != "evaluate" or (path / "results.parquet").is_file():
            return ""
        if m.get("status") == "running" and workfolder.lock_holder(path, workdir) is not None:
            return (
                f"{path.name} is still running in another process: it opens here when it "
                "is complete"
            )
        if m.get("status") == "running":  # no process writes it: it died mid-run
            return (
                f"{path.name} stopped without finishing: continue it in tab 3 (run folder "
                f"name {path.name}, resume ticked)"
            )
        if m.get("status") in ("interrupted", "cancelled"):
            return (
                f"{path.name} was stopped before it finished: continue it in tab 3 (run "
                f"folder name {path.name}, resume ticked)"
            )
        return ""

    async def on_map_click(self, e) -> None:
        """A click on the score map selects the pick-point drawn nearest it."""
        if self.state.run is None or self.map_pixels is None:
            return
        i = views.nearest_pick(self.map_pixels, e.image_x, e.image_y)
        if i is None:
            return
        pid = self.map_ids[i]
        row = next(r for r in self.table.rows if int(r["pick_id"]) == pid)
        self.table.selected = [row]
        self.table.update()
        await self.show_pick(row)

    async def on_select(self, e) -> None:
        """A selected pick-point: its metrics, and if traced its force plot and replay."""
        if e.selection and self.state.run is not None:
            await self.show_pick(e.selection[0])

    async def show_pick(self, row: dict) -> None:
        """A pick-point's metrics, drawn whole on the map (its part at its pose, the
        fingers at its opening); if traced its force plot and replay."""
        opened = self.state.run
        pid = int(row["pick_id"])
        self.shown = (opened, pid)  # what the awaits below draw for, unless it changes
        full = opened.row(pid)
        posed = views.posed(opened)
        if posed:  # a grasp given as a pose: its tilt and height first
            head = (
                f"**grasp {pid}** (rank {row['rank']}): approach tilted "
                f"{full['tilt_deg']:.1f} deg from vertical, grasp centre "
                f"{full['height_mm']:.1f} mm above the table; its planar part: object x "
                f"{full['x_mm']:.2f} mm, y {full['y_mm']:.2f} mm, yaw "
                f"{full['yaw_deg']:.1f} deg under the gripper's heading; opening "
                f"{full['opening_mm']:.1f} mm"
            )
        else:
            head = (
                f"**pick {pid}** (rank {row['rank']}): object x {full['x_mm']:.2f} mm, y "
                f"{full['y_mm']:.2f} mm, yaw {full['yaw_deg']:.1f} deg under the gripper "
                f"({FRAME_NAME}), opening {full['opening_mm']:.1f} mm"
            )
        lines = [
            head,
            "",
            f"- score (eq. 2): **{fmt(full['score'])}**, success: **{full['success']}**, "
            f"outcome: {outcome_words(full['failure'])}",
            f"- `t_grasp`: {fmt(full['t_grasp'])} (grip force held, fraction of the window)",
            f"- `phi_max`: {fmt(full['phi_max_deg'], 1)} deg (largest rotation)",
            f"- `t_grasp_nc`: {fmt(full['t_grasp_nc'])} (off the table, fraction)",
            f"- pad forces max {fmt(full['max_force_left_n'], 1)} / "
            f"{fmt(full['max_force_right_n'], 1)} N, object raised "
            f"{fmt(full['lift_height_mm'], 1)} mm at the end of the hold, slip "
            f"{fmt(full['slip_mm'], 2)} mm",
        ]
        if full.get("height_compensation_mm") is not None:
            lines.append("- " + compensation_text(full["height_compensation_mm"]))
        self.detail.set_content("\n".join(lines))
        if not posed:  # drawn whole on the map (grasps as poses have none)
            png, _ = await run.io_bound(views.score_map_png, opened, self.map_ids.index(pid))
            if self.shown != (opened, pid):  # another pick chosen meanwhile: it draws its own
                return
            self.score_map.set_source(views.data_uri(png, "image/png"))
        f_d = float(opened.config["grasp"]["grip_force_n"])
        if row.get("traced") == "yes":
            trace = opened.trace(pid)
        else:
            trace = await self.simulate_untraced(opened, pid, lines)
            if trace is None or self.shown != (opened, pid):  # another pick chosen meanwhile
                return
        try:
            tilted = (
                f"; the gripper tilted {full['tilt_deg']:.1f} deg from vertical, as simulated"
                if posed
                else ""
            )
            await self.replay.show(
                opened.path / "scene.xml",
                opened.gripper,
                trace,
                f_d,
                outcome_words(full["failure"]) + tilted,
                not full["success"],
            )
        except (OSError, ValueError) as err:  # scene.xml missing or damaged: keep the plot
            self.error.set_text(f"{opened.path.name}: no 3-D replay ({err})")
        if self.shown != (opened, pid):
            return
        title = f"pick {pid}: score {fmt(full['score'])}, {outcome_words(full['failure'])}"
        png = await run.io_bound(views.force_png, trace, f_d, title)
        if self.shown == (opened, pid):
            show_picture(self.force_image, png)

    async def simulate_untraced(self, opened, pid: int, lines: list[str]) -> dict | None:
        """The trace of a pick-point the run did not trace: simulated now (in a worker
        thread) with the run's settings and the page's object, kept for this page; None
        (and why, in the details) when it cannot be."""
        key = (opened.path, pid)
        if key in self.simulated:
            return self.simulated[key]
        self.force_image.set_visibility(False)
        self.replay.hide()
        note = (
            "\n\nNot traced by the run (it records the forces of its best and worst "
            "pick-points, tab 3's 'traced best and worst'): "
        )
        name = (opened.config.get("object") or {}).get("name", "its object")
        if self.state.obj is None:
            self.detail.set_content(
                "\n".join(lines) + note + f"import the run's object ({md_text(name)}) in tab 1 to "
                "simulate it here for its force plot and replay."
            )
            return None
        self.detail.set_content("\n".join(lines) + note + "simulating it now ...")
        try:
            trace, again, differs = await run.io_bound(
                simulate_untraced, opened, self.state.obj, pid
            )
        except ConfigError as err:
            self.detail.set_content(
                "\n".join(lines)
                + note
                + f"it cannot be simulated here: {md_text(page_words(str(err)))}"
            )
            return None
        self.simulated[key] = trace
        if self.state.run is not opened or self.shown != (opened, pid):
            return None  # another run or pick was chosen meanwhile: it says its own
        self.detail.set_content(
            "\n".join(lines)
            + note
            + f"simulated now with the run's settings (score {fmt(again['score'])}, "
            f"{outcome_words(again['failure'])})" + (f", {md_text(differs)}." if differs else ".")
        )
        return trace

    def export(self) -> None:
        """``mjx-pick report`` of the open run: templates, report, robot pick-points."""
        self.error.set_text("")
        opened = self.state.run
        if opened is None:
            self.error.set_text("open an evaluate output folder first")
            return
        if self.panel.busy(self.error):
            return
        n = checked(self.export_n, "report_n")
        if n is None:
            return
        log = self.state.log(f"{opened.path.name}-report")
        job = jobs.report_job(opened.path, n, bool(self.export_anim.value), log)
        self.panel.start(f"report {opened.path.name}", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        """A report ended: its run open here (also after a reload), with its downloads."""
        run = Path(job.argv[1])
        if self.state.run is None or self.state.run.path != run:
            self.open(run)
        self.show_downloads()

    def show_downloads(self) -> None:
        """A download button for each file the report (or the grasps' export) wrote
        into the open run; for grasps given as poses, not the report's template (a
        vertical approach), and said so."""
        from mjx_pick.outputs.exchange import default_path, object_mesh_path

        self.downloads.clear()
        self.downloads_note.set_text("")
        opened = self.state.run
        if opened is None:
            return
        offered = list(DOWNLOADS)
        if views.posed(opened):
            offered = [(n, label) for n, label in offered if n not in VERTICAL_ONLY]
            for fmt_name, label in GRASP_FORMATS.items():
                name = default_path(opened.path, fmt_name).name
                offered += [(name, f"grasps: {label}"), (object_mesh_path(name).name, "")]
            if (opened.path / "report.html").is_file():
                self.downloads_note.set_text(
                    "No printed template: a 1:1 template places pick-points under a "
                    "vertical approach, and these grasps are tilted. The robot's file "
                    "gives each grasp's whole pose, its tilt included; the grasps with "
                    "the part's mesh, as simulated: 'Export the grasps'."
                )
        with self.downloads:
            for name, label in offered:
                path = opened.path / name
                if path.is_file():
                    shown = label or f"part's mesh for {name.removesuffix('_object.obj')}"
                    ui.button(
                        shown, icon="download", on_click=lambda p=path: self.download(p)
                    ).props(f'outline data-testid="download-{name}"')

    def export_grasps(self) -> None:
        """``mjx-pick export``: the open run's grasps (poses, labels, scores) in a grasp
        format, with the part's mesh as simulated, into its folder."""
        self.error.set_text("")
        opened = self.state.run
        if opened is None or not views.posed(opened):
            self.error.set_text("open a run of grasps given as poses first")
            return
        if self.panel.busy(self.error):
            return
        fmt_name = self.grasp_format.value
        # --overwrite: the file is this export's own (its default name in the run folder)
        argv = ["export", str(opened.path), "--format", fmt_name, "--overwrite"]
        log = self.state.log(f"{opened.path.name}-export-{fmt_name}")
        job = jobs.Job(argv, log, unit="files")
        job.writes = opened.path  # into the run's folder: one writer at a time
        self.panel.start(f"export {opened.path.name} ({fmt_name})", job, self.error)

    async def download(self, path: Path) -> None:
        """A file of the open run, sent to the browser -- checked when asked for (a
        link made since the run was opened is refused too) and read then, beside the
        event loop: its bytes go, not a route to its path that a link made later could
        redirect."""
        self.error.set_text("")
        try:
            data = await run.io_bound(workfolder.read_bytes, path, self.state.workdir)
        except workfolder.OutsideWorkFolder as err:
            self.error.set_text(str(err))
            return
        except OSError as err:
            self.error.set_text(f"{self.state.where(path)}: cannot be read ({err.strerror})")
            return
        ui.download.content(data, path.name)


def ranked_rows(opened) -> list[dict]:
    """The table's rows: every pick-point of a run, best score first (NaN last)."""
    traced = {pid for pid, _ in opened.traced()}
    t = opened.table
    score = np.asarray(t["score"], float)
    order = np.argsort(np.where(np.isnan(score), -np.inf, -score), kind="stable")
    rows = []
    for rank, i in enumerate(order, start=1):
        row = {
            k: t[k][int(i)].as_py() for k, _ in TABLE_COLUMNS + GRASP_COLUMNS if k in t.column_names
        }
        for k, v in row.items():
            if isinstance(v, float):
                row[k] = None if math.isnan(v) else round(v, 3)
        row["rank"] = rank
        row["traced"] = "yes" if row["pick_id"] in traced else ""
        if row.get("failure") is not None:  # the outcome in words, not its label
            row["failure"] = outcome_words(row["failure"])
        rows.append(row)
    return rows
