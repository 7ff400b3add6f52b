"""The settings form of tab 2: gripper preset or TOML, backend, and every settings field.

It lives on the gripper tab, but every run reads it: :meth:`SettingsForm.read` checks the
fields (each error under its field; the page switches to tab 2 to show them) and
:meth:`SettingsForm.cli_flags` writes them as the CLI's TOML files for a run.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from nicegui import ui

from mjx_pick.core.config import ConfigError
from mjx_pick.gui import forms, jobs
from mjx_pick.gui.page.widgets import error_label, file_error_label, received, upload
from mjx_pick.gui.uploads import TOML_MAX_BYTES, check_toml_upload, toml_refused

PRESET = "robotiq-2f85"  # the gripper the page starts with


class SettingsForm:
    """The gripper, pick-point, procedure and contact settings every run uses."""

    def __init__(self, show: Callable[[], None]):
        """show: brings the form into view (switches to tab 2) when a field is wrong."""
        from mjx_pick.core.gripper import load_gripper, preset_names

        self.show = show
        self.base_contact = None  # calibrated contact parameters, once adopted
        self.base_grasp = self.base_picks = None  # a run's, once loaded from its folder
        self.inputs: dict[str, ui.number] = {}
        with ui.row().classes("items-end"):
            self.preset = ui.select(
                preset_names(),
                value=PRESET,
                label="gripper preset",
                on_change=self.on_preset,
            ).classes("w-56")
            self.backend = ui.select(
                forms.backend_choices(), value=jobs.DEFAULT_BACKEND, label="backend"
            )
            self.backend.classes("w-40")
            ui.label(forms.backend_note()).classes("text-xs max-w-xs").props(
                'data-testid="backend-note"'
            )
        with ui.row().classes("items-center"):
            self.toml_upload = upload(
                "or load a gripper TOML",
                ".toml",
                TOML_MAX_BYTES,
                self.on_gripper_toml,
                self.refuse_toml,
                toml_refused,
                "gripper-upload",
            ).classes("w-72")
            self.toml_error = file_error_label().props('data-testid="toml-error"')
        self.settings_error = error_label().props('data-testid="settings-error"')
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
                    self.inputs[f.key].tooltip(f.hint)
        self.base_gripper = load_gripper(PRESET)
        self.fill(self.base_gripper)

    def fill(self, gripper) -> None:
        """A gripper's fields; the other fields keep their values (defaults if empty)."""
        for key, value in forms.defaults(gripper).items():
            if key.startswith("gripper.") or not self.inputs[key].value:
                self.inputs[key].value = value
            self.inputs[key].error = None

    def on_preset(self, _=None) -> None:
        from mjx_pick.core.gripper import load_gripper

        self.base_gripper = load_gripper(self.preset.value)
        self.toml_error.set_text("")  # the gripper of a refused TOML is not in use
        self.fill(self.base_gripper)
        # the preset's force and speed ranges bound F_d and the closing speed
        g = self.base_gripper
        f_d = self.inputs["grasp.grip_force_n"]
        f_d.value = min(max(f_d.value or 0, g.force_min_n), g.force_max_n)
        v = self.inputs["grasp.closing_speed_mm_s"]
        v.value = min(max(v.value or 0, g.speed_min_mm_s), g.speed_max_mm_s)

    async def on_gripper_toml(self, e) -> None:
        self.toml_error.set_text("")
        got = await received(e, self.toml_upload, check_toml_upload, self.refuse_toml)
        if got is None:
            return
        name, data = got
        try:
            gripper = forms.gripper_from_toml(data.decode("utf-8"), where=name)
        except UnicodeDecodeError:
            self.refuse_toml(f"{name}: not a UTF-8 text file")
            return
        except ConfigError as err:
            self.refuse_toml(str(err))
            return
        self.base_gripper = gripper
        self.fill(gripper)
        self.toml_error.set_text("")

    def refuse_toml(self, why: str) -> None:
        """A gripper TOML refused (by the browser or here): why, and that the fields
        keep the gripper they show -- a refused file changes nothing."""
        self.toml_error.set_text(f"{why} (the gripper in use stays {self.base_gripper.name})")

    def restore(self, before: SettingsForm) -> None:
        """The settings of this browser tab's page before a reload."""
        self.preset.value = before.preset.value
        self.backend.value = before.backend.value
        self.base_gripper, self.base_contact = before.base_gripper, before.base_contact
        self.base_grasp, self.base_picks = before.base_grasp, before.base_picks
        for key, widget in self.inputs.items():
            widget.value = before.inputs[key].value

    def adopt_run(self, settings, picks, backend: str | None) -> None:
        """A run's own settings (read from its folder), every field of them: its gripper,
        contact, procedure and pick-point settings, and its backend."""
        self.base_gripper, self.base_contact = settings.gripper, settings.contact
        self.base_grasp, self.base_picks = settings.grasp, picks
        values = forms.defaults(
            settings.gripper, picks=picks, grasp=settings.grasp, contact=settings.contact
        )
        for key, value in values.items():
            self.inputs[key].value = int(value) if float(value).is_integer() else value
            self.inputs[key].error = None
        if backend in (self.backend.options or []):
            self.backend.value = backend
        elif backend is not None:  # said, never silently another one
            why = forms.backend_problems().get(backend, "not offered by the page")
            self.settings_error.set_text(
                f"the run ran on backend {backend}, which cannot run here ({why}): the "
                f"backend stays {self.backend.value}"
            )

    def adopt_contact(self, contact) -> None:
        """Fitted contact parameters (the calibration study) for every later run."""
        self.base_contact = contact
        for key in ("contact.pad_friction", "contact.table_friction"):
            self.inputs[key].value = float(getattr(contact, key.split(".")[1]))

    def read(self) -> forms.Settings | None:
        """The settings, or None with each error next to its field (and the form shown)."""
        values = {k: w.value for k, w in self.inputs.items()}
        settings, errors = forms.build(
            values, self.base_gripper, self.base_contact, self.base_grasp, self.base_picks
        )
        for key, widget in self.inputs.items():
            widget.error = errors.get(key)
        self.settings_error.set_text(errors.get("", ""))
        if settings is None:
            self.show()
        return settings

    def cli_flags(self, settings: forms.Settings, workdir: Path, out: Path) -> list[str]:
        """The CLI flags of a run into out: its settings written under workdir/inputs/."""
        folder = workdir / "inputs" / out.name
        paths = forms.write_inputs(settings, folder, workdir)
        return forms.cli_flags(settings, paths) + ["--backend", self.backend.value]
