"""Tab 3, *Generate input data*: sample feasible pick-points, then run them (``evaluate``).

The grasps are top-down pick-points (the paper's: their map drawn here), antipodal
grasps on the part's surface, or an uploaded grasp file (``evaluate --grasps``). The
batch simulation is ``mjx-pick evaluate`` in a child process, shown by the job panel; a
run estimated longer than a few minutes is asked about first; a cancelled run is set up
to be resumed, a complete one is opened in tab 4.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.core.pickpoints import rejected_text
from mjx_pick.gui import grasp_input, jobs, views, workfolder
from mjx_pick.gui.formatting import MAP_HELP, fmt, md_text, stamp
from mjx_pick.gui.grasp_input import ANTIPODAL, FILE, TOPDOWN
from mjx_pick.gui.page.job_panel import JobPanel
from mjx_pick.gui.page.settings_form import SettingsForm
from mjx_pick.gui.page.widgets import (
    SearchProgress,
    checked,
    checked_or_empty,
    error_label,
    file_error_label,
    need_object,
    received,
    run_folder,
    upload,
    warning_label,
)
from mjx_pick.gui.search import Search
from mjx_pick.gui.state import PageState
from mjx_pick.gui.uploads import GRASPS_MAX_BYTES, grasps_refused, save_upload


def sample_picks(obj, settings, n: int, seed: int, progress=None):
    """The pick-points of tab 3's map and the warnings their generator gave (in the page,
    not only in the server's log); progress: the page's :class:`Search`."""
    from mjx_pick.core.pickpoints import check_stroke, generate_normal

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        # a part no pose fits is refused before the raster and the draws (as the CLI)
        check_stroke(obj, settings.gripper, settings.picks, settings.grasp)
        picks = generate_normal(
            obj, settings.gripper, n, seed, settings.picks, settings.grasp, progress=progress
        )
    return picks, [str(w.message) for w in caught]


class GenerateTab:
    def __init__(
        self,
        state: PageState,
        form: SettingsForm,
        panel: JobPanel,
        on_complete: Callable[[Path], None],
        on_pick: Callable[[float, float, float, str], None],
    ):
        """on_complete(folder): a complete evaluate run's folder (opened in tab 4);
        on_pick(x, y, yaw, what): a pick-point clicked on the map (for tab 2's test)."""
        self.state, self.form, self.panel = state, form, panel
        self.on_complete, self.on_pick = on_complete, on_pick
        panel.handle("evaluate", self.ended, self.shown)
        self.picks = None  # the pick-points drawn on the map, and where
        self.pixels = None
        self.drawn_for = None  # (object, settings, n, seed) of the map's pick-points
        self.grasp_file: Path | None = None  # the uploaded grasp file, stored
        self.grasp_file_name = ""  # as the user named it
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.source = ui.select(
                    grasp_input.SOURCES,
                    value=TOPDOWN,
                    label="grasps from",
                    on_change=self.on_source,
                ).props('data-testid="grasp-source"')
                with ui.column().classes("w-full gap-1") as self.file_box:
                    self.grasp_upload = upload(
                        "upload a grasp file",
                        ",".join(grasp_input.FILE_SUFFIXES),
                        GRASPS_MAX_BYTES,
                        self.on_grasp_file,
                        self.refuse_grasp_file,
                        grasps_refused,
                        "grasps-upload",
                    ).classes("w-full")
                    self.grasp_file_info = (
                        ui.label("").classes("text-sm").props('data-testid="grasps-file-info"')
                    )
                    self.grasp_file_error = file_error_label().props(
                        'data-testid="grasps-file-error"'
                    )
                    self.depth = ui.number(
                        "grasp depth (mm): base to grasp centre", value=None, step=1
                    ).props('data-testid="grasp-depth"')
                    self.depth.tooltip(
                        "the grasp centre's distance from the gripper's base along the "
                        "approach, for every grasp; empty: the file's own (0: the poses are "
                        "grasp centres)"
                    )
                self.file_box.set_visibility(False)
                self.n = ui.number(
                    "pick-points", value=200, step=1, on_change=self.forget_map
                ).props('data-testid="n"')
                self.seed = ui.number("seed", value=0, step=1, on_change=self.forget_map)
                self.source_note = (
                    ui.label("").classes("text-xs").props('data-testid="grasp-source-note"')
                )
                self.traces = ui.number("traced best and worst (force plots)", value=3, step=1)
                self.chunk = ui.number("pick-points per saved chunk", value=None, step=1)
                self.chunk.tooltip("empty: chosen so that the progress bar moves often")
                self.run_name = ui.input("run folder name", value=f"evaluate-{stamp()}")
                self.resume = ui.checkbox("resume an interrupted run of this folder")
                ui.button("Load this run folder's settings", on_click=self.load_run_settings).props(
                    'flat dense data-testid="load-run"'
                )
                self.checks = ui.checkbox(
                    "check each label: again at half the time step and with the part moved "
                    "1 um (about 3x the simulation)"
                ).props('data-testid="label-checks"')
                self.generate_button = ui.button(
                    "Generate pick-points", on_click=self.generate
                ).props('data-testid="generate"')
                ui.button("Start batch simulation", on_click=self.start_evaluate).props(
                    'data-testid="start-batch"'
                )
                self.error = error_label().props('data-testid="generate-error"')
            with ui.column().classes("grow"):
                self.search = SearchProgress("picks-search")
                self.picks_info = ui.label("").props('data-testid="picks-info"')
                self.picks_warning = warning_label("picks-warning")
                self.map_help = ui.label(
                    MAP_HELP + " It also goes into tab 2's test simulation."
                ).classes("text-xs max-w-2xl")
                self.map_help.set_visibility(False)
                self.picks_image = (
                    ui.interactive_image(on_mouse=self.on_map_click, events=["click"])
                    .classes("w-full max-w-2xl cursor-pointer")
                    .props('data-testid="picks-map"')
                )
                self.picks_image.set_visibility(False)
                self.run_summary = ui.markdown("").props('data-testid="run-summary"')

    def on_source(self, _=None) -> None:
        """Another grasp source: its own fields (a file and its depth; a count of drawn
        grasps) and what the tab says of it. Generate and the map are for top-down
        pick-points only: the map draws each in the gripper frame of a vertical
        approach, which a tilted grasp is not."""
        source = self.source.value
        self.file_box.set_visibility(source == FILE)
        self.n.set_visibility(source != FILE)  # a file's every grasp is simulated
        self.n.props(f'label="{"grasps" if source == ANTIPODAL else "pick-points"}"')
        self.generate_button.set_visibility(source == TOPDOWN)
        self.forget_map()
        from mjx_pick.core.antipodal import AntipodalConfig

        tilt = AntipodalConfig().max_tilt_deg  # the run's (the page sets none of its own)
        self.source_note.set_text(
            {
                TOPDOWN: "",
                ANTIPODAL: "The run draws this many antipodal grasps on the part's surface "
                "(a photo's part: its outline extruded to its thickness), each approaching "
                f"from above, tilted up to {tilt:g} deg, checked for the real gripper. Tab "
                "4 shows them with their tilt and height; no map here (it draws top-down "
                "pick-points).",
                FILE: "Every grasp of the file is simulated, those the gripper cannot do "
                "left out and counted by reason: its poses are the gripper's base in the "
                "frame of tab 1's mesh file. Tab 4 shows them with their tilt and height.",
            }[source]
        )

    async def on_grasp_file(self, e) -> None:
        """An uploaded grasp file: stored in the work folder and read as the run will
        read it (its format, its grasps, which give their depth)."""
        self.grasp_file_error.set_text("")
        got = await received(
            e, self.grasp_upload, lambda n, d: grasps_refused(n, len(d)), self.refuse_grasp_file
        )
        if got is None:
            return
        name, data = got
        try:
            path = await run.io_bound(
                save_upload, data, name, self.state.uploads, self.state.workdir
            )
            _, n, missing = await run.io_bound(grasp_input.read_grasp_file, path, name)
        except ConfigError as err:
            self.refuse_grasp_file(str(err))
            return
        self.grasp_file, self.grasp_file_name = path, name
        depth = (
            "each gives its depth"
            if not missing
            else f"{missing} without a depth: give the grasp depth below"
        )
        self.grasp_file_info.set_text(f"{name}: {n:,} grasps ({depth})")

    def refuse_grasp_file(self, why: str) -> None:
        """A grasp file refused (by the browser or here): said until the next upload,
        and it replaces the one before -- a run never takes the earlier file."""
        self.grasp_file_error.set_text(why)
        self.grasp_file, self.grasp_file_name = None, ""
        self.grasp_file_info.set_text("")

    def load_run_settings(self) -> None:
        """The settings a run in the work folder was made with (its config.json, written
        when it starts: a stopped run has one), into this page: tab 2's fields, the
        pick-points, the seed, the traces, the chunk size and the name, resume ticked --
        so that it can be continued after a reload, or a run repeated."""
        self.error.set_text("")
        folder = self.state.run_folder(self.run_name.value or "")
        if folder is None or not (folder / "config.json").is_file():
            self.run_name.error = "no run of this name in the work folder"
            return
        self.run_name.error = None
        argv = jobs.recorded_argv(self.state.log(folder.name), self.state.workdir)
        if self.show_recorded(folder, argv or [], settings=True):
            done = (workfolder.manifest(folder, self.state.workdir) or {}).get("status")
            self.resume.value = done != "complete"

    def show_recorded(self, folder: Path, argv: list[str], settings: bool = False) -> bool:
        """Tab 3 as a run's folder records it: its pick-points and seed as its run key
        holds them (what a resume compares: the number asked for, not the feasible
        count), its traces, chunk size and label checks from its command line (argv:
        the CLI arguments it was started with) or its config; with settings, tab 2's
        fields too (its config.json). False (and why, in the tab) when they cannot be
        read."""
        from mjx_pick.studies.recorded import settings_of

        workdir = self.state.workdir
        recorded = (workfolder.manifest(folder, workdir) or {}).get("settings") or {}
        config = workfolder.json_or_none(folder / "config.json", workdir) or {}
        if settings:
            try:
                if not config:
                    workfolder.read_json(folder / "config.json", workdir)  # says why
                run_settings, picks = settings_of(config, f"run {folder.name}")
            except (OSError, ValueError) as err:  # ConfigError and OutsideWorkFolder too
                self.error.set_text(f"{folder.name}: its settings cannot be read ({err})")
                return False
            self.form.adopt_run(run_settings, picks, config.get("backend"))
        numbers = {
            self.n: recorded.get("n") or jobs.flag_value(argv, "--n") or config.get("n"),
            self.seed: recorded.get("seed", jobs.flag_value(argv, "--seed")),
            self.traces: jobs.flag_value(argv, "--traces"),
            self.chunk: jobs.flag_value(argv, "--chunk-size") or config.get("chunk_size"),
        }
        for widget, value in numbers.items():
            if value is not None:
                widget.value = int(value)
        self.checks.value = bool(recorded.get("step_check", "--step-check" in argv))
        self.show_source(argv)
        self.run_name.value = folder.name
        self.run_name.error = None
        obj = (config.get("object") or {}).get("name")
        if obj is not None and (self.state.obj is None or self.state.obj.name != obj):
            self.error.set_text(f"{folder.name} is a run of {obj}: import it in tab 1")
        return True

    def show_source(self, argv: list[str]) -> None:
        """The grasp source a run's command line names: its file (inside the work
        folder only) and depth, so that Start continues it."""
        source, file, depth = grasp_input.recorded_source(argv)
        self.source.value = source
        self.depth.value = depth
        if source == FILE:
            path = self.state.inside(file or "")
            if path is None or not path.is_file():
                self.refuse_grasp_file(
                    f"{file}: the run's grasp file is not in the work folder: upload it again"
                )
            else:
                self.grasp_file, self.grasp_file_name = path, path.name
                self.grasp_file_error.set_text("")
                self.grasp_file_info.set_text(f"{path.name}: the run's grasp file")
        self.on_source()

    def shown(self, job: jobs.Job) -> None:
        """An evaluate run the panel shows that this page did not start (after a reload,
        or chosen in the runs list): tab 3 shows its numbers and name as its folder
        records them, so that Start continues it where it can be continued."""
        if job.out is not None:
            self.show_recorded(job.out, job.argv)

    def pick_numbers(self, count: bool = True) -> tuple[int, int] | None:
        """(n, seed) by their rules, or None with the rule under the field; count False:
        the grasps are a file's (its count, not n's: n is hidden and not read)."""
        n = checked(self.n, "n") if count else 0
        seed = checked(self.seed, "seed")
        return None if n is None or seed is None else (n, seed)

    async def generate(self) -> None:
        """Sample the pick-points (in a worker thread) and draw them on the outline."""
        self.error.set_text("")
        if not need_object(self.state, self.error):
            return
        if self.source.value != TOPDOWN:  # its button is hidden: a click sent before
            self.error.set_text("the map draws top-down pick-points: choose them as grasps")
            return
        settings = self.form.read()
        numbers = self.pick_numbers()
        if settings is None or numbers is None:
            return
        n, seed = numbers
        if self.search.running:
            self.error.set_text("pick-points are being checked: wait for them or stop them")
            return
        obj = self.state.obj
        self.forget_map()
        try:
            found = await self.search.run(
                Search(n, settings.picks.max_candidates), sample_picks, obj, settings, n, seed
            )
            if found is None:  # stopped: the search's line says how far it got
                return
            picks, warned = found
            png, pixels = await run.io_bound(views.picks_png, obj, picks, settings.gripper)
        except ConfigError as err:
            self.error.set_text(str(err))
            return
        self.picks, self.pixels = picks, pixels
        self.drawn_for = (obj, settings, n, seed)
        self.picks_warning.set_text("warning: " + "; ".join(warned) if warned else "")
        rejected = rejected_text(picks.rejected)
        self.picks_info.set_text(
            f"{len(picks)} feasible pick-points of {picks.n_candidates} candidates checked "
            f"(rejected: {rejected})"
        )
        self.picks_image.set_source(views.data_uri(png, "image/png"))
        self.picks_image.set_visibility(True)
        self.map_help.set_visibility(True)

    def forget_map(self, _=None) -> None:
        """The map and its count no longer show what would run (another n, seed or
        object): hidden until Generate draws them again."""
        self.search.clear()
        if self.picks is None:
            return
        self.picks = self.pixels = self.drawn_for = None
        self.picks_info.set_text("")
        self.picks_warning.set_text("")
        self.picks_image.set_visibility(False)
        self.map_help.set_visibility(False)

    async def on_map_click(self, e) -> None:
        """The pick-point nearest a click on the map: drawn whole on the map (its part
        at its pose, the fingers at its opening) and put into tab 2's test simulation."""
        if self.picks is None:
            return
        i = views.nearest_pick(self.pixels, e.image_x, e.image_y)
        if i is None:
            return
        p = self.picks
        x, y, yaw = (round(float(v[i]), 2) for v in (p.x_mm, p.y_mm, p.yaw_deg))
        self.on_pick(x, y, yaw, f"pick-point {int(p.pick_id[i])} of tab 3's map")
        obj, settings = self.drawn_for[0], self.drawn_for[1]
        png, _ = await run.io_bound(views.picks_png, obj, p, settings.gripper, i)
        if self.picks is p:  # the map was not redrawn or forgotten meanwhile
            self.picks_image.set_source(views.data_uri(png, "image/png"))

    async def start_evaluate(self) -> None:
        """``mjx-pick evaluate`` with the page's object, settings, grasps and numbers:
        every input checked first, a run estimated longer than a few minutes asked
        about, then started."""
        self.error.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        source = self.source.value
        settings = self.form.read()
        numbers = self.pick_numbers(count=source != FILE)
        # each by its one rule (core.numbers), as the CLI checks --traces and
        # --chunk-size: a value out of it is refused under its field, never changed
        traces = checked(self.traces, "n_traces")
        chunk_ok, chunk = checked_or_empty(self.chunk, "chunk_size")
        depth_ok, depth = (True, None)
        if source == FILE:
            depth_ok, depth = checked_or_empty(self.depth, "depth_mm")
        out = run_folder(self.state, self.run_name, resume=bool(self.resume.value))
        if (
            settings is None
            or numbers is None
            or out is None
            or traces is None
            or not chunk_ok
            or not depth_ok
        ):
            return
        n, seed = numbers
        obj = self.state.obj
        if source == FILE:  # the file as the run will read it, before any work
            n = await self.file_grasps(obj, settings, depth)
            if n is None:
                return
        checks = bool(self.checks.value)
        refusal = jobs.long_run(
            "evaluate",
            "this evaluate",
            self.form.backend.value,
            settings.grasp,
            n=n,
            step_check=checks,
            stability_um=1.0 if checks else 0.0,
        )
        yes = await self.panel.confirmed(refusal, self.error)
        if yes is None:
            return
        if chunk is None and source != TOPDOWN:
            # the bar moves every 2 % of the grasps: a file's count (the feasible are
            # fewer), or the antipodal grasps asked for (the run draws that many feasible)
            chunk = jobs.progress_chunk(n)
        elif chunk is None:  # the bar moves every 2 % of the pick-points the run simulates
            drawn = self.drawn_for
            if drawn is not None and drawn[0] is obj and drawn[1:] == (settings, n, seed):
                feasible = len(self.picks)
            elif self.search.running:
                self.error.set_text("pick-points are being checked: wait for them or stop them")
                return
            else:  # the same search as the run's first step: shown, and it can be stopped
                wanted = min(n, jobs.ESTIMATE_SAMPLE)
                try:
                    feasible = await self.search.run(
                        Search(wanted, settings.picks.max_candidates),
                        jobs.feasible_estimate,
                        obj,
                        settings,
                        n,
                        seed,
                    )
                except ConfigError as err:
                    self.error.set_text(str(err))
                    return
                if feasible is None:
                    self.error.set_text("not started: its pick-point check was stopped")
                    return
            chunk = jobs.progress_chunk(feasible)
        if self.panel.busy(self.error):  # another start while this one was estimating
            return
        flags = self.form.cli_flags(settings, self.state.workdir, out)
        argv = ["evaluate", *self.state.obj_args, *flags]
        argv += grasp_input.source_args(source, self.grasp_file, depth)
        if source != FILE:  # a file's every grasp runs: its count is the file's
            argv += ["--n", str(n)]
        argv += ["--seed", str(seed), "--traces", str(traces)]
        argv += ["--chunk-size", str(chunk), "--no-progress", "--out", str(out)]
        if checks:
            argv += ["--step-check", "--stability-um", "1"]
        if self.resume.value:
            argv.append("--resume")
        argv += yes
        self.run_summary.set_content("")

        unit = "pick-points" if source == TOPDOWN else "grasps"
        job = jobs.Job(argv, self.state.log(out.name), out, n, chunk, unit=unit)
        self.panel.start(f"evaluate {out.name}", job, self.error)

    async def file_grasps(self, obj, settings, depth_mm: float | None) -> int | None:
        """How many grasps the uploaded file gives the run, checked as the run will read
        them (every grasp's depth known, the grasp centres near the part); None, and
        why under the field it concerns, when it cannot run."""
        path, name = self.grasp_file, self.grasp_file_name
        if path is None:
            self.grasp_file_error.set_text("upload a grasp file first (or choose other grasps)")
            return None
        try:
            path = workfolder.confined(path, self.state.workdir)
            n, missing = await run.io_bound(
                grasp_input.check_grasp_file, obj, settings.gripper, path, name, depth_mm
            )
            if missing:
                self.depth.error = (
                    f"{missing:,} of the {n:,} grasps of {name} do not say how far the grasp "
                    "centre lies from the gripper's base: give that distance here (0 where "
                    "the poses are grasp centres)"
                )
                return None
            return n
        except ConfigError as err:  # OutsideWorkFolder too
            self.grasp_file_error.set_text(str(err))
            return None

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        """An evaluate run ended (also one started before a reload of the page)."""
        out = job.out
        if progress.state == "cancelled":  # ready to continue: same folder, its settings
            self.show_recorded(out, job.argv, settings=True)
            self.resume.value = True
            self.run_summary.set_content(
                f"**{md_text(out.name)}**: cancelled; its finished chunks are kept. Start the "
                "batch again (resume is ticked) to continue it."
            )
            return
        if progress.state != "complete":
            return
        from mjx_pick.core.metrics import MARGINAL_BAND, rate_text

        self.resume.value = False
        self.run_name.value = f"evaluate-{stamp()}"  # this name is taken now
        s = workfolder.read_json(out / "summary.json", self.state.workdir)
        checks = "".join(
            f" {s[key]} of {s['n']} labels {what}."
            for key, what in (
                ("labels_marginal", f"decided within {MARGINAL_BAND:g} of a threshold"),
                ("labels_unconverged", "change at half the time step"),
                ("labels_unstable", "change with the part moved 1 um"),
            )
            if key in s
        )
        self.run_summary.set_content(
            f"**{md_text(out.name)}**: success rate {rate_text(s['successes'], s['n'])}, "
            f"mean score {fmt(s['score_mean'])}, "
            f"{s['picks_per_s']} pick-points/s on {s['backend']}.{checks} Open tab 4."
        )
        self.on_complete(out)
