"""The job panel: the run this browser tab started, its progress, Cancel, its CLI command.

Details: docs/gui.md (gui/page/job_panel.py).
"""

from __future__ import annotations

import logging
from collections.abc import Callable

from nicegui import background_tasks, ui

from mjx_pick.gui import jobs
from mjx_pick.gui.page.widgets import MessageLabel, StartQuestion, warning_label

POLL_S = 0.5  # how often the panel reads the run's progress

# the server's log says which start clicks arrived and what became of them: a click the
# page seemed to lose is then told apart from one the server refused or never received
log = logging.getLogger(__name__)


class JobPanel:
    """One browser tab's current run, shown above the tabs."""

    def __init__(self, runs: jobs.Runs, owner: str | None = None):
        """runs: the server's runs (server-side: they outlive this page; stopped at
        shutdown); owner: this browser tab's id (it survives a reload), once known."""
        self.runs, self.owner = runs, owner
        self.job: jobs.Job | None = None
        self.on_end: Callable[[jobs.Progress], None] | None = None
        # what each command's end draws, by command: a run re-attached after a reload
        # is drawn by this page's tabs, not by the page that started it
        self.handlers: dict[str, Callable[[jobs.Job, jobs.Progress], None]] = {}
        # what each command's tab shows of a run this page did not start (one re-attached
        # after a reload, or chosen in the runs list): its numbers as its folder records
        self.shown: dict[str, Callable[[jobs.Job], None]] = {}
        with ui.card().classes("w-full") as card:
            with ui.row().classes("items-center w-full"):
                self.title = ui.label("").classes("font-bold").props('data-testid="job-title"')
                self.status = MessageLabel("").props('data-testid="job-status"')
                ui.space()
                self.cancel_button = ui.button("Cancel", on_click=self.cancel, color="red")
            self.offline = ui.label(
                "connection to the server lost: this run's state is unknown until the page "
                "reconnects (reload it)"
            ).classes("mjx-offline-note text-negative")
            self.bar = (
                ui.linear_progress(value=0, show_value=False).props("size=12px").classes("mjx-live")
            )
            self.warnings = warning_label("job-warnings")
            self.where = ui.label("").classes("text-xs").props('data-testid="job-where"')
            self.command = ui.code("", language="bash").classes("w-full text-xs")
        self.status.classes("mjx-live")
        card.set_visibility(False)
        self.card = card
        self.others = ui.label("").classes("text-sm").props('data-testid="other-runs"')
        # every run of the server -- the work folder's from before a restart included:
        # choosing one shows it here (its state, and its results drawn by the tabs)
        self.listed: list[jobs.Job] = []
        self.history = (
            ui.select({}, label="runs in this work folder", on_change=self.on_history)
            .classes("w-[32rem]")
            .props('data-testid="runs-list"')
        )
        self.question = StartQuestion()
        ui.timer(POLL_S, self.poll)
        # what the page last heard is not the run's state once the server is gone: the
        # status and bar are hidden while the connection is lost, and a note says why
        ui.add_css(
            ".mjx-offline-note{display:none} body.mjx-offline .mjx-offline-note{display:block}"
            " body.mjx-offline .mjx-live{visibility:hidden}"
        )
        ui.add_body_html(
            "<script>setInterval(() => document.body.classList.toggle('mjx-offline', "
            "!!window.socket && window.did_handshake === true && !window.socket.connected),"
            " 500);</script>"
        )

    def handle(
        self,
        command: str,
        ended: Callable[[jobs.Job, jobs.Progress], None],
        shown: Callable[[jobs.Job], None] | None = None,
    ) -> None:
        """ended(job, progress) draws the results of a run of command when it ends;
        shown(job) fills the tab from a run of command the panel shows without this page
        having started it (after a reload, or chosen in the runs list)."""
        self.handlers[command] = ended
        if shown is not None:
            self.shown[command] = shown

    def busy(self, where: ui.label) -> bool:
        """True (and says so in where) while a run is current: no second run starts.
        Every start handler asks this first, so it also logs that a start was asked for."""
        if self.job is not None:
            log.info(
                "a start was asked for (tab %s): refused, %r is current",
                self.owner,
                self.title.text,
            )
            where.set_text("a run is in progress: wait for it or cancel it")
            return True
        log.info("a start was asked for (tab %s)", self.owner)
        return False

    async def confirmed(self, refusal: str, where: ui.label) -> list[str] | None:
        """Before a run starts: [] when it is not long (refusal '': ``jobs.long_run``
        found nothing to ask), ["--yes"] once the user confirms a long one in the
        dialog (the CLI's flag that starts it), None when the user does not (and so in
        where) or when another start took the panel while the dialog waited
        (:meth:`busy`, said in where)."""
        if not refusal:
            return []
        if not await self.question.ask(refusal):
            where.set_text(f"not started: {refusal}")
            return None
        return None if self.busy(where) else ["--yes"]

    def start(
        self,
        title: str,
        job: jobs.Job,
        where: ui.label,
        on_end: Callable[[jobs.Progress], None] | None = None,
    ) -> bool:
        """Start job and show it; when the panel sees it end it calls on_end(progress),
        or the handler of its command (:meth:`handle`). False, and why in where, when a
        run of this server (any browser tab's) writes its folder now (``Runs.taken``)."""
        if self.job is not None:  # callers check busy() first
            raise RuntimeError(f"a run is current ({self.title.text}): cannot start {title}")
        taken = self.runs.taken(job, self.owner)
        if taken:
            log.info("refused %r (tab %s): %s", title, self.owner, taken)
            where.set_text(taken)
            return False
        job.title = title
        log.info("starting %r (tab %s): %s", title, self.owner, job.command_line)
        job.start(self.runs.workers)
        self.runs.add(job, self.owner)
        self._show(job, on_end)
        self.status.set_text("starting ...")
        return True

    def reattach(self, owner: str) -> None:
        """This browser tab's id: show the run it started before a reload, if any (a
        run that ended meanwhile is shown ended, its results drawn)."""
        self.owner = owner
        job = self.runs.last_of(owner)
        if job is not None and self.job is None:
            self._show_other(job)

    def _show_other(self, job: jobs.Job) -> None:
        """A run this page did not start, shown: its tab filled from its record, then its
        state (and, if it ended, its results)."""
        self._show(job, None)
        shown = self.shown.get(job.argv[0] if job.argv else "")
        if shown is not None:
            shown(job)
        self.poll()

    def _show(self, job: jobs.Job, on_end) -> None:
        self.job = job
        if on_end is None:
            handler = self.handlers.get(job.argv[0] if job.argv else "")
            on_end = None if handler is None else (lambda p: handler(job, p))
        self.on_end = on_end
        self.title.set_text(job.title)
        self.command.set_content(job.command_line)
        self.where.set_text(job.where)
        self.bar.set_value(0)
        self.warnings.set_text("")
        self.bar.props(remove="indeterminate")
        if job.total is None:
            self.bar.props("indeterminate")
        self.cancel_button.set_visibility(True)
        self.card.set_visibility(True)

    def cancel(self) -> None:
        if self.job is not None:
            self.job.cancel()

    def list_runs(self) -> None:
        """The runs list's entries, newest first, each saying whether it runs."""
        jobs_now = list(self.runs)  # oldest first: a run's key stays as runs are added
        options = {
            k: f"{j.title}" + (" (running)" if j.running else "")
            for k, j in reversed(list(enumerate(jobs_now)))
        }
        if jobs_now != self.listed or options != self.history.options:
            self.listed = jobs_now
            self.history.set_options(options)

    def on_history(self, e) -> None:
        """A run chosen in the list: shown here, its results drawn (not while another
        run is current)."""
        if e.value is None or e.value >= len(self.listed):
            return
        job = self.listed[e.value]
        if self.job is not None and self.job is not job:
            ui.notify("a run is current: wait for it or cancel it", type="warning")
        elif self.job is None:
            self._show_other(job)

    def poll(self) -> None:
        """Show the run's progress; when it has ended, free the panel and call on_end."""
        self.list_runs()
        others = [j for j in self.runs if j.running and j is not self.job]
        self.others.set_text(
            "also running on this server: " + "; ".join(j.title for j in others) if others else ""
        )
        if self.job is None:
            return
        p = self.job.poll()
        if p.fraction is not None:  # a count (also one learnt as the run goes)
            self.bar.props(remove="indeterminate")
            self.bar.set_value(p.fraction)
        self.status.set_text(status_line(p))
        self.warnings.set_text("warning: " + "; ".join(p.warnings) if p.warnings else "")
        if p.state == "running":
            return
        refused = self.job.refused_as_long()
        if refused:  # the CLI's own estimate: asked here, started again with --yes
            job, on_end = self.job, self.on_end
            self.job, self.on_end = None, None
            job.discard_log()  # it never started: its name stays free
            self.runs.forget(job)
            self.cancel_button.set_visibility(False)
            self.status.set_text(f"not started: {refused}")
            background_tasks.create(self.ask_again(job, on_end, refused), name="long run")
            return
        self.bar.props(remove="indeterminate")
        if p.state == "complete":
            self.bar.set_value(1.0)
        self.cancel_button.set_visibility(False)
        on_end = self.on_end
        self.job, self.on_end = None, None
        try:
            if on_end is not None:
                on_end(p)
        except (OSError, ValueError, KeyError) as err:
            self.status.set_text(f"{p.state}; its results cannot be read: {err}")

    async def ask_again(self, job: jobs.Job, on_end, refused: str) -> None:
        """A run the CLI refused as long (its estimate, where the page's own count
        could not say it first: a calibration's fit): asked in the dialog, and started
        again with --yes once confirmed."""
        if not await self.question.ask(refused):
            return
        if self.job is None:  # no other run was started meanwhile
            self.start(job.title, job.again("--yes"), self.status, on_end)
        else:
            self.status.set_text("a run is in progress: wait for it or cancel it")


def status_line(p: jobs.Progress) -> str:
    """The panel's one line: state, count, rate, time left, time so far, message."""
    parts = [p.state]
    if p.done is not None:
        parts.append(f"{p.done}/{p.total} {p.unit}")
    if p.rate:
        parts.append(f"{p.rate:.1f} {p.unit} per s")
    if p.eta_s is not None and p.state == "running":
        parts.append(f"about {p.eta_s:.0f} s left")
    parts.append(f"{p.elapsed_s:.0f} s")
    if p.message:
        parts.append(p.message)
    return ", ".join(parts)
