"""Tab 3, *Generate input data*: sample feasible pick-points, then run them (``evaluate``).

The batch simulation is ``mjx-pick evaluate`` in a child process, shown by the job panel;
a cancelled run is set up to be resumed, a complete one is opened in tab 4.
"""

from __future__ import annotations

import warnings
from collections.abc import Callable
from pathlib import Path

from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.core.pickpoints import rejected_text
from mjx_pick.gui import jobs, views, workfolder
from mjx_pick.gui.formatting import MAP_HELP, fmt, md_text, stamp
from mjx_pick.gui.page.job_panel import JobPanel
from mjx_pick.gui.page.settings_form import SettingsForm
from mjx_pick.gui.page.widgets import (
    SearchProgress,
    checked,
    checked_or_empty,
    error_label,
    need_object,
    run_folder,
    warning_label,
)
from mjx_pick.gui.search import Search
from mjx_pick.gui.state import PageState


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
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.n = ui.number(
                    "pick-points", value=200, step=1, on_change=self.forget_map
                ).props('data-testid="n"')
                self.seed = ui.number("seed", value=0, step=1, on_change=self.forget_map)
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
                ui.button("Generate pick-points", on_click=self.generate).props(
                    'data-testid="generate"'
                )
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
        self.run_name.value = folder.name
        self.run_name.error = None
        obj = (config.get("object") or {}).get("name")
        if obj is not None and (self.state.obj is None or self.state.obj.name != obj):
            self.error.set_text(f"{folder.name} is a run of {obj}: import it in tab 1")
        return True

    def shown(self, job: jobs.Job) -> None:
        """An evaluate run the panel shows that this page did not start (after a reload,
        or chosen in the runs list): tab 3 shows its numbers and name as its folder
        records them, so that Start continues it where it can be continued."""
        if job.out is not None:
            self.show_recorded(job.out, job.argv)

    def pick_numbers(self) -> tuple[int, int] | None:
        n = checked(self.n, "n")
        seed = checked(self.seed, "seed")
        return None if n is None or seed is None else (n, seed)

    async def generate(self) -> None:
        """Sample the pick-points (in a worker thread) and draw them on the outline."""
        self.error.set_text("")
        if not need_object(self.state, self.error):
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
        """``mjx-pick evaluate`` with the page's object, settings and numbers."""
        self.error.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        settings = self.form.read()
        numbers = self.pick_numbers()
        # each by its one rule (core.numbers), as the CLI checks --traces and
        # --chunk-size: a value out of it is refused under its field, never changed
        traces = checked(self.traces, "n_traces")
        chunk_ok, chunk = checked_or_empty(self.chunk, "chunk_size")
        out = run_folder(self.state, self.run_name, resume=bool(self.resume.value))
        if settings is None or numbers is None or out is None or traces is None or not chunk_ok:
            return
        n, seed = numbers
        if chunk is None:  # the bar moves every 2 % of the pick-points the run will simulate
            obj = self.state.obj
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
        argv += ["--n", str(n), "--seed", str(seed), "--traces", str(traces)]
        argv += ["--chunk-size", str(chunk), "--no-progress", "--out", str(out)]
        if self.checks.value:
            argv += ["--step-check", "--stability-um", "1"]
        if self.resume.value:
            argv.append("--resume")
        self.run_summary.set_content("")

        job = jobs.Job(argv, self.state.log(out.name), out, n, chunk)
        self.panel.start(f"evaluate {out.name}", job, self.error)

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
