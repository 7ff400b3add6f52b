"""Small pieces every tab uses: error labels, pictures, number checks, result tables."""

from __future__ import annotations

from pathlib import Path

from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.core.numbers import INPUTS
from mjx_pick.gui.formatting import column_label, fmt_cell
from mjx_pick.gui.forms import file_words, page_words
from mjx_pick.gui.search import Search, SearchStopped
from mjx_pick.gui.state import RUN_NAME_RULE, PageState
from mjx_pick.gui.uploads import browser_refused
from mjx_pick.gui.views import data_uri


class MessageLabel(ui.label):
    """A label that shows messages (errors, warnings, a run's state): every text set
    on it passes ``forms.page_words`` -- no path of the software's own files, no key,
    flag or advice of the program's reaches the page, whichever library wrote it."""

    words = staticmethod(page_words)

    def set_text(self, text: str) -> None:
        super().set_text(self.words(text) if text else text)


def drawn_grasps_select(testid: str, count: ui.number | None = None) -> ui.select:
    """Where a study draws its grasps (``--grasps``): top-down pick-points or antipodal
    grasps on the part's surface (a grasp file: tab 3's evaluate). count: the study's
    number of them, its label following the choice (None: a field labelled otherwise)."""
    from mjx_pick.gui.grasp_input import ANTIPODAL, SOURCES, TOPDOWN

    def relabel(e) -> None:
        if count is not None:
            count.props(f'label="{"grasps" if e.value == ANTIPODAL else "pick-points"}"')

    return ui.select(
        {k: SOURCES[k] for k in (TOPDOWN, ANTIPODAL)},
        value=TOPDOWN,
        label="grasps from",
        on_change=relabel,
    ).props(f'data-testid="{testid}"')


async def received(e, upload, refused, refuse) -> tuple[str, bytes] | None:
    """An upload event's file: (its name, its bytes), the upload widget reset (a
    corrected file of the same name may follow); None, and why through refuse(text),
    when refused(name, data) says why ('' when accepted)."""
    name = e.file.name
    data = await e.file.read()
    upload.reset()
    problem = refused(name, data)
    if problem:
        refuse(problem)
        return None
    return name, data


def error_label() -> MessageLabel:
    """A red line for a message that belongs to no single field."""
    return MessageLabel("").classes("text-negative text-sm").props('role="alert"')


class FileMessageLabel(MessageLabel):
    """A label for what is wrong inside a file the user wrote (a gripper TOML, a grasp
    file, trials): its keys and columns are the user's own words there (``stroke_mm =
    -5`` on its line), so they stay; the software's paths, the CLI's flags and advice
    become the page's (``forms.file_words``)."""

    words = staticmethod(file_words)


def file_error_label() -> FileMessageLabel:
    """A red line for what is wrong inside a file the user wrote."""
    return FileMessageLabel("").classes("text-negative text-sm").props('role="alert"')


def warning_label(testid: str) -> MessageLabel:
    """A line for a warning (a library's or a run's), in the warning colour."""
    return MessageLabel("").classes("text-warning text-sm").props(f'data-testid="{testid}"')


class SearchProgress:
    """A search for feasible pick-points the page waits for: a line saying how far it
    is, a bar and a Stop button while it runs (a search that finds few feasible poses
    checks up to a million candidates: minutes, never silent)."""

    def __init__(self, testid: str):
        self.line = MessageLabel("").classes("text-sm").props(f'data-testid="{testid}"')
        with ui.row().classes("items-center w-full no-wrap") as self.running_row:
            self.bar = ui.linear_progress(value=0, show_value=False).classes("grow")
            ui.button("Stop", on_click=self.stop, color="red").props(
                f'dense data-testid="{testid}-stop"'
            )
        self.running_row.set_visibility(False)
        self.search: Search | None = None
        self.timer = ui.timer(0.3, self.show, active=False)

    @property
    def running(self) -> bool:
        return self.search is not None

    async def run(self, search: Search, fn, *args):
        """fn(*args, progress=search) in a worker thread, shown here as it goes: its
        result, or None once stopped (the line then says how far it got)."""
        self.search = search
        self.line.set_text("checking candidate poses ...")
        self.bar.set_value(0)
        self.running_row.set_visibility(True)
        self.timer.activate()
        try:
            result = await run.io_bound(fn, *args, progress=search)
        except SearchStopped:
            self.line.set_text(search.stopped_text())
            return None
        except Exception:  # it ended (no feasible pick-point, ...): said so, not "so far"
            self.line.set_text(search.ended_text())
            raise
        finally:
            self.timer.deactivate()
            self.running_row.set_visibility(False)
            self.search = None
        self.line.set_text("")
        return result

    def show(self) -> None:
        if self.search is not None and self.search.drawn and not self.search.stopping:
            self.line.set_text(self.search.text())
            self.bar.set_value(self.search.fraction)

    def stop(self) -> None:
        if self.search is not None:
            self.search.stop()
            self.line.set_text("stopping ...")

    def clear(self) -> None:
        """Forget what the last search said (the map it was for is gone)."""
        if not self.running:
            self.line.set_text("")


class StartQuestion:
    """A dialog that asks before a long run starts: the estimate in the page's words
    and two buttons, "Start it" and "Not now" (persistent: only they close it, so that
    no answer is taken from a stray click or key)."""

    def __init__(self) -> None:
        with ui.dialog().props('persistent data-testid="long-run-dialog"') as self.dialog:
            with ui.card().classes("max-w-xl"):
                ui.label("A long run").classes("font-bold")
                self.text = (
                    MessageLabel("").classes("text-sm").props('data-testid="long-run-question"')
                )
                with ui.row().classes("w-full justify-end"):
                    ui.button("Not now", on_click=lambda: self.dialog.submit(False)).props(
                        'flat data-testid="long-run-no"'
                    )
                    ui.button("Start it", on_click=lambda: self.dialog.submit(True)).props(
                        'data-testid="long-run-yes"'
                    )

    async def ask(self, refusal: str) -> bool:
        """Whether the user starts the run refusal describes (its estimate, as
        ``studies.duration.refuse_long`` says it)."""
        self.text.set_text(refusal[:1].upper() + refusal[1:])  # MessageLabel: page's words
        self.dialog.open()
        return bool(await self.dialog)


def upload(label: str, accept: str, max_bytes: int, on_upload, on_rejected, refused, testid: str):
    """A file upload sent as soon as it is chosen: accept lists the file types
    (".csv", ".png,.stl"), max_bytes the largest file. A file the browser refuses by
    either is said by the upload's own rule, refused(name, size) -- its name and why, as
    the server would say it -- in on_rejected(text)."""
    widget = ui.upload(
        label=label, auto_upload=True, max_file_size=max_bytes, on_upload=on_upload
    ).props(f'accept="{accept}" data-testid="{testid}"')
    widget.on(
        "rejected",
        lambda e: on_rejected(browser_refused(e.args, refused)),
        # QUploader's entries hold the File: only its name, size and the failed check
        js_handler="(entries) => emit(entries.map((e) => ({name: e.file.name, "
        "size: e.file.size, reason: e.failedPropValidation})))",
    )
    return widget


def picture(classes: str = "w-full max-w-2xl") -> ui.image:
    """An image shown only once it has a picture (``set_source`` + ``set_visibility``)."""
    image = ui.image().props("no-transition no-spinner").classes(classes)
    image.set_visibility(False)
    return image


def show_picture(image: ui.image, data: bytes, mime: str = "image/png") -> None:
    """Show PNG (or GIF) bytes in a picture."""
    image.set_source(data_uri(data, mime))
    image.set_visibility(True)


def checked(widget, name: str) -> int | float | None:
    """A number field checked by the input's one rule (``core.numbers.INPUTS[name]``,
    as the CLI and the library check it), or None with the rule under the field."""
    rule = INPUTS[name]
    widget.error = None
    value = widget.value
    try:
        if value is None or value == "":
            raise ConfigError("empty")
        return rule.check(name, value)
    except ConfigError:
        widget.error = rule_words(rule)
        return None


def checked_or_empty(widget, name: str) -> tuple[bool, int | float | None]:
    """A number field that may be left empty (the run then chooses, e.g. the chunk
    size), checked by the same rule: (True, None) when empty, (True, value) when it
    keeps the rule, (False, None) with the rule under the field otherwise."""
    if widget.value is None or widget.value == "":
        widget.error = None
        return True, None
    value = checked(widget, name)
    if value is None:
        widget.error += ", or empty"
        return False, None
    return True, value


def rule_words(rule) -> str:
    """What a number field takes, in the page's words: 'a whole number from 1 to 1,000'."""
    kind = "a whole number" if rule.integer else "a number"
    lo = None if rule.lo is None else f"{rule.lo:,.10g}"
    hi = None if rule.hi is None else f"{rule.hi:,.10g}"
    if lo is not None and hi is not None:
        low = f"above {lo}" if rule.lo_open else f"from {lo}"
        high = f"below {hi}" if rule.hi_open else f"to {hi}"
        return f"{kind} {low} {high}"
    if lo is not None:
        return f"{kind} {'above' if rule.lo_open else 'of at least'} {lo}"
    if hi is not None:
        return f"{kind} {'below' if rule.hi_open else 'of at most'} {hi}"
    return kind


def run_folder(state: PageState, name_widget, resume: bool = False) -> Path | None:
    """The output folder a run-name field names, or None with the reason under the field.

    A run's name is its folder's: a name already in the work folder is refused (its
    results and log stay as they are), unless the run resumes that folder."""
    name_widget.error = None
    out = state.run_folder(name_widget.value or "")
    if out is None:
        name_widget.error = RUN_NAME_RULE
    elif not resume and (out.exists() or state.log(out.name).exists()):
        name_widget.error = f"a run named {out.name} already exists here: choose another name"
        return None
    return out


def need_object(state: PageState, where: ui.label) -> bool:
    """True if tab 1 imported an object; else says so in where."""
    if state.obj is None:
        where.set_text("import an object first (tab 1)")
        return False
    return True


def show_rows(table: ui.table, rows: list[dict], keys: list[str]) -> None:
    """Rows of a study's JSON in a table, one column per key."""
    table.columns = [
        {"name": k, "label": column_label(k), "field": k, "align": "left"} for k in keys
    ]
    table.rows = [{k: fmt_cell(r.get(k)) for k in keys} for r in rows]
    table.update()
