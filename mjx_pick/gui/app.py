"""The web page: the paper's four tabs (its Fig. 10) and its parameter-sweep tab.

Built with NiceGUI (docs/gui.md says why). Every tab is a thin layer over the public
API: short steps (importing an object, checking and generating pick-points, simulating
one test pick) run in a worker thread of this process; long runs (evaluate, sweep,
report) are the CLI command itself in a child process (:mod:`mjx_pick.gui.jobs`), so
their output folders are the CLI's.
"""

from __future__ import annotations

import datetime
import json
import math
import re
from pathlib import Path

import numpy as np

from mjx_pick.config import ConfigError, write_atomic
from mjx_pick.gui import forms, jobs, views
from mjx_pick.objects import IMAGE_SUFFIXES, MESH_SUFFIXES

IMAGE_MAX_BYTES = 20 * 2**20
MESH_MAX_BYTES = 50 * 2**20
TOML_MAX_BYTES = 64 * 2**10
OUTCOMES_MAX_BYTES = 5 * 2**20
UPLOAD_TYPES = IMAGE_SUFFIXES + MESH_SUFFIXES
NAME_OK = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,79}$")
TABLE_COLUMNS = (
    ("rank", "rank"),
    ("pick_id", "pick"),
    ("x_mm", "x, mm"),
    ("y_mm", "y, mm"),
    ("yaw_deg", "yaw, deg"),
    ("score", "score"),
    ("success", "success"),
    ("failure", "outcome"),
    ("t_grasp", "t_grasp"),
    ("phi_max_deg", "phi_max, deg"),
    ("t_grasp_nc", "t_grasp_nc"),
    ("traced", "traced"),
)


def _stamp() -> str:
    return datetime.datetime.now().strftime("%Y%m%d-%H%M%S")


def _fmt(v, digits: int = 3) -> str:
    if isinstance(v, bool) or v is None:
        return str(v)
    if isinstance(v, float):
        return "NaN" if math.isnan(v) else f"{v:.{digits}f}"
    return str(v)


def _fmt_cell(v) -> str:
    if isinstance(v, list | tuple):
        return "[" + ", ".join(_fmt(x) for x in v) + "]"
    return _fmt(v)


def save_upload(data: bytes, name: str, folder: Path) -> Path:
    """An uploaded file under folder, atomically; never replaces another file's content."""
    stem = re.sub(r"[^A-Za-z0-9._-]+", "_", Path(name).stem)[:60] or "upload"
    suffix = Path(name).suffix.lower()
    for k in range(1000):
        path = folder / (f"{stem}{suffix}" if k == 0 else f"{stem}-{k + 1}{suffix}")
        if not path.exists():
            return write_atomic(path, data)
        if path.read_bytes() == data:
            return path  # the same file uploaded again
    raise ConfigError(f"too many uploads named {name!r} in {folder}")


def check_upload(name: str, size: int, data: bytes | None = None) -> str:
    """Why an uploaded object file is refused ('' when it is accepted)."""
    suffix = Path(name).suffix.lower()
    if suffix not in UPLOAD_TYPES:
        return (
            f"{name}: not an image ({', '.join(IMAGE_SUFFIXES)}) or a mesh "
            f"({', '.join(MESH_SUFFIXES)})"
        )
    limit = IMAGE_MAX_BYTES if suffix in IMAGE_SUFFIXES else MESH_MAX_BYTES
    if size > limit:
        return f"{name}: {size / 2**20:.1f} MB is too large (at most {limit // 2**20} MB)"
    if size == 0:
        return f"{name}: the file is empty"
    if data is not None and suffix in IMAGE_SUFFIXES:
        import cv2

        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if img is None:
            return f"{name}: cannot be read as an image (is it really a {suffix[1:].upper()}?)"
    return ""


class Page:
    """One browser tab's state and widgets."""

    def __init__(self, workdir: Path, started: set | None = None):
        """started: the server's set of the jobs it started that may still run."""
        self.workdir = workdir
        self.started = started if started is not None else set()
        self.uploads = workdir / "inputs" / "uploads"
        self.obj = None
        self.obj_args: list[str] = []
        self.upload_path: Path | None = None
        self.base_gripper = None
        self.base_contact = None  # calibrated contact parameters, once adopted
        self.outcomes_path: Path | None = None
        self.job: jobs.Job | None = None
        self.on_job_end = None
        self.run = None

    # ------------------------------------------------------------------ layout
    def build(self) -> None:
        from nicegui import ui

        ui.page_title("mjx-pick")
        with ui.header().classes("items-center py-1"):
            ui.label("mjx-pick: pick-point evaluation").classes("text-lg")
            ui.label(f"runs in {self.workdir}").classes("text-xs opacity-80")
        with ui.tabs().classes("w-full") as tabs:
            t1 = ui.tab("import", "1 Import object model")
            t2 = ui.tab("gripper", "2 Set gripper parameters")
            t3 = ui.tab("generate", "3 Generate input data")
            t4 = ui.tab("analyze", "4 Analyze results")
            t5 = ui.tab("sweep", "Parameter sweep")
            t6 = ui.tab("studies", "Studies")
        self.tabs = tabs
        self.job_panel()
        with ui.tab_panels(tabs, value=t1).classes("w-full"):
            with ui.tab_panel(t1):
                self.import_tab()
            with ui.tab_panel(t2):
                self.gripper_tab()
            with ui.tab_panel(t3):
                self.generate_tab()
            with ui.tab_panel(t4):
                self.analyze_tab()
            with ui.tab_panel(t5):
                self.sweep_tab()
            with ui.tab_panel(t6):
                self.studies_tab()
        ui.timer(0.5, self.poll_job)
        # a bug in a handler: one line in the page, the traceback only in the server log
        ui.on_exception(
            lambda e: ui.notify(
                f"unexpected error: {type(e).__name__}: {str(e)[:300]} (details in the "
                "server's log)",
                type="negative",
                multi_line=True,
            )
        )

    def job_panel(self) -> None:
        """The running job: progress bar, rate, time left, cancel, the CLI command."""
        from nicegui import ui

        with ui.card().classes("w-full") as card:
            with ui.row().classes("items-center w-full"):
                self.job_title = ui.label("").classes("font-bold").props('data-testid="job-title"')
                self.job_status = ui.label("").props('data-testid="job-status"')
                ui.space()
                self.cancel_button = ui.button("Cancel", on_click=self.cancel_job, color="red")
            self.job_bar = ui.linear_progress(value=0, show_value=False).props("size=12px")
            self.job_command = ui.code("", language="bash").classes("w-full text-xs")
        card.set_visibility(False)
        self.job_card = card

    def error_label(self):
        from nicegui import ui

        return ui.label("").classes("text-negative text-sm").props('role="alert"')

    # ------------------------------------------------------------ tab 1: object
    def import_tab(self) -> None:
        from nicegui import ui

        from mjx_pick.objects import asset_manifest

        self.manifest = asset_manifest()
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                ui.label(
                    "A top-down image (PNG/JPG, up to 20 MB), a mesh (STL/OBJ/PLY, up "
                    "to 50 MB), or a shipped object."
                ).classes("text-sm")
                self.upload = (
                    ui.upload(
                        label="upload image or mesh",
                        auto_upload=True,
                        max_file_size=MESH_MAX_BYTES,
                        on_upload=self.on_object_upload,
                        on_rejected=lambda: self.upload_error.set_text(
                            "file refused: upload an image ("
                            + ", ".join(IMAGE_SUFFIXES)
                            + f", up to {IMAGE_MAX_BYTES // 2**20} MB) or a mesh ("
                            + ", ".join(MESH_SUFFIXES)
                            + f", up to {MESH_MAX_BYTES // 2**20} MB)"
                        ),
                    )
                    .props('accept="' + ",".join(UPLOAD_TYPES) + '" data-testid="object-upload"')
                    .classes("w-full")
                )
                self.upload_error = self.error_label().props('data-testid="upload-error"')
                self.asset = ui.select(
                    ["(uploaded file)", *sorted(self.manifest)],
                    value="block",
                    label="object",
                    on_change=self.on_asset,
                )
                self.px_per_mm = ui.number("image scale (px per mm)", value=10.0, step=0.5)
                self.thickness = ui.number("thickness (mm)", value=20.0, step=1)
                self.mass = ui.number("mass (g)", value=43.2, step=1)
                self.unit = ui.select(["mm", "m"], value="mm", label="mesh unit").classes("w-40")
                self.on_asset()
                ui.button("Import object", on_click=self.import_object).props(
                    'data-testid="import"'
                )
                self.import_error = self.error_label().props('data-testid="import-error"')
            with ui.column().classes("grow"):
                self.object_info = ui.label("No object imported yet.").props(
                    'data-testid="object-info"'
                )
                self.object_image = (
                    ui.image()
                    .props("no-transition no-spinner")
                    .classes("w-full max-w-3xl")
                    .props('data-testid="object-image"')
                )
                self.object_image.set_visibility(False)

    def on_asset(self, _=None) -> None:
        name = self.asset.value
        if name in getattr(self, "manifest", {}):
            entry = self.manifest[name]
            self.px_per_mm.value = entry["px_per_mm"]
            self.thickness.value = entry["thickness_mm"]
            self.mass.value = round(entry["mass_g"], 3)

    async def on_object_upload(self, e) -> None:
        from nicegui import run

        self.upload_error.set_text("")
        name = e.file.name
        data = await e.file.read()
        self.upload.reset()  # a corrected file of the same name may follow
        problem = check_upload(name, len(data), data)
        if problem:
            self.upload_error.set_text(problem)
            return
        try:
            self.upload_path = await run.io_bound(save_upload, data, name, self.uploads)
        except (OSError, ConfigError) as err:
            self.upload_error.set_text(f"{name}: cannot be stored ({err})")
            return
        self.asset.value = "(uploaded file)"
        self.upload_error.set_text("")
        self.object_info.set_text(
            f"uploaded {name}: set its scale, thickness and mass, then Import object"
        )

    def object_source(self) -> tuple[str, Path | None]:
        if self.asset.value == "(uploaded file)":
            if self.upload_path is None:
                raise ConfigError("upload an image or a mesh first, or choose a shipped object")
            return str(self.upload_path), self.upload_path
        from importlib import resources

        entry = self.manifest[self.asset.value]
        image = Path(str(resources.files("mjx_pick.assets") / "objects" / entry["image"]))
        return self.asset.value, image

    def object_fields(self) -> dict:
        return {
            "px_per_mm": self.px_per_mm,
            "thickness_mm": self.thickness,
            "mass_g": self.mass,
        }

    async def import_object(self) -> None:
        from nicegui import run

        from mjx_pick.objects import load_object

        self.import_error.set_text("")
        for w in self.object_fields().values():
            w.error = None
        try:
            source, image = self.object_source()
        except ConfigError as err:
            self.import_error.set_text(str(err))
            return
        is_mesh = Path(source).suffix.lower() in MESH_SUFFIXES
        values = {k: w.value for k, w in self.object_fields().items()}
        needed = ("mass_g",) if is_mesh else ("px_per_mm", "thickness_mm", "mass_g")
        missing = [k for k in needed if values[k] is None]
        for k in missing:
            self.object_fields()[k].error = f"{k} is required"
        if missing:
            return
        kwargs = {"mass_g": float(values["mass_g"])}
        args = [source, "--mass-g", repr(float(values["mass_g"]))]
        if is_mesh:
            kwargs["unit"] = self.unit.value
            args += ["--unit", self.unit.value]
            image = None
        else:
            kwargs["px_per_mm"] = float(values["px_per_mm"])
            kwargs["thickness_mm"] = float(values["thickness_mm"])
            args += ["--px-per-mm", repr(kwargs["px_per_mm"])]
            args += ["--thickness-mm", repr(kwargs["thickness_mm"])]
        self.object_info.set_text("importing ...")
        try:
            obj = await run.io_bound(load_object, source, **kwargs)
            png = await run.io_bound(views.object_png, obj, image)
        except ConfigError as err:
            self.object_info.set_text("No object imported.")
            self.show_object_error(str(err))
            return
        except Exception as err:  # noqa: BLE001 - a bad file must not show a traceback
            self.object_info.set_text("No object imported.")
            self.import_error.set_text(f"{Path(source).name}: cannot be imported ({err})")
            return
        self.obj, self.obj_args = obj, args
        self.object_info.set_text(
            f"{obj.name}: outline {obj.area_mm2:.0f} mm^2, length {obj.length_mm:.1f} mm, "
            f"height {obj.height_mm:g} mm, mass {obj.mass_kg * 1e3:.1f} g"
        )
        self.object_image.set_source(views.data_uri(png, "image/png"))
        self.object_image.set_visibility(True)

    def show_object_error(self, message: str) -> None:
        for key, widget in self.object_fields().items():
            if f"object.{key}" in message or message.startswith(key):
                widget.error = message
                return
        self.import_error.set_text(message)

    # ----------------------------------------------------------- tab 2: gripper
    def gripper_tab(self) -> None:
        from nicegui import ui

        from mjx_pick.gripper import load_gripper, preset_names

        self.inputs: dict[str, object] = {}
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-[44rem]"):
                with ui.row().classes("items-end"):
                    self.preset = ui.select(
                        preset_names(),
                        value="robotiq-2f85",
                        label="gripper preset",
                        on_change=self.on_preset,
                    ).classes("w-56")
                    self.backend = ui.select(
                        ["auto", "mujoco", "warp", "mjx"], value="mujoco", label="backend"
                    ).classes("w-40")
                with ui.row().classes("items-center"):
                    self.toml_upload = (
                        ui.upload(
                            label="or load a gripper TOML",
                            auto_upload=True,
                            max_file_size=TOML_MAX_BYTES,
                            on_upload=self.on_gripper_toml,
                            on_rejected=lambda: self.toml_error.set_text(
                                "file refused: a .toml file of at most "
                                f"{TOML_MAX_BYTES // 2**10} KB"
                            ),
                        )
                        .props('accept=".toml" data-testid="gripper-upload"')
                        .classes("w-72")
                    )
                    self.toml_error = self.error_label().props('data-testid="toml-error"')
                self.settings_error = self.error_label()
                for title, group in (
                    ("Gripper", forms.GRIPPER_FIELDS),
                    ("Pick-points", forms.PICK_FIELDS),
                    ("Procedure (force controller, lift)", forms.PROCEDURE_FIELDS),
                    ("Contact", forms.CONTACT_FIELDS),
                ):
                    ui.label(title).classes("font-bold mt-2")
                    with ui.grid(columns=3).classes("w-full gap-x-4 gap-y-0"):
                        for f in group:
                            label = f"{f.label} ({f.unit})" if f.unit else f.label
                            self.inputs[f.key] = ui.number(label, step=f.step).props(
                                f'data-testid="{f.key}"'
                            )
                self.base_gripper = load_gripper("robotiq-2f85")
                self.fill_settings(self.base_gripper)
            with ui.column().classes("grow"):
                ui.label("Test simulation of one pick-point").classes("font-bold")
                with ui.row():
                    self.test_x = ui.number("x (mm)", value=0.0, step=1).classes("w-24")
                    self.test_y = ui.number("y (mm)", value=0.0, step=1).classes("w-24")
                    self.test_yaw = ui.number("yaw (deg)", value=0.0, step=5).classes("w-24")
                ui.button("Test simulation", on_click=self.test_pick).props(
                    'data-testid="test-pick"'
                )
                self.test_error = self.error_label()
                self.test_info = ui.markdown("").props('data-testid="test-info"')
                self.test_plot = (
                    ui.image().props("no-transition no-spinner").classes("w-full max-w-2xl")
                )
                self.test_plot.set_visibility(False)

    def fill_settings(self, gripper) -> None:
        for key, value in forms.defaults(gripper).items():
            if key.startswith("gripper.") or not self.inputs[key].value:
                self.inputs[key].value = value
            self.inputs[key].error = None

    def on_preset(self, _=None) -> None:
        from mjx_pick.gripper import load_gripper

        self.base_gripper = load_gripper(self.preset.value)
        self.fill_settings(self.base_gripper)
        # the preset's force and speed ranges bound F_d and the closing speed
        g = self.base_gripper
        f_d = self.inputs["grasp.grip_force_n"]
        f_d.value = min(max(f_d.value or 0, g.force_min_n), g.force_max_n)
        v = self.inputs["grasp.closing_speed_mm_s"]
        v.value = min(max(v.value or 0, g.speed_min_mm_s), g.speed_max_mm_s)

    async def on_gripper_toml(self, e) -> None:
        self.toml_error.set_text("")
        name = e.file.name
        data = await e.file.read()
        self.toml_upload.reset()  # a corrected file of the same name may follow
        if not name.lower().endswith(".toml"):
            self.toml_error.set_text(f"{name}: not a .toml file")
            return
        if len(data) > TOML_MAX_BYTES:
            self.toml_error.set_text(f"{name}: larger than {TOML_MAX_BYTES // 2**10} KB")
            return
        try:
            gripper = forms.gripper_from_toml(data.decode("utf-8"), where=name)
        except UnicodeDecodeError:
            self.toml_error.set_text(f"{name}: not a UTF-8 text file")
            return
        except ConfigError as err:
            self.toml_error.set_text(str(err))
            return
        self.base_gripper = gripper
        self.fill_settings(gripper)
        self.toml_error.set_text("")

    def read_settings(self) -> forms.Settings | None:
        """The settings on the gripper tab, or None with each error next to its field."""
        values = {k: w.value for k, w in self.inputs.items()}
        settings, errors = forms.build(values, self.base_gripper, self.base_contact)
        for key, widget in self.inputs.items():
            widget.error = errors.get(key)
        self.settings_error.set_text(errors.get("", ""))
        if settings is None:
            self.tabs.set_value("gripper")
        return settings

    def need_object(self, where) -> bool:
        if self.obj is None:
            where.set_text("import an object first (tab 1)")
            return False
        return True

    async def test_pick(self) -> None:
        from nicegui import run

        self.test_error.set_text("")
        if not self.need_object(self.test_error):
            return
        settings = self.read_settings()
        if settings is None:
            return
        pose = [self.test_x.value, self.test_y.value, self.test_yaw.value]
        if any(v is None for v in pose):
            self.test_error.set_text("give x, y and yaw of the test pick-point")
            return
        self.test_info.set_content("simulating one pick-point ...")
        try:
            result = await run.io_bound(
                test_simulation, self.obj, settings, *map(float, pose), self.backend.value
            )
        except ConfigError as err:
            self.test_info.set_content("")
            self.test_error.set_text(str(err))
            return
        self.test_info.set_content(result["text"])
        if result["plot"] is not None:
            self.test_plot.set_source(views.data_uri(result["plot"], "image/png"))
        self.test_plot.set_visibility(result["plot"] is not None)

    # ---------------------------------------------------------- tab 3: generate
    def generate_tab(self) -> None:
        from nicegui import ui

        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.n = ui.number("pick-points", value=200, step=1, min=1).props('data-testid="n"')
                self.seed = ui.number("seed", value=0, step=1)
                self.traces = ui.number("traced best and worst (force plots)", value=3, step=1)
                self.chunk = ui.number(
                    "chunk (pick-points per saved part; empty: automatic)", value=None, step=1
                )
                self.run_name = ui.input("run folder name", value=f"evaluate-{_stamp()}")
                self.resume = ui.checkbox("resume an interrupted run of this folder")
                ui.button("Generate pick-points", on_click=self.generate).props(
                    'data-testid="generate"'
                )
                ui.button("Start batch simulation", on_click=self.start_evaluate).props(
                    'data-testid="start-batch"'
                )
                self.generate_error = self.error_label().props('data-testid="generate-error"')
            with ui.column().classes("grow"):
                self.picks_info = ui.label("").props('data-testid="picks-info"')
                self.picks_image = (
                    ui.image().props("no-transition no-spinner").classes("w-full max-w-2xl")
                )
                self.picks_image.set_visibility(False)
                self.run_summary = ui.markdown("").props('data-testid="run-summary"')

    def pick_numbers(self) -> tuple[int, int] | None:
        n = self.whole(self.n, 1, 10_000_000)
        seed = self.whole(self.seed, 0, 2**31 - 1)
        return None if n is None or seed is None else (n, seed)

    async def generate(self) -> None:
        from nicegui import run

        from mjx_pick.pickpoints import generate_normal

        self.generate_error.set_text("")
        if not self.need_object(self.generate_error):
            return
        settings = self.read_settings()
        numbers = self.pick_numbers()
        if settings is None or numbers is None:
            return
        n, seed = numbers
        self.picks_info.set_text("generating ...")
        try:
            picks = await run.io_bound(
                generate_normal,
                self.obj,
                settings.gripper,
                n,
                seed,
                settings.picks,
                settings.grasp,
            )
            png = await run.io_bound(views.picks_png, self.obj, picks)
        except ConfigError as err:
            self.picks_info.set_text("")
            self.generate_error.set_text(str(err))
            return
        rejected = ", ".join(f"{k} {v}" for k, v in picks.rejected.items() if v)
        self.picks_info.set_text(
            f"{len(picks)} feasible pick-points of {picks.n_candidates} candidates checked "
            f"(rejected: {rejected or 'none'})"
        )
        self.picks_image.set_source(views.data_uri(png, "image/png"))
        self.picks_image.set_visibility(True)

    def run_folder(self, name_widget) -> Path | None:
        name = (name_widget.value or "").strip()
        name_widget.error = None
        if not NAME_OK.match(name):
            name_widget.error = "letters, digits, '.', '_' and '-' only (at most 80)"
            return None
        return self.workdir / name

    def settings_flags(self, settings, out: Path) -> list[str]:
        folder = self.workdir / "inputs" / out.name
        paths = forms.write_inputs(settings, folder)
        return forms.cli_flags(settings, paths) + ["--backend", self.backend.value]

    def start_evaluate(self) -> None:
        self.generate_error.set_text("")
        if self.busy(self.generate_error) or not self.need_object(self.generate_error):
            return
        settings = self.read_settings()
        numbers = self.pick_numbers()
        out = self.run_folder(self.run_name)
        if settings is None or numbers is None or out is None:
            return
        n, seed = numbers
        traces = int(self.traces.value or 0)
        chunk = int(self.chunk.value) if self.chunk.value else max(64, math.ceil(n / 20))
        argv = ["evaluate", *self.obj_args, *self.settings_flags(settings, out)]
        argv += ["--n", str(n), "--seed", str(seed), "--traces", str(max(traces, 0))]
        argv += ["--chunk-size", str(max(1, chunk)), "--no-progress", "--out", str(out)]
        if self.resume.value:
            argv.append("--resume")
        self.run_summary.set_content("")

        def done(progress):
            if progress.state == "cancelled":  # ready to continue: same folder, resume
                self.run_name.value = out.name
                self.resume.value = True
                self.run_summary.set_content(
                    f"**{out.name}**: cancelled; its finished chunks are kept. Start the "
                    "batch again (resume is ticked) to continue it."
                )
                return
            if progress.state != "complete":
                return
            from mjx_pick.metrics import rate_text

            self.resume.value = False
            s = json.loads((out / "summary.json").read_text())
            self.run_summary.set_content(
                f"**{out.name}**: success rate {rate_text(s['successes'], s['n'])}, "
                f"mean score {_fmt(s['score_mean'])}, "
                f"{s['picks_per_s']} pick-points/s on {s['backend']}. Open tab 4."
            )
            self.run_dir.value = str(out)
            self.open_run()

        job = jobs.Job(argv, self.workdir / "logs" / f"{out.name}.log", out, n, chunk)
        self.start_job(f"evaluate {out.name}", job, done)
        self.run_name.value = f"evaluate-{_stamp()}"

    # ----------------------------------------------------------- tab 4: analyze
    def analyze_tab(self) -> None:
        from nicegui import ui

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
        self.analyze_error = self.error_label().props('data-testid="analyze-error"')
        self.run_info = ui.label("").props('data-testid="run-info"')
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-[46rem]"):
                self.table = (
                    ui.table(
                        columns=[
                            {
                                "name": k,
                                "label": label,
                                "field": k,
                                "sortable": True,
                                "align": "left",
                            }
                            for k, label in TABLE_COLUMNS
                        ],
                        rows=[],
                        row_key="pick_id",
                        selection="single",
                        pagination=10,
                        on_select=self.on_select,
                    )
                    .classes("w-full")
                    .props('dense data-testid="picks-table"')
                )
                with ui.row().classes("items-end"):
                    self.export_n = ui.number("n best and n worst", value=3, step=1).classes("w-40")
                    self.export_anim = ui.checkbox("animations (slow)")
                    ui.button("Export template and report", on_click=self.export).props(
                        'data-testid="export"'
                    )
                self.downloads = ui.row()
            with ui.column().classes("grow"):
                self.detail = ui.markdown("Select a pick-point.").props('data-testid="pick-detail"')
                with ui.column().classes("w-full"):
                    self.force_image = (
                        ui.image()
                        .props("no-transition no-spinner")
                        .classes("w-full max-w-2xl")
                        .props('data-testid="force-plot"')
                    )
                    self.replay_image = (
                        ui.image()
                        .props("no-transition no-spinner")
                        .classes("w-full max-w-2xl")
                        .props('data-testid="replay"')
                    )
                self.force_image.set_visibility(False)
                self.replay_image.set_visibility(False)
        self.refresh_runs()

    def refresh_runs(self) -> None:
        from mjx_pick.rundir import read_manifest

        names = []
        if self.workdir.is_dir():
            for p in sorted(self.workdir.iterdir()):
                m = read_manifest(p) if p.is_dir() else None
                if m and m.get("command") == "evaluate":
                    names.append(str(p))
        self.known_runs.set_options(names)

    def on_known_run(self, _=None) -> None:
        if self.known_runs.value:
            self.run_dir.value = self.known_runs.value
            self.open_run()

    def open_run(self) -> None:
        from mjx_pick.metrics import rate_text
        from mjx_pick.reporting import Run

        self.analyze_error.set_text("")
        path = Path((self.run_dir.value or "").strip()).expanduser()
        try:
            run = Run.load(path)
        except ConfigError as err:
            self.analyze_error.set_text(str(err))
            return
        except (OSError, ValueError) as err:
            self.analyze_error.set_text(f"{path}: cannot be read ({err})")
            return
        self.run = run
        s = run.summary
        self.run_info.set_text(
            f"{s.get('object')} / {s.get('gripper')}: {s.get('n')} pick-points, success rate "
            f"{rate_text(s.get('successes', 0), s.get('n', 0))}, "
            f"mean score {_fmt(s.get('score_mean'))}, "
            f"F_Gmin {_fmt(s.get('f_gmin_n'))} N"
        )
        traced = {pid for pid, _ in run.traced()}
        t = run.table
        score = np.asarray(t["score"], float)
        order = np.argsort(np.where(np.isnan(score), -np.inf, -score), kind="stable")
        rows = []
        for rank, i in enumerate(order, start=1):
            row = {k: t[k][int(i)].as_py() for k, _ in TABLE_COLUMNS if k in t.column_names}
            for k, v in row.items():
                if isinstance(v, float):
                    row[k] = None if math.isnan(v) else round(v, 3)
            row["rank"] = rank
            row["traced"] = "yes" if row["pick_id"] in traced else ""
            rows.append(row)
        self.table.rows = rows
        self.table.selected = []
        self.table.update()
        self.detail.set_content("Select a pick-point (the table is ranked by score).")
        self.force_image.set_visibility(False)
        self.replay_image.set_visibility(False)
        self.show_downloads()
        self.refresh_runs()

    async def on_select(self, e) -> None:
        from nicegui import run

        if not e.selection or self.run is None:
            return
        row = e.selection[0]
        pid = int(row["pick_id"])
        full = self.run.row(pid)
        lines = [
            f"**pick {pid}** (rank {row['rank']}): x {full['x_mm']:.2f} mm, y "
            f"{full['y_mm']:.2f} mm, yaw {full['yaw_deg']:.1f} deg, opening "
            f"{full['opening_mm']:.1f} mm",
            "",
            f"- score (eq. 2): **{_fmt(full['score'])}**, success: **{full['success']}**, "
            f"outcome: {full['failure']}",
            f"- `t_grasp`: {_fmt(full['t_grasp'])} (grip force held, fraction of the window)",
            f"- `phi_max`: {_fmt(full['phi_max_deg'], 1)} deg (largest rotation)",
            f"- `t_grasp_nc`: {_fmt(full['t_grasp_nc'])} (off the table, fraction)",
            f"- pad forces max {_fmt(full['max_force_left_n'], 1)} / "
            f"{_fmt(full['max_force_right_n'], 1)} N, lift {_fmt(full['lift_height_mm'], 1)} "
            f"mm, slip {_fmt(full['slip_mm'], 2)} mm",
        ]
        self.detail.set_content("\n".join(lines))
        if row.get("traced") != "yes":
            self.detail.set_content(
                "\n".join(lines)
                + "\n\nNot traced: the run recorded the forces of its best and worst "
                "pick-points only (tab 3, 'traced best and worst')."
            )
            self.force_image.set_visibility(False)
            self.replay_image.set_visibility(False)
            return
        trace = self.run.trace(pid)
        f_d = float(self.run.config["grasp"]["grip_force_n"])
        title = f"pick {pid}: score {_fmt(full['score'])}, {full['failure']}"
        png = await run.io_bound(views.force_png, trace, f_d, title)
        self.force_image.set_source(views.data_uri(png, "image/png"))
        self.force_image.set_visibility(True)
        self.replay_image.set_visibility(False)
        try:
            gif = await run.io_bound(views.replay_gif, self.run.path / "scene.xml", trace)
        except RuntimeError as err:  # no offscreen GL here: say so, keep the plot
            self.analyze_error.set_text(str(err))
            return
        self.replay_image.set_source(views.data_uri(gif, "image/gif"))
        self.replay_image.set_visibility(True)

    def export(self) -> None:
        self.analyze_error.set_text("")
        if self.run is None:
            self.analyze_error.set_text("open an evaluate output folder first")
            return
        if self.busy(self.analyze_error):
            return
        n = self.whole(self.export_n, 1, 50)
        if n is None:
            return
        argv = ["report", str(self.run.path), "--n", str(int(n))]
        if not self.export_anim.value:
            argv.append("--no-animations")
        job = jobs.Job(argv, self.workdir / "logs" / f"{self.run.path.name}-report.log")
        self.start_job(f"report {self.run.path.name}", job, lambda p: self.show_downloads())

    def show_downloads(self) -> None:
        from nicegui import ui

        self.downloads.clear()
        if self.run is None:
            return
        with self.downloads:
            for name, label in (
                ("template_a4.pdf", "template (A4, PDF)"),
                ("template_letter.pdf", "template (Letter, PDF)"),
                ("report.html", "report (HTML)"),
                ("robot_picks.json", "robot pick-points (JSON)"),
            ):
                path = self.run.path / name
                if path.is_file():
                    ui.button(
                        label, icon="download", on_click=lambda p=path: ui.download.file(p)
                    ).props(f'outline data-testid="download-{name}"')

    # ------------------------------------------------------------- tab 5: sweep
    def sweep_tab(self) -> None:
        from nicegui import ui

        from mjx_pick.sweeps import sweepable

        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                self.sweep_param = ui.select(
                    sweepable(),
                    value="contact.pad_friction",
                    label="parameter",
                    with_input=True,
                ).classes("w-full")
                self.sweep_start = ui.number("start", value=0.4, step=0.05)
                self.sweep_end = ui.number("end", value=1.0, step=0.05)
                self.sweep_step = ui.number("step", value=0.2, step=0.05)
                self.sweep_n = ui.number("simulations per value", value=100, step=1)
                self.sweep_name = ui.input("run folder name", value=f"sweep-{_stamp()}")
                ui.button("Start sweep", on_click=self.start_sweep).props(
                    'data-testid="start-sweep"'
                )
                self.sweep_error = self.error_label().props('data-testid="sweep-error"')
            with ui.column().classes("grow"):
                self.sweep_table = ui.table(columns=[], rows=[], row_key="variant").props(
                    'dense data-testid="sweep-table"'
                )
                self.sweep_image = (
                    ui.image().props("no-transition no-spinner").classes("w-full max-w-3xl")
                )
                self.sweep_image.set_visibility(False)

    def start_sweep(self) -> None:
        self.sweep_error.set_text("")
        if self.busy(self.sweep_error) or not self.need_object(self.sweep_error):
            return
        fields = {"start": self.sweep_start, "end": self.sweep_end, "step": self.sweep_step}
        values, errors = forms.sweep_values(*(w.value for w in fields.values()))
        for key, widget in fields.items():
            widget.error = errors.get(key)
        n = self.whole(self.sweep_n, 1, 1_000_000)
        if n is None:
            return
        settings = self.read_settings()
        out = self.run_folder(self.sweep_name)
        if values is None or settings is None or out is None:
            return
        if not self.sweep_param.value:
            self.sweep_error.set_text("choose a parameter")
            return
        param = f"{self.sweep_param.value}=" + ",".join(repr(v) for v in values)
        argv = ["sweep", *self.obj_args, *self.settings_flags(settings, out)]
        argv += ["--param", param, "--n", str(int(n)), "--out", str(out)]

        def done(progress):
            if progress.state == "complete":
                self.show_sweep(out)

        job = jobs.Job(argv, self.workdir / "logs" / f"{out.name}.log", out, None, None)
        self.start_job(f"sweep {out.name} ({len(values)} values x {int(n)})", job, done)
        self.sweep_name.value = f"sweep-{_stamp()}"

    def show_sweep(self, out: Path) -> None:
        variants = json.loads((out / "variants.json").read_text())
        keys = [k for k in variants[0] if k not in ("success_ci", "score_ci")]
        self.sweep_table.columns = [{"name": k, "label": k, "field": k} for k in keys]
        self.sweep_table.rows = [{k: _fmt(v[k]) for k in keys} for v in variants]
        self.sweep_table.update()
        self.sweep_image.set_source(views.data_uri((out / "sweep.png").read_bytes(), "image/png"))
        self.sweep_image.set_visibility(True)

    # ----------------------------------------------------------- tab 6: studies
    def studies_tab(self) -> None:
        from nicegui import ui

        from mjx_pick.calibration import FITTABLE
        from mjx_pick.gripper import preset_names

        ui.label(
            "Each study runs on the object of tab 1 with the settings of tab 2, and writes "
            "the folder of its CLI command."
        ).classes("text-sm")
        with ui.expansion("Compare grippers", value=True).classes("w-full"):
            with ui.row().classes("w-full no-wrap items-start"):
                with ui.column().classes("w-96"):
                    self.cmp_grippers = ui.select(
                        preset_names(),
                        value=["robotiq-2f85", "onrobot-rg2"],
                        multiple=True,
                        label="presets",
                    ).classes("w-full")
                    self.cmp_current = ui.checkbox("and the gripper of tab 2")
                    self.cmp_n = ui.number("pick-points", value=200, step=1)
                    self.cmp_rank = ui.select(
                        ["success", "score"], value="success", label="rank by"
                    )
                    self.cmp_name = ui.input("run folder name", value=f"compare-{_stamp()}")
                    ui.button("Start comparison", on_click=self.start_compare).props(
                        'data-testid="start-compare"'
                    )
                    self.cmp_error = self.error_label().props('data-testid="compare-error"')
                with ui.column().classes("grow"):
                    self.cmp_table = ui.table(columns=[], rows=[], row_key="rank").props(
                        'dense data-testid="compare-table"'
                    )
                    self.cmp_image = (
                        ui.image().props("no-transition no-spinner").classes("w-full max-w-3xl")
                    )
                    self.cmp_image.set_visibility(False)
        with ui.expansion("Robustness of the best pick-points (run of tab 4)").classes("w-full"):
            with ui.row().classes("w-full no-wrap items-start"):
                with ui.column().classes("w-96"):
                    self.rob_k = ui.number("top pick-points", value=10, step=1)
                    self.rob_m = ui.number("perturbed draws each", value=32, step=1)
                    self.rob_xy = ui.number("position error sigma (mm)", value=2.0, step=0.5)
                    self.rob_yaw = ui.number("yaw error sigma (deg)", value=3.0, step=0.5)
                    ui.button("Start robustness study", on_click=self.start_robust).props(
                        'data-testid="start-robust"'
                    )
                    self.rob_error = self.error_label().props('data-testid="robust-error"')
                with ui.column().classes("grow"):
                    self.rob_table = ui.table(columns=[], rows=[], row_key="rank").props(
                        'dense data-testid="robust-table"'
                    )
        with ui.expansion("Calibrate contact parameters from measured outcomes").classes("w-full"):
            with ui.row().classes("w-full no-wrap items-start"):
                with ui.column().classes("w-96"):
                    ui.label(
                        "A CSV of tested pick-points and their outcomes (format: "
                        "mjx_pick/assets/outcomes/README.md), up to 5 MB."
                    ).classes("text-sm")
                    self.outcomes_upload = (
                        ui.upload(
                            label="upload outcomes CSV",
                            auto_upload=True,
                            max_file_size=OUTCOMES_MAX_BYTES,
                            on_upload=self.on_outcomes_upload,
                            on_rejected=lambda: self.cal_error.set_text(
                                "file refused: a .csv file of at most "
                                f"{OUTCOMES_MAX_BYTES // 2**20} MB"
                            ),
                        )
                        .props('accept=".csv" data-testid="outcomes-upload"')
                        .classes("w-full")
                    )
                    self.cal_params = ui.select(
                        list(FITTABLE),
                        value=["pad_friction"],
                        multiple=True,
                        label="parameters to fit",
                    ).classes("w-full")
                    self.cal_steps = ui.number("optimiser steps", value=60, step=1)
                    self.cal_name = ui.input("run folder name", value=f"calibrate-{_stamp()}")
                    ui.button("Start calibration", on_click=self.start_calibrate).props(
                        'data-testid="start-calibrate"'
                    )
                    self.cal_error = self.error_label().props('data-testid="calibrate-error"')
                with ui.column().classes("grow"):
                    self.cal_info = ui.markdown("").props('data-testid="calibrate-info"')
                    self.cal_use = ui.button(
                        "Use the fitted contact parameters in tab 2", on_click=self.use_calibration
                    ).props('data-testid="use-calibration"')
                    self.cal_use.set_visibility(False)
                    self.cal_image = (
                        ui.image().props("no-transition no-spinner").classes("w-full max-w-2xl")
                    )
                    self.cal_image.set_visibility(False)

    def whole(self, widget, lo: int, hi: int) -> int | None:
        """A whole number field in [lo, hi], or None with the message under it."""
        v = widget.value
        widget.error = None
        if v is None or v != int(v) or not lo <= v <= hi:
            widget.error = f"a whole number from {lo} to {hi:,}"
            return None
        return int(v)

    def show_rows(self, table, rows: list[dict], keys: list[str]) -> None:
        table.columns = [{"name": k, "label": k, "field": k, "align": "left"} for k in keys]
        table.rows = [{k: _fmt_cell(r.get(k)) for k in keys} for r in rows]
        table.update()

    def start_compare(self) -> None:
        self.cmp_error.set_text("")
        if self.busy(self.cmp_error) or not self.need_object(self.cmp_error):
            return
        n = self.whole(self.cmp_n, 1, 1_000_000)
        settings = self.read_settings()
        out = self.run_folder(self.cmp_name)
        if n is None or settings is None or out is None:
            return
        flags = self.settings_flags(settings, out)
        names = list(self.cmp_grippers.value or [])
        if self.cmp_current.value:
            names.append(flags[flags.index("--gripper-file") + 1])
        if len(names) < 2:
            self.cmp_error.set_text("choose at least two grippers")
            return
        argv = ["compare", *self.obj_args, *flags, "--grippers", ",".join(names)]
        argv += ["--n", str(n), "--rank-by", self.cmp_rank.value, "--out", str(out)]

        def done(progress):
            if progress.state == "complete":
                rows = json.loads((out / "ranking.json").read_text())
                keys = ["rank", "gripper", "success_rate", "success_ci", "score_mean"]
                self.show_rows(self.cmp_table, rows, keys + ["feasible", "p_vs_best"])
                self.cmp_image.set_source(
                    views.data_uri((out / "maps.png").read_bytes(), "image/png")
                )
                self.cmp_image.set_visibility(True)

        job = jobs.Job(argv, self.workdir / "logs" / f"{out.name}.log", out)
        self.start_job(f"compare {out.name} ({len(names)} grippers x {n})", job, done)
        self.cmp_name.value = f"compare-{_stamp()}"

    def start_robust(self) -> None:
        self.rob_error.set_text("")
        if self.busy(self.rob_error) or not self.need_object(self.rob_error):
            return
        if self.run is None:
            self.rob_error.set_text("open an evaluate output folder in tab 4 first")
            return
        k = self.whole(self.rob_k, 1, 1000)
        m = self.whole(self.rob_m, 2, 10_000)
        sig = []
        for w in (self.rob_xy, self.rob_yaw):
            w.error = None
            if w.value is None or not 0 <= w.value <= 100:
                w.error = "from 0 to 100"
            sig.append(w.value)
        settings = self.read_settings()
        if k is None or m is None or settings is None or self.rob_xy.error or self.rob_yaw.error:
            return
        s = self.run.summary
        if (s.get("object"), s.get("gripper")) != (self.obj.name, settings.gripper.name):
            self.rob_error.set_text(
                f"the run of tab 4 is of {s.get('object')} / {s.get('gripper')}: import that "
                f"object and set that gripper (now {self.obj.name} / {settings.gripper.name})"
            )
            return
        out = self.run.path
        argv = ["robust", *self.obj_args, *self.settings_flags(settings, out)]
        argv += ["--results", str(out), "--top-k", str(k), "--m", str(m)]
        argv += ["--sigma-xy-mm", repr(float(sig[0])), "--sigma-yaw-deg", repr(float(sig[1]))]
        argv += ["--out", str(out)]

        def done(progress):
            if progress.state == "complete":
                rows = json.loads((out / "robustness.json").read_text())["ranking"]
                keys = ["rank", "pick_id", "x_mm", "y_mm", "yaw_deg", "robust_p"]
                self.show_rows(self.rob_table, rows, keys + ["robust_ci_low", "landed"])

        job = jobs.Job(argv, self.workdir / "logs" / f"{out.name}-robust.log", out)
        self.start_job(f"robust {out.name} (top {k} x {m} draws)", job, done)

    async def on_outcomes_upload(self, e) -> None:
        from nicegui import run

        self.cal_error.set_text("")
        name = e.file.name
        data = await e.file.read()
        self.outcomes_upload.reset()
        if not name.lower().endswith(".csv") or len(data) > OUTCOMES_MAX_BYTES:
            self.cal_error.set_text(f"{name}: not a .csv file of at most 5 MB")
            return
        try:
            data.decode("utf-8")
        except UnicodeDecodeError:
            self.cal_error.set_text(f"{name}: not a UTF-8 text file")
            return
        path = await run.io_bound(save_upload, data, name, self.uploads)
        try:
            from mjx_pick.calibration import read_outcomes

            outcomes = await run.io_bound(read_outcomes, str(path))
        except ConfigError as err:
            self.cal_error.set_text(str(err))
            return
        self.outcomes_path = path
        self.cal_info.set_content(
            f"outcomes: {name}, {len(outcomes)} tested pick-points "
            f"({int(np.sum(outcomes.trials))} trials)"
        )

    def start_calibrate(self) -> None:
        self.cal_error.set_text("")
        if self.busy(self.cal_error) or not self.need_object(self.cal_error):
            return
        if self.outcomes_path is None:
            self.cal_error.set_text("upload an outcomes CSV first")
            return
        steps = self.whole(self.cal_steps, 1, 100_000)
        settings = self.read_settings()
        out = self.run_folder(self.cal_name)
        params = list(self.cal_params.value or [])
        self.cal_params.error = None if params else "choose at least one parameter"
        if steps is None or settings is None or out is None or not params:
            return
        argv = ["calibrate", str(self.outcomes_path), *self.obj_args]
        argv += self.settings_flags(settings, out)
        argv += ["--params", ",".join(params), "--steps", str(steps), "--log-every", "1"]
        argv += ["--out", str(out)]

        def done(progress):
            if progress.state == "complete":
                self.show_calibration(out)

        job = jobs.Job(
            argv,
            self.workdir / "logs" / f"{out.name}.log",
            out,
            steps,
            steps_logged=r"(?m)^step\s+(\d+)\s",
            unit="steps",
        )
        self.start_job(f"calibrate {out.name} ({steps} steps)", job, done)
        self.cal_name.value = f"calibrate-{_stamp()}"

    def show_calibration(self, out: Path) -> None:
        c = json.loads((out / "calibration.json").read_text())
        lines = [f"**{out.name}**: fitted contact parameters (`{out / 'contact.toml'}`)", ""]
        lines += [
            f"- `{k}`: {_fmt(c['initial'][k], 4)} -> **{_fmt(c['fitted'][k], 4)}**"
            for k in c["parameters"]
        ]
        self.cal_info.set_content("\n".join(lines))
        self.cal_image.set_source(views.data_uri((out / "loss.png").read_bytes(), "image/png"))
        self.cal_image.set_visibility(True)
        self.cal_contact = out / "contact.toml"
        self.cal_use.set_visibility(True)

    def use_calibration(self) -> None:
        from mjx_pick.physics import load_contact

        try:
            contact, _ = load_contact(self.cal_contact)
        except ConfigError as err:
            self.cal_error.set_text(str(err))
            return
        self.base_contact = contact
        for key in ("contact.pad_friction", "contact.table_friction"):
            self.inputs[key].value = float(getattr(contact, key.split(".")[1]))
        self.cal_info.set_content(
            self.cal_info.content + "\n\nIn use in tab 2 (all fitted parameters)."
        )

    # -------------------------------------------------------------------- jobs
    def busy(self, where) -> bool:
        if self.job is not None and self.job.running:
            where.set_text("a run is in progress: wait for it or cancel it")
            return True
        return False

    def start_job(self, title: str, job: jobs.Job, on_end) -> None:
        self.job, self.on_job_end = job.start(), on_end
        self.started.difference_update([j for j in self.started if not j.running])
        self.started.add(job)
        self.job_title.set_text(title)
        self.job_status.set_text("starting ...")
        self.job_command.set_content(job.command_line)
        self.job_bar.set_value(0)
        self.job_bar.props(remove="indeterminate")
        if job.total is None:
            self.job_bar.props("indeterminate")
        self.cancel_button.set_visibility(True)
        self.job_card.set_visibility(True)

    def cancel_job(self) -> None:
        if self.job is not None:
            self.job.cancel()

    def poll_job(self) -> None:
        if self.job is None:
            return
        p = self.job.poll()
        if p.fraction is not None:
            self.job_bar.set_value(p.fraction)
        parts = [p.state]
        if p.done is not None:
            parts.append(f"{p.done}/{p.total} {p.unit}")
        if p.rate:
            parts.append(f"{p.rate:.1f} per s")
        if p.eta_s is not None and p.state == "running":
            parts.append(f"about {p.eta_s:.0f} s left")
        parts.append(f"{p.elapsed_s:.0f} s")
        if p.message:
            parts.append(p.message)
        self.job_status.set_text(", ".join(parts))
        if p.state != "running":
            self.job_bar.props(remove="indeterminate")
            if p.state == "complete":
                self.job_bar.set_value(1.0)
            self.cancel_button.set_visibility(False)
            on_end = self.on_job_end
            self.job, self.on_job_end = None, None
            try:
                if on_end is not None:
                    on_end(p)
            except (OSError, ValueError, KeyError) as err:
                self.job_status.set_text(f"{p.state}; its results cannot be read: {err}")


def test_simulation(obj, settings: forms.Settings, x: float, y: float, yaw: float, backend):
    """The gripper tab's check of one pick-point: clearance, then a recorded simulation."""
    from mjx_pick import pickpoints as pp
    from mjx_pick.evaluation import evaluate
    from mjx_pick.grasp import fingertip_height_mm

    checker = pp.FeasibilityChecker(obj, settings.gripper, settings.picks, settings.grasp)
    res = checker(np.array([x]), np.array([y]), np.array([yaw]))
    reason = pp.REASONS[int(res["reason"][0])]
    tip = fingertip_height_mm(obj, settings.gripper, settings.grasp)
    head = [
        f"- clearance and coverage check: **{reason}** (opening "
        f"{float(res['opening_mm'][0]):.1f} mm, coverage {float(res['coverage'][0]):.2f})",
        f"- initial (closing) speed: {settings.grasp.closing_speed_mm_s:g} mm/s",
        f"- height compensation (fingertips above the table): {tip:.1f} mm",
    ]
    if reason != "feasible":
        return {
            "text": "\n".join(head) + "\n- not simulated: the pick-point is infeasible",
            "plot": None,
        }
    batch = checker.batch(np.array([0]), np.array([x]), np.array([y]), np.array([yaw]), "user")
    ev = evaluate(
        obj,
        settings.gripper,
        picks=batch,
        contact=settings.contact,
        grasp=settings.grasp,
        pick_config=settings.picks,
        backend=backend,
        n_traces=1,
    )
    r = {k: ev.table[k][0].as_py() for k in ev.table.column_names}
    trace = {name: np.asarray(ev.traces[name]) for name in ev.traces.column_names}
    head += [
        f"- score (eq. 2): **{_fmt(r['score'])}**, success: **{r['success']}**, outcome: "
        f"{r['failure']}",
        f"- `t_grasp` {_fmt(r['t_grasp'])}, `phi_max` {_fmt(r['phi_max_deg'], 1)} deg, "
        f"`t_grasp_nc` {_fmt(r['t_grasp_nc'])}",
        f"- `F_Gmin`, eq. (1): {_fmt(ev.summary['f_gmin_n'])} N at `F_d` = "
        f"{settings.grasp.grip_force_n:g} N",
    ]
    plot = views.force_png(trace, settings.grasp.grip_force_n, f"test pick ({x:g}, {y:g}, {yaw:g})")
    return {"text": "\n".join(head), "plot": plot}


def serve(host: str, port: int, workdir: Path, show: bool) -> None:
    """Run the app until interrupted (``mjx-pick gui``)."""
    from nicegui import app, ui

    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    started: set[jobs.Job] = set()  # kept while running, also after its tab closed

    @ui.page("/")
    def index() -> None:
        Page(workdir, started).build()

    def stop_jobs() -> None:  # the server stops: runs stop as on Ctrl-C, keeping their parts
        for job in list(started):
            job.cancel()

    app.on_shutdown(stop_jobs)
    ui.run(
        host=host,
        port=port,
        reload=False,
        show=show,
        title="mjx-pick",
        show_welcome_message=False,
        uvicorn_logging_level="warning",
        reconnect_timeout=30.0,
    )
