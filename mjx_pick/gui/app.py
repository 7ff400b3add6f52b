"""The web server and its page: the paper's four tabs (its Fig. 10), a sweep tab, studies.

Details: docs/gui.md (gui/app.py).
"""

from __future__ import annotations

import logging
import subprocess
import uuid
from pathlib import Path

from mjx_pick.gui import forms, jobs
from mjx_pick.gui.formatting import raised_in, unexpected_text
from mjx_pick.gui.state import PageState, server_log

# the page's unexpected errors, with their tracebacks (the server's log, :func:`log_to_file`)
log = logging.getLogger(__name__)

# (name, label) of each tab, in the page's order
TABS = (
    ("import", "1 Import object model"),
    ("gripper", "2 Set gripper parameters"),
    ("generate", "3 Generate input data"),
    ("analyze", "4 Analyze results"),
    ("sweep", "Parameter sweep"),
    ("studies", "Studies"),
)


def build_page(workdir: Path, runs: jobs.Runs, pages: dict | None = None) -> PageState:
    """One browser tab's page.

    runs: the server's runs; pages: the server's {browser tab id: (PageState,
    SettingsForm)} of each browser tab's last page -- what a reload brings back (the
    object, the open run, the settings; the run it started, from runs).
    """
    from nicegui import app, ui

    from mjx_pick.gui.page.analyze_tab import AnalyzeTab
    from mjx_pick.gui.page.generate_tab import GenerateTab
    from mjx_pick.gui.page.gripper_tab import GripperTab
    from mjx_pick.gui.page.import_tab import ImportTab
    from mjx_pick.gui.page.job_panel import JobPanel
    from mjx_pick.gui.page.studies_tab import StudiesTab
    from mjx_pick.gui.page.sweep_tab import SweepTab

    state = PageState(workdir)
    ui.page_title("mjx-pick")
    # a field in a column takes the column's width (one without a width of its own):
    # Quasar's fields shrink to 160 px otherwise, and clip their labels and values
    ui.add_css(".nicegui-column > .q-field { align-self: stretch; }")
    with ui.header().classes("items-center py-1"):
        ui.label("mjx-pick: pick-point evaluation").classes("text-lg")
        ui.label(f"runs in {workdir}").classes("text-xs opacity-80")
    with ui.tabs().classes("w-full") as tabs:
        tab = {name: ui.tab(name, label) for name, label in TABS}
    panel = JobPanel(runs)
    analyze: AnalyzeTab | None = None  # built after the tab that opens runs in it
    generate: GenerateTab | None = None  # built after the tab that imports objects
    with ui.tab_panels(tabs, value=tab["import"]).classes("w-full"):
        with ui.tab_panel(tab["import"]):
            import_tab = ImportTab(state, on_import=lambda: generate.forget_map())
        with ui.tab_panel(tab["gripper"]):
            gripper = GripperTab(state, show=lambda: tabs.set_value("gripper"))
            form = gripper.form
        with ui.tab_panel(tab["generate"]):
            generate = GenerateTab(
                state,
                form,
                panel,
                on_complete=lambda out: analyze.open(out),
                on_pick=gripper.use_pick,
            )
        with ui.tab_panel(tab["analyze"]):
            analyze = AnalyzeTab(state, panel)
        with ui.tab_panel(tab["sweep"]):
            SweepTab(state, form, panel)
        with ui.tab_panel(tab["studies"]):
            StudiesTab(state, form, panel)

    async def attach() -> None:
        """Once the browser is connected: its tab's id, what its last page held, its run."""
        await ui.context.client.connected()
        tab_id = app.storage.tab.setdefault("mjx_pick_tab", uuid.uuid4().hex)
        before = (pages or {}).get(tab_id)
        if pages is not None:
            pages[tab_id] = (state, form)
        if before is not None:
            old_state, old_form = before
            form.restore(old_form)
            if old_state.obj is not None:
                await import_tab.restore(old_state.obj, old_state.obj_args)
            if old_state.run is not None:
                analyze.open(old_state.run.path)
        panel.reattach(tab_id)

    ui.timer(0.05, attach, once=True)

    def unexpected(err: Exception) -> None:
        """A bug in a handler: what failed in a line in the page, the traceback only in
        the server's log."""
        log.error("a page handler failed", exc_info=err)
        library = raised_in(err)
        text = unexpected_text(
            "the last action", library, type(err).__name__, state.where(state.server_log)
        )
        ui.notify(text, type="negative", multi_line=True)

    ui.on_exception(unexpected)
    return state


def log_to_file(workdir: Path) -> None:
    """The server's log, also in the work folder (:func:`state.server_log`): the
    tracebacks of unexpected errors, which the page names but never shows."""
    import logging

    path = server_log(workdir)
    path.parent.mkdir(parents=True, exist_ok=True)
    handler = logging.FileHandler(path, encoding="utf-8")
    handler.setFormatter(logging.Formatter("%(asctime)s %(name)s %(levelname)s: %(message)s"))
    logger = logging.getLogger("mjx_pick")
    logger.addHandler(handler)
    logger.setLevel(logging.INFO)


def serve(host: str, port: int, workdir: Path, show: bool) -> None:
    """Run the app until interrupted (``mjx-pick gui``)."""
    from nicegui import app, ui

    workdir = Path(workdir).resolve()
    workdir.mkdir(parents=True, exist_ok=True)
    log_to_file(workdir)
    # server-side: they outlive the page (a reload finds them); the simulation commands
    # run in warm workers, the default backend's started now so a first job may find it
    forms.backend_problems()  # asked once, before the first page needs the backends
    workers = jobs.Workers(workdir / "logs")
    workers.prepare(jobs.DEFAULT_BACKEND)
    runs = jobs.Runs(workers)
    runs.recover(workdir)  # a restarted server remembers the work folder's runs
    pages: dict = {}  # each browser tab's last page, by the tab's id

    @ui.page("/")
    def index() -> None:
        build_page(workdir, runs, pages)

    def stop_jobs() -> None:  # the server stops: runs stop as on Ctrl-C, keeping their parts
        # (its own runs only: one a previous server left running is not this one's to stop)
        mine = [job for job in runs if job.started_here]
        for job in mine:
            job.cancel()
        for job in mine:  # then the workers end (a cancelled job first marks its folder)
            if job.running:
                try:
                    job.wait(jobs.CANCEL_GRACE_S)
                except subprocess.TimeoutExpired:
                    pass
        workers.close()

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
