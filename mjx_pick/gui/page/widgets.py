"""Small pieces every tab uses: error labels, pictures, number checks, result tables."""

from __future__ import annotations

from pathlib import Path

from nicegui import ui

from mjx_pick.gui.formatting import column_label, fmt_cell
from mjx_pick.gui.state import RUN_NAME_RULE, PageState
from mjx_pick.gui.views import data_uri


def error_label() -> ui.label:
    """A red line for a message that belongs to no single field."""
    return ui.label("").classes("text-negative text-sm").props('role="alert"')


def upload(label: str, accept: str, max_bytes: int, on_upload, on_rejected, testid: str):
    """A file upload sent as soon as it is chosen: accept lists the file types
    (".csv", ".png,.stl"), max_bytes the largest file; on_rejected runs for a file
    refused by either (the caller says why, under the widget)."""
    return ui.upload(
        label=label,
        auto_upload=True,
        max_file_size=max_bytes,
        on_upload=on_upload,
        on_rejected=on_rejected,
    ).props(f'accept="{accept}" data-testid="{testid}"')


def picture(classes: str = "w-full max-w-2xl") -> ui.image:
    """An image shown only once it has a picture (``set_source`` + ``set_visibility``)."""
    image = ui.image().props("no-transition no-spinner").classes(classes)
    image.set_visibility(False)
    return image


def show_picture(image: ui.image, data: bytes, mime: str = "image/png") -> None:
    """Show PNG (or GIF) bytes in a picture."""
    image.set_source(data_uri(data, mime))
    image.set_visibility(True)


def whole(widget, lo: int, hi: int) -> int | None:
    """A whole number field in [lo, hi], or None with the message under it."""
    v = widget.value
    widget.error = None
    if v is None or v != int(v) or not lo <= v <= hi:
        widget.error = f"a whole number from {lo} to {hi:,}"
        return None
    return int(v)


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
