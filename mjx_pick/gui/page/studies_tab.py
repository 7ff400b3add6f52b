"""The *Studies* tab: compare grippers, robustness of a run's best pick-points, calibrate,
validate against physical trials.

Each study is a section (an expansion) and a class here; each runs its CLI command
(``compare``, ``robust``, ``calibrate``, ``validate``) with the settings of tab 2, the
first three on the object of tab 1. The robustness study reads the run open in tab 4; a
calibration's fitted contact parameters can be put into tab 2's form; a validation reads
an uploaded zip of a TRIALS.csv with its meshes (or a TRIALS.csv in the work folder).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.gui import forms, jobs, trials_input, workfolder
from mjx_pick.gui.formatting import fmt, md_text, stamp
from mjx_pick.gui.grasp_input import source_args
from mjx_pick.gui.page.job_panel import JobPanel
from mjx_pick.gui.page.settings_form import SettingsForm
from mjx_pick.gui.page.widgets import (
    checked,
    drawn_grasps_select,
    error_label,
    file_error_label,
    need_object,
    picture,
    received,
    run_folder,
    show_picture,
    show_rows,
    upload,
)
from mjx_pick.gui.state import PageState
from mjx_pick.gui.uploads import (
    OUTCOMES_MAX_BYTES,
    TRIALS_MAX_BYTES,
    check_outcomes_upload,
    outcomes_refused,
    save_upload,
    store_trials,
    trials_refused,
)


class StudiesTab:
    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        ui.label(
            "Each study runs on the object of tab 1 with the settings of tab 2, and writes "
            "the folder of its CLI command."
        ).classes("text-sm")
        with ui.expansion("Compare grippers", value=True).classes("w-full"):
            self.compare = CompareStudy(state, form, panel)
        with ui.expansion("Robustness of the best pick-points (run of tab 4)").classes("w-full"):
            self.robust = RobustStudy(state, form, panel)
        with ui.expansion("Calibrate contact parameters from measured outcomes").classes("w-full"):
            self.calibrate = CalibrationStudy(state, form, panel)
        with ui.expansion("Validate against physical trials (TRIALS.csv)").classes("w-full"):
            self.validate = ValidateStudy(state, form, panel)


class CompareStudy:
    """``mjx-pick compare``: presets (and tab 2's gripper) ranked on the same pick-points."""

    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        from mjx_pick.core.gripper import preset_names

        self.state, self.form, self.panel = state, form, panel
        panel.handle("compare", self.ended)
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.grippers = ui.select(
                    preset_names(),
                    value=["robotiq-2f85", "onrobot-rg2"],
                    multiple=True,
                    label="presets",
                ).classes("w-full")
                self.current = ui.checkbox("and the gripper of tab 2")
                self.n = ui.number("pick-points", value=200, step=1)
                self.source = drawn_grasps_select("compare-grasps", self.n)
                self.rank = ui.select(["success", "score"], value="success", label="rank by")
                self.name = ui.input("run folder name", value=f"compare-{stamp()}")
                ui.button("Start comparison", on_click=self.start).props(
                    'data-testid="start-compare"'
                )
                self.error = error_label().props('data-testid="compare-error"')
                self.note = ui.label("").props('data-testid="compare-note"')
            with ui.column().classes("grow"):
                self.table = ui.table(columns=[], rows=[], row_key="rank").props(
                    'dense data-testid="compare-table"'
                )
                self.image = picture("w-full max-w-3xl")

    async def start(self) -> None:
        self.error.set_text("")
        self.note.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        n = checked(self.n, "n")
        settings = self.form.read()
        out = run_folder(self.state, self.name)
        if n is None or settings is None or out is None:
            return
        flags = self.form.cli_flags(settings, self.state.workdir, out)
        names = list(self.grippers.value or [])
        if self.current.value:
            names.append(flags[flags.index("--gripper-file") + 1])
        if len(names) < 2:
            self.error.set_text("choose at least two grippers")
            return
        sizes = {"variants": len(names), "n": n}
        backend = self.form.backend.value
        refusal = jobs.long_run("compare", "this comparison", backend, settings.grasp, **sizes)
        yes = await self.panel.confirmed(refusal, self.error)
        if yes is None:
            return
        argv = ["compare", *self.state.obj_args, *flags, "--grippers", ",".join(names)]
        argv += source_args(self.source.value)
        argv += ["--n", str(n), "--rank-by", self.rank.value, "--out", str(out), *yes]

        job = jobs.study_job(argv, self.state.log(out.name), out)
        self.panel.start(f"compare {out.name} ({len(names)} grippers x {n})", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        if progress.state == "complete":
            self.name.value = f"compare-{stamp()}"  # this name is taken now
            from mjx_pick.studies.comparison import unequal_forces

            workdir = self.state.workdir
            rows = workfolder.read_json(job.out / "ranking.json", workdir)
            keys = ["rank", "gripper", "success_rate", "success_ci", "score_mean"]
            show_rows(self.table, rows, keys + ["grip_force_n", "feasible", "p_vs_best"])
            self.note.set_text(unequal_forces(rows))
            show_picture(self.image, workfolder.read_bytes(job.out / "maps.png", workdir))


class RobustStudy:
    """``mjx-pick robust``: the open run's best pick-points under position and yaw error."""

    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        self.state, self.form, self.panel = state, form, panel
        panel.handle("robust", self.ended)
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.k = ui.number("top pick-points", value=10, step=1)
                self.m = ui.number("perturbed draws each", value=32, step=1)
                self.sigma_xy = ui.number("position error sigma (mm)", value=2.0, step=0.5)
                self.sigma_yaw = ui.number("yaw error sigma (deg)", value=3.0, step=0.5)
                ui.button("Start robustness study", on_click=self.start).props(
                    'data-testid="start-robust"'
                )
                self.error = error_label().props('data-testid="robust-error"')
            with ui.column().classes("grow"):
                self.table = ui.table(columns=[], rows=[], row_key="rank").props(
                    'dense data-testid="robust-table"'
                )

    async def start(self) -> None:
        self.error.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        opened = self.state.run
        if opened is None:
            self.error.set_text("open an evaluate output folder in tab 4 first")
            return
        k = checked(self.k, "top_k")
        m = checked(self.m, "m")
        sig = [checked(self.sigma_xy, "sigma_xy_mm"), checked(self.sigma_yaw, "sigma_yaw_deg")]
        settings = self.form.read()
        if (
            k is None
            or m is None
            or settings is None
            or self.sigma_xy.error
            or self.sigma_yaw.error
        ):
            return
        obj = self.state.obj
        s = opened.summary
        if (s.get("object"), s.get("gripper")) != (obj.name, settings.gripper.name):
            self.error.set_text(
                f"the run of tab 4 is of {s.get('object')} / {s.get('gripper')}: import that "
                f"object and set that gripper (now {obj.name} / {settings.gripper.name})"
            )
            return
        sizes = {"top_k": k, "m": m, "n": None}  # ranked from the run's results
        backend = self.form.backend.value
        what = "this robustness study"
        refusal = jobs.long_run("robust", what, backend, settings.grasp, **sizes)
        yes = await self.panel.confirmed(refusal, self.error)
        if yes is None:
            return
        out = opened.path
        argv = ["robust", *self.state.obj_args]
        argv += self.form.cli_flags(settings, self.state.workdir, out)
        argv += ["--results", str(out), "--top-k", str(k), "--m", str(m)]
        argv += ["--sigma-xy-mm", repr(float(sig[0])), "--sigma-yaw-deg", repr(float(sig[1]))]
        # robust keeps its chunks in the run's folder: a cancelled one started again
        # continues, and one complete with these settings is read back
        argv += ["--out", str(out), "--resume", *yes]

        job = jobs.study_job(argv, self.state.log(f"{out.name}-robust"), out)
        self.panel.start(f"robust {out.name} (top {k} x {m} draws)", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        if progress.state == "complete":
            rows = workfolder.read_json(job.out / "robustness.json", self.state.workdir)["ranking"]
            keys = ["rank", "pick_id", "x_mm", "y_mm", "yaw_deg", "robust_p"]
            show_rows(self.table, rows, keys + ["robust_ci_low", "landed"])


class CalibrationStudy:
    """``mjx-pick calibrate``: contact parameters fitted to an uploaded outcomes CSV."""

    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        from mjx_pick.studies.calibration import FITTABLE

        self.state, self.form, self.panel = state, form, panel
        panel.handle("calibrate", self.ended)
        self.outcomes_path: Path | None = None
        self.fitted_contact: Path | None = None
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                ui.label(
                    "A CSV of tested pick-points and their outcomes (format: "
                    "mjx_pick/assets/outcomes/README.md), up to 5 MB."
                ).classes("text-sm")
                self.upload = upload(
                    "upload outcomes CSV",
                    ".csv",
                    OUTCOMES_MAX_BYTES,
                    self.on_upload,
                    self.refuse_upload,
                    outcomes_refused,
                    "outcomes-upload",
                ).classes("w-full")
                self.upload_error = error_label().props('data-testid="outcomes-error"')
                self.params = ui.select(
                    list(FITTABLE),
                    value=["pad_friction"],
                    multiple=True,
                    label="parameters to fit",
                ).classes("w-full")
                self.steps = ui.number("optimiser steps", value=60, step=1)
                self.name = ui.input("run folder name", value=f"calibrate-{stamp()}")
                ui.button("Start calibration", on_click=self.start).props(
                    'data-testid="start-calibrate"'
                )
                self.error = error_label().props('data-testid="calibrate-error"')
            with ui.column().classes("grow"):
                self.info = ui.markdown("").props('data-testid="calibrate-info"')
                self.use = ui.button(
                    "Use the fitted contact parameters in tab 2", on_click=self.use_fitted
                ).props('data-testid="use-calibration"')
                self.use.set_visibility(False)
                self.image = picture()

    async def on_upload(self, e) -> None:
        from mjx_pick.studies.calibration import read_outcomes

        self.upload_error.set_text("")
        got = await received(e, self.upload, check_outcomes_upload, self.refuse_upload)
        if got is None:
            return
        name, data = got
        try:
            path = await run.io_bound(
                save_upload, data, name, self.state.uploads, self.state.workdir
            )
            outcomes = await run.io_bound(read_outcomes, str(path))
        except ConfigError as err:
            self.refuse_upload(str(err))
            return
        self.outcomes_path = path
        self.info.set_content(
            f"outcomes: {md_text(name)}, {len(outcomes)} tested pick-points "
            f"({int(np.sum(outcomes.trials))} trials)"
        )

    def refuse_upload(self, why: str) -> None:
        """An outcomes file refused (by the browser or here): said until the next
        upload, and it replaces the one before -- a calibration never runs on the
        earlier file."""
        self.upload_error.set_text(why)
        self.outcomes_path = None
        self.info.set_content("")

    def start(self) -> None:
        self.error.set_text("")
        if self.panel.busy(self.error) or not need_object(self.state, self.error):
            return
        if self.outcomes_path is None:
            self.error.set_text("upload an outcomes CSV first")
            return
        steps = checked(self.steps, "steps")
        settings = self.form.read()
        out = run_folder(self.state, self.name)
        params = list(self.params.value or [])
        self.params.error = None if params else "choose at least one parameter"
        if steps is None or settings is None or out is None or not params:
            return
        argv = ["calibrate", str(self.outcomes_path), *self.state.obj_args]
        argv += self.form.cli_flags(settings, self.state.workdir, out)
        argv += ["--params", ",".join(params), "--steps", str(steps), "--log-every", "1"]
        argv += ["--out", str(out)]

        job = jobs.Job(
            argv,
            self.state.log(out.name),
            out,
            steps,
            steps_logged=r"(?m)^step\s+(\d+)\s",
            unit="steps",
        )
        self.panel.start(f"calibrate {out.name} ({steps} steps)", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        if progress.state == "complete":
            self.name.value = f"calibrate-{stamp()}"  # this name is taken now
            self.show(job.out)

    def show(self, out: Path) -> None:
        """A complete calibration: initial -> fitted values, the loss plot, Use button."""
        workdir = self.state.workdir
        c = workfolder.read_json(out / "calibration.json", workdir)
        lines = [f"**{out.name}**: fitted contact parameters (`{out / 'contact.toml'}`)", ""]
        lines += [
            f"- `{k}`: {fmt(c['initial'][k], 4)} -> **{fmt(c['fitted'][k], 4)}**"
            for k in c["parameters"]
        ]
        self.info.set_content("\n".join(lines))
        show_picture(self.image, workfolder.read_bytes(out / "loss.png", workdir))
        self.fitted_contact = out / "contact.toml"
        self.use.set_visibility(True)

    def use_fitted(self) -> None:
        """The fitted contact parameters into tab 2's form, for every later run."""
        from mjx_pick.core.physics import load_contact

        try:
            contact, _ = load_contact(workfolder.confined(self.fitted_contact, self.state.workdir))
        except ConfigError as err:
            self.error.set_text(str(err))
            return
        self.form.adopt_contact(contact)
        self.info.set_content(self.info.content + "\n\nIn use in tab 2 (all fitted parameters).")


class ValidateStudy:
    """``mjx-pick validate``: each physical trial's grasp simulated, its label held
    against the real outcome -- accuracy, precision, recall, F1 with their intervals,
    the confusion matrix, per object, the checks' rejections (validation.json)."""

    def __init__(self, state: PageState, form: SettingsForm, panel: JobPanel):
        self.state, self.form, self.panel = state, form, panel
        panel.handle("validate", self.ended)
        self.trials: Path | None = None  # the TRIALS.csv checked, inside the work folder
        self.summary: dict | None = None  # check_trials's
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                ui.label(
                    "A zip of a TRIALS.csv (object, mass_g, gripper, object_pose, "
                    "grasp_pose, depth_mm, success, trial: docs/formats.md) with the meshes "
                    "and gripper TOMLs it names, as it names them, up to 50 MB; or a "
                    "TRIALS.csv already in the work folder. Each trial's gripper is its "
                    "row's; the contact settings and the backend are tab 2's, the procedure "
                    "each gripper's defaults."
                ).classes("text-sm")
                self.upload = upload(
                    "upload trials (zip)",
                    ".zip",
                    TRIALS_MAX_BYTES,
                    self.on_upload,
                    self.refuse,
                    trials_refused,
                    "trials-upload",
                ).classes("w-full")
                with ui.row().classes("w-full items-end no-wrap"):
                    self.in_folder = ui.input("or a TRIALS.csv in the work folder").classes("grow")
                    ui.button("Use it", on_click=self.use_in_folder).props(
                        'flat dense data-testid="trials-use"'
                    )
                self.upload_error = file_error_label().props('data-testid="trials-error"')
                self.info = ui.label("").classes("text-sm").props('data-testid="trials-info"')
                self.unit = ui.select(["m", "mm"], value="m", label="mesh unit").classes("w-40")
                self.seed = ui.number("seed of the intervals' bootstrap", value=0, step=1)
                self.name = ui.input("run folder name", value=f"validate-{stamp()}")
                ui.button("Start validation", on_click=self.start).props(
                    'data-testid="start-validate"'
                )
                self.error = error_label().props('data-testid="validate-error"')
            with ui.column().classes("grow"):
                self.headline = ui.markdown("").props('data-testid="validate-info"')
                self.figures = ui.table(columns=[], rows=[], row_key="figure").props(
                    'dense data-testid="validate-figures"'
                )
                self.confusion = ui.table(columns=[], rows=[], row_key="real").props(
                    'dense data-testid="validate-confusion"'
                )
                self.objects = ui.table(columns=[], rows=[], row_key="object").props(
                    'dense data-testid="validate-objects"'
                )
                self.checks = ui.label("").classes("text-sm").props('data-testid="validate-checks"')
                for table in (self.figures, self.confusion, self.objects):
                    table.set_visibility(False)

    async def on_upload(self, e) -> None:
        """An uploaded zip: unpacked into the work folder (checked member by member
        first), its TRIALS.csv read and every file it names found inside."""
        self.upload_error.set_text("")
        got = await received(e, self.upload, lambda n, d: trials_refused(n, len(d)), self.refuse)
        if got is None:
            return
        name, data = got
        folder = self.state.workdir / "inputs" / "trials"
        try:
            csv = await run.io_bound(store_trials, data, name, folder, self.state.workdir)
        except ConfigError as err:
            self.refuse(str(err))
            return
        await self.take(csv, f"{name}: {csv.name}")

    async def use_in_folder(self) -> None:
        """A TRIALS.csv the user put into the work folder (a large set, copied in)."""
        self.upload_error.set_text("")
        text = (self.in_folder.value or "").strip()
        path = self.state.inside(text)
        if path is None or not path.is_file():
            self.refuse(
                f"{text or '(empty)'}: no file of this name inside the work folder "
                f"({self.state.workdir}); give a TRIALS.csv's path relative to it"
            )
            return
        await self.take(path, text)

    async def take(self, csv: Path, shown: str) -> None:
        """The trials of csv, checked (shown: its name in the page), or refused."""
        try:
            summary = await run.io_bound(trials_input.check_trials, csv, self.state.workdir, shown)
        except ConfigError as err:  # OutsideWorkFolder too
            self.refuse(str(err))
            return
        self.trials, self.summary = csv, summary
        self.info.set_text(trials_input.trials_text(shown, summary))

    def refuse(self, why: str) -> None:
        """Trials refused (by the browser or here): said until the next, and they
        replace the ones before -- a validation never runs on the earlier file."""
        self.upload_error.set_text(why)
        self.trials = self.summary = None
        self.info.set_text("")

    async def start(self) -> None:
        self.error.set_text("")
        if self.panel.busy(self.error):
            return
        if self.trials is None:
            self.error.set_text("upload trials (or give a TRIALS.csv in the work folder) first")
            return
        seed = checked(self.seed, "seed")
        settings = self.form.read()
        out = run_folder(self.state, self.name)
        if seed is None or settings is None or out is None:
            return
        try:  # read again as it will run: the files may have changed since
            self.summary = await run.io_bound(
                trials_input.check_trials, self.trials, self.state.workdir, self.trials.name
            )
        except ConfigError as err:
            self.refuse(str(err))
            return
        backend = self.form.backend.value
        # each distinct grasp is simulated once (its repeats share its label), as the
        # CLI counts it
        grasps = self.summary["grasps"]
        refusal = jobs.long_run("evaluate", "this validate", backend, None, n=grasps)
        yes = await self.panel.confirmed(refusal, self.error)
        if yes is None:
            return
        paths = forms.write_inputs(settings, self.state.workdir / "inputs" / out.name)
        argv = ["validate", str(self.trials), "--unit", self.unit.value, "--seed", str(seed)]
        argv += ["--contact", str(paths["contact"]), "--backend", backend]
        argv += ["--out", str(out), *yes]

        job = jobs.Job(argv, self.state.log(out.name), out, unit="grasps")
        self.panel.start(f"validate {out.name} ({grasps} grasps)", job, self.error)

    def ended(self, job: jobs.Job, progress: jobs.Progress) -> None:
        if progress.state == "complete":
            self.name.value = f"validate-{stamp()}"  # this name is taken now
            self.show(job.out)

    def show(self, out: Path) -> None:
        """A complete validation: its figures with their intervals, the confusion
        matrix, each object's figures and the checks' rejections."""
        r = workfolder.read_json(out / "validation.json", self.state.workdir)
        self.headline.set_content(
            f"**{md_text(out.name)}**: {r['n']:,} trials ({r['grasps']:,} grasps), real "
            f"success rate {fmt(float(r['real_success_rate']))}; 95 % intervals from a "
            "bootstrap over grasps (a grasp's repeats together); a success is the positive "
            "class"
        )
        tables = (
            (self.figures, ["figure", "value", "interval"], trials_input.figure_rows(r)),
            (
                self.confusion,
                ["real", "sim_success", "sim_failure"],
                trials_input.confusion_rows(r),
            ),
            (
                self.objects,
                ["object", "trials", "grasps", "accuracy", "precision", "recall", "f1"]
                + ["real_success_rate"],
                trials_input.object_rows(r),
            ),
        )
        labels = {
            "figure": "",
            "interval": "95 % interval",
            "real": "trials",
            "sim_success": "simulated success",
            "sim_failure": "simulated failure",
            "f1": "F1",
            "real_success_rate": "real success rate",
        }
        for table, keys, rows in tables:
            table.columns = [
                {"name": k, "label": labels.get(k, k), "field": k, "align": "left"} for k in keys
            ]
            table.rows = rows
            table.update()
            table.set_visibility(True)
        self.checks.set_text(trials_input.checks_text(r))
