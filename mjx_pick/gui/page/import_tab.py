"""Tab 1, *Import object model*: upload an image or a mesh, or choose a shipped object.

Sets the page's object (:attr:`PageState.obj`, and the same object as CLI arguments for
every run) and shows its segmentation and outline.
"""

from __future__ import annotations

import logging
import re
from importlib import resources
from pathlib import Path

from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.core.objects import DENSITY_PLAUSIBLE_KG_M3, MESH_SUFFIXES
from mjx_pick.gui import views
from mjx_pick.gui.formatting import page_text, raised_in, unexpected_text
from mjx_pick.gui.page.widgets import (
    checked,
    error_label,
    picture,
    received,
    show_picture,
    upload,
    warning_label,
)
from mjx_pick.gui.state import PageState
from mjx_pick.gui.uploads import (
    MESH_MAX_BYTES,
    UPLOAD_TYPES,
    check_upload,
    object_refused,
    save_upload,
)

UPLOADED = "(uploaded file)"
# an import's unexpected error, with its traceback (the server's log)
log = logging.getLogger(__name__)


# the library's plausible density's upper end, in g/cm^3 (above osmium's 22.6)
DENSEST_G_CM3 = DENSITY_PLAUSIBLE_KG_M3[1] / 1000.0


def mass_warning(obj) -> str:
    """A warning when the mass cannot be the part's: denser than any solid in the
    volume of its outline times its height (at least its true volume)."""
    volume_cm3 = obj.area_mm2 * obj.height_mm / 1000.0
    density = obj.mass_kg * 1e3 / max(volume_cm3, 1e-9)
    if density <= DENSEST_G_CM3:
        return ""
    return (
        f"warning: {obj.mass_kg * 1e3:g} g in at most {volume_cm3:.3g} cm³ is "
        f"{density:.3g} g/cm³, denser than any solid: check the mass (in grams)"
    )


class ImportTab:
    def __init__(self, state: PageState, on_import=None):
        """on_import(): runs after each import, also a failed one (other tabs forget
        what they drew for the object before)."""
        from mjx_pick.core.objects import asset_manifest

        self.state = state
        self.on_import = on_import
        self.upload_path: Path | None = None
        self.manifest = asset_manifest()
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-96"):
                ui.label(
                    "A top-down image (PNG/JPG, up to 20 MB), a mesh (STL/OBJ/PLY, up "
                    "to 50 MB), or a shipped object."
                ).classes("text-sm")
                self.upload = upload(
                    "upload image or mesh",
                    ",".join(UPLOAD_TYPES),
                    MESH_MAX_BYTES,
                    self.on_upload,
                    self.refuse_upload,
                    object_refused,
                    "object-upload",
                ).classes("w-full")
                self.upload_error = error_label().props('data-testid="upload-error"')
                self.asset = ui.select(
                    [UPLOADED, *sorted(self.manifest)],
                    value="block",
                    label="object",
                    on_change=self.on_asset,
                )
                self.px_per_mm = ui.number("image scale (px per mm)", value=10.0, step=0.5)
                self.thickness = ui.number("thickness (mm)", value=20.0, step=1)
                self.mass = ui.number("mass (g)", value=43.2, step=1)
                self.unit = ui.select(["mm", "m"], value="mm", label="mesh unit").classes("w-40")
                # a mesh of several disconnected bodies is refused unless this is ticked
                # (the library's largest_body, the CLI's --largest-body): the refusal
                # names this box, so the page must have it
                self.largest = ui.checkbox("largest body only (a mesh of several bodies)")
                self.largest.props('data-testid="largest-body"')
                for w in (self.unit, self.largest):
                    w.set_visibility(False)  # shown for an uploaded mesh only
                self.on_asset()
                ui.button("Import object", on_click=self.import_object).props(
                    'data-testid="import"'
                )
                self.import_error = error_label().props('data-testid="import-error"')
                self.import_warning = warning_label("import-warning")
            with ui.column().classes("grow"):
                self.object_info = ui.label("No object imported yet.").props(
                    'data-testid="object-info"'
                )
                self.object_image = picture("w-full max-w-3xl").props('data-testid="object-image"')

    def fields(self) -> dict:
        return {"px_per_mm": self.px_per_mm, "thickness_mm": self.thickness, "mass_g": self.mass}

    def on_asset(self, _=None) -> None:
        """A shipped object fills in its scale, thickness and mass."""
        if self.asset.value != UPLOADED:
            self.show_mesh_fields(False)
        if self.asset.value in self.manifest:
            entry = self.manifest[self.asset.value]
            self.px_per_mm.value = entry["px_per_mm"]
            self.thickness.value = entry["thickness_mm"]
            self.mass.value = round(entry["mass_g"], 3)

    async def on_upload(self, e) -> None:
        self.upload_error.set_text("")
        self.import_error.set_text("")
        got = await received(
            e, self.upload, lambda n, d: check_upload(n, len(d), d), self.refuse_upload
        )
        if got is None:
            return
        name, data = got
        try:
            self.upload_path = await run.io_bound(
                save_upload, data, name, self.state.uploads, self.state.workdir
            )
        except (OSError, ConfigError) as err:
            self.refuse_upload(f"{name}: cannot be stored ({err})")
            return
        self.asset.value = UPLOADED
        self.show_mesh_fields(Path(name).suffix.lower() in MESH_SUFFIXES)
        self.upload_error.set_text("")
        self.object_info.set_text(
            f"uploaded {name}: set its scale, thickness and mass, then Import object"
        )

    def refuse_upload(self, why: str) -> None:
        """A file refused -- by the browser (its type or size) or here: said by its name
        and why until another file or object is chosen, and it replaces the upload
        before it: Import takes the refused file, that is nothing, never the earlier
        file, and no later tab runs on the object imported from that."""
        from_upload = self.asset.value == UPLOADED
        self.upload_error.set_text(why)
        self.upload_path = None
        self.asset.value = UPLOADED
        if from_upload and self.state.obj is not None:
            self.forget_object()

    def show_mesh_fields(self, mesh: bool) -> None:
        """A mesh has a unit; an image has a scale and a thickness."""
        self.unit.set_visibility(mesh)
        self.largest.set_visibility(mesh)
        self.px_per_mm.set_visibility(not mesh)
        self.thickness.set_visibility(not mesh)

    def source(self) -> tuple[str, Path | None]:
        """The object's CLI argument (a file or a shipped name) and its image, if any."""
        if self.asset.value == UPLOADED:
            if self.upload_path is None:
                raise ConfigError("upload an image or a mesh first, or choose a shipped object")
            return str(self.upload_path), self.upload_path
        entry = self.manifest[self.asset.value]
        image = Path(str(resources.files("mjx_pick.assets") / "objects" / entry["image"]))
        return self.asset.value, image

    async def import_object(self) -> None:
        from mjx_pick.core.objects import load_object

        self.import_error.set_text("")
        if self.asset.value != UPLOADED or self.upload_path is not None:
            self.upload_error.set_text("")  # an earlier upload's message is history now
        self.import_warning.set_text("")
        for w in self.fields().values():
            w.error = None
        try:
            source, image = self.source()
        except ConfigError as err:
            self.import_error.set_text(str(err))
            return
        is_mesh = Path(source).suffix.lower() in MESH_SUFFIXES
        needed = ("mass_g",) if is_mesh else ("px_per_mm", "thickness_mm", "mass_g")
        # each by the number's one rule (core.numbers), as the CLI and the library check
        # it: a value no library could build an object from never reaches one
        values = {k: checked(self.fields()[k], k) for k in needed}
        if any(v is None for v in values.values()):
            return
        kwargs = {"mass_g": float(values["mass_g"])}
        args = [source, "--mass-g", repr(float(values["mass_g"]))]
        if is_mesh:
            kwargs["unit"] = self.unit.value
            args += ["--unit", self.unit.value]
            if self.largest.value:
                kwargs["largest_body"] = True
                args.append("--largest-body")
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
            self.forget_object()
            self.show_error(str(err))
            return
        except Exception as err:  # noqa: BLE001 - a bad file must not show a traceback
            self.forget_object()
            log.error("importing %s failed", source, exc_info=err)
            self.import_error.set_text(
                unexpected_text(
                    f"importing {Path(source).name}",
                    raised_in(err),
                    type(err).__name__,
                    self.state.where(self.state.server_log),
                )
            )
            return
        self.state.obj, self.state.obj_args = obj, args
        self.import_warning.set_text(mass_warning(obj))
        if self.on_import is not None:
            self.on_import()
        self.show_object(obj)
        show_picture(self.object_image, png)

    async def restore(self, obj, args: list[str]) -> None:
        """The object this browser tab imported before a reload of the page."""
        self.state.obj, self.state.obj_args = obj, args
        self.show_object(obj)
        show_picture(self.object_image, await run.io_bound(views.object_png, obj, None))

    def show_object(self, obj) -> None:
        self.object_info.set_text(
            f"{obj.name}: outline {obj.area_mm2:.0f} mm², length {obj.length_mm:.1f} mm, "
            f"height {obj.height_mm:g} mm, mass {obj.mass_kg * 1e3:.1f} g"
        )

    def forget_object(self) -> None:
        """A failed import: no object, so no later tab runs on the one imported before."""
        self.state.obj, self.state.obj_args = None, []
        self.object_info.set_text("No object imported.")
        self.object_image.set_visibility(False)
        if self.on_import is not None:
            self.on_import()

    def show_error(self, message: str) -> None:
        """An object's ConfigError, in the tab's words, under the field it names, else
        above the button."""
        words = object_words(message)
        for key, widget in self.fields().items():
            if f"object.{key}" in message or message.startswith(key):
                widget.error = words
                return
        self.import_error.set_text(words)


# the object's inputs as this tab names them (a library message names the arguments)
OBJECT_LABELS = {
    "px_per_mm": "image scale (px per mm)",
    "thickness_mm": "thickness (mm)",
    "mass_g": "mass (g)",
    "density_kg_m3": "density (kg/m³)",
}
_CLI_FLAG = re.compile(r" \(--[a-z0-9-]+\)")


def object_words(message: str) -> str:
    """An object's error in this tab's words: its fields' labels for the library's
    argument names, no CLI flags, no paths of the software's files."""
    words = _CLI_FLAG.sub("", page_text(message))
    for name, label in OBJECT_LABELS.items():
        words = re.sub(rf"(?<![\w.]){name}\b", label, words)
    return words
