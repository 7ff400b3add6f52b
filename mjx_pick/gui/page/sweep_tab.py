"""The *Parameter sweep* tab: one parameter over start..end by step (``mjx-pick sweep``)."""

from __future__ import annotations

from pathlib import Path

from nicegui import background_tasks, run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.core.numbers import INPUTS
from mjx_pick.gui import forms, jobs, views, workfolder
from mjx_pick.gui.formatting import column_label, fmt, stamp
from mjx_pick.gui.grasp_input import ANTIPODAL, source_args
from mjx_pick.gui.page.job_panel import JobPanel
from mjx_pick.gui.page.settings_form import SettingsForm
from mjx_pick.gui.page.widgets import (
    checked,
    drawn_grasps_select,
    error_label,
    need_object,
    picture,
    run_folder,
    show_picture,
)
from mjx_pick.gui.state import PageState


class SweepTab:
    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        self.state, self.form, self.panel = state, form, panel
        panel.handle("sweep", self.ended)
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.param = ui.select(
                    forms.sweep_labels(),  # in words; the run's argument is the key
                    value="contact.pad_friction",
                    label="parameter",
                    with_input=True,
                    on_change=self.on_param,
                ).classes("w-full")
                self.start = ui.number("start", value=0.4, step=0.05, on_change=self.estimate)
                self.end = ui.number("end", value=1.0, step=0.05, on_change=self.estimate)
                self.step = ui.number("step", value=0.2, step=0.05, on_change=self.estimate)
                self.n = ui.number(
                    "simulations per value", value=100, step=1, on_change=self.estimate
                )
                self.source = drawn_grasps_select("sweep-grasps")
                self.source.on_value_change(self.estimate)
                self.count = ui.label("").props('data-testid="sweep-count"')
                self.name = ui.input("run folder name", value=f"sweep-{stamp()}")
                ui.button("Start sweep", on_click=self.start_sweep).props(
                    'data-testid="start-sweep"'
                )
                self.error = error_label().props('data-testid="sweep-error"')
            with ui.column().classes("grow"):
                self.table = ui.table(columns=[], rows=[], row_key="variant").props(
                    'dense data-testid="sweep-table"'
                )
                self.image = picture("w-full max-w-3xl")

    def on_param(self, _=None) -> None:
        """Another parameter: its own starting range (never the last one's numbers)."""
        if not self.param.value:
            return
        try:
            start, end, step = forms.sweep_range(self.param.value)
        except (ConfigError, StopIteration, KeyError):
            return
        # a whole number as one ("11", not "11.0")
        whole = [int(v) if float(v).is_integer() else v for v in (start, end, step)]
        self.start.value, self.end.value, self.step.value = whole
        for w in (self.start, self.end, self.step):
            w.props["step"] = step  # a number, as every numeric prop (never a string)
        self.estimate()

    def estimate(self, _=None) -> None:
        """How many simulations the sweep as set would run, before it starts."""
        values, _errors = forms.sweep_values(self.start.value, self.end.value, self.step.value)
        n = self.n.value
        if values is None or n is None or n != int(n) or n < 1:
            self.count.set_text("")
            return
        total = len(values) * int(n)
        each = "grasps" if self.source.value == ANTIPODAL else "pick-points"
        self.count.set_text(f"{len(values)} values x {int(n):,} {each} = {total:,} simulations")

    async def start_sweep(self) -> None:
        """``mjx-pick sweep`` of the chosen parameter with the page's object and settings."""
        self.error.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        fields = {"start": self.start, "end": self.end, "step": self.step}
        values, errors = forms.sweep_values(*(w.value for w in fields.values()))
        for key, widget in fields.items():
            widget.error = errors.get(key)
        n = checked(self.n, "n")
        if n is None:
            return
        settings = self.form.read()
        out = run_folder(self.state, self.name)
        if values is None or settings is None or out is None:
            return
        if not self.param.value:
            self.error.set_text("choose a parameter")
            return
        most = int(INPUTS["sweep_simulations"].hi)
        if len(values) * int(n) > most:
            self.n.error = (
                f"{len(values)} values x {int(n):,} = {len(values) * int(n):,} simulations: "
                f"at most {most:,} in one sweep"
            )
            return
        problem = forms.sweep_problem(settings, self.param.value, values)
        if problem:
            self.error.set_text(problem)
            return
        backend = self.form.backend.value
        sizes = {"variants": len(values), "n": int(n)}
        refusal = jobs.long_run("sweep", "this sweep", backend, settings.grasp, **sizes)
        yes = await self.panel.confirmed(refusal, self.error)
        if yes is None:
            return
        param = f"{self.param.value}=" + ",".join(repr(v) for v in values)
        argv = [
            "sweep",
            *self.state.obj_args,
            *self.form.cli_flags(settings, self.state.workdir, out),
        ]
        argv += source_args(self.source.value)
        argv += ["--param", param, "--n", str(int(n)), "--out", str(out), *yes]

        job = jobs.study_job(argv, self.state.log(out.name), out)
        self.panel.start(f"sweep {out.name} ({len(values)} values x {int(n)})", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        if progress.state == "complete":
            self.name.value = f"sweep-{stamp()}"  # this name is taken now
            self.show(job.out)

    def show(self, out: Path) -> None:
        """A complete sweep: one row per value, and its plot."""
        variants = workfolder.read_json(out / "variants.json", self.state.workdir)
        keys = [k for k in variants[0] if k not in ("success_ci", "score_ci")]
        labels = forms.sweep_labels()
        self.table.columns = [
            {"name": k, "label": labels.get(k) or column_label(k), "field": k} for k in keys
        ]
        self.table.rows = [{k: fmt(v[k]) for k in keys} for v in variants]
        self.table.update()
        background_tasks.create(self.draw(out, labels), name="sweep picture")

    async def draw(self, out: Path, labels: dict[str, str]) -> None:
        """The sweep's picture, drawn beside the server's event loop (matplotlib: every
        tab would wait for it otherwise)."""
        try:
            png = await run.io_bound(views.sweep_png, out, self.state.workdir, labels)
        except (OSError, ValueError) as err:  # a folder changed since it completed
            self.error.set_text(f"{self.state.where(out)}: its picture cannot be drawn ({err})")
            return
        show_picture(self.image, png)
