"""Tab 2, *Set gripper parameters*: the settings form and a test of one pick-point.

The form (:class:`~mjx_pick.gui.page.settings_form.SettingsForm`) is built here, where
the user sees it, and handed to every tab that starts a run.
"""

from __future__ import annotations

from collections.abc import Callable

from nicegui import run, ui

from mjx_pick.core.config import ConfigError
from mjx_pick.gui.formatting import FRAME_NAME, PICK_LABELS
from mjx_pick.gui.one_pick import simulate_one_pick
from mjx_pick.gui.page.settings_form import SettingsForm
from mjx_pick.gui.page.widgets import checked, error_label, need_object, picture, show_picture
from mjx_pick.gui.state import PageState

# one frame for every pick-point the page shows or takes (named in formatting)
FRAME = FRAME_NAME[0].upper() + FRAME_NAME[1:]


class GripperTab:
    def __init__(self, state: PageState, show: Callable[[], None]):
        """show: switches the page to this tab (when a settings field is wrong)."""
        self.state = state
        with ui.row().classes("w-full no-wrap items-start"):
            with ui.column().classes("w-[44rem]"):
                self.form = SettingsForm(show)
            with ui.column().classes("grow"):
                ui.label("Test simulation of one pick-point").classes("font-bold")
                ui.label(
                    f"{FRAME}: where the object's centre (the + of tab 1) lies from the "
                    "gripper's centre, x along the fingers' closing direction, y across "
                    "it, and the object's yaw, counter-clockwise seen from above. Tab 3's "
                    "and tab 4's maps and tab 4's table use it too, with the same arrows "
                    "in their corner; a click on tab 3's map fills it in."
                ).classes("text-xs max-w-xl").props('data-testid="test-frame"')
                with ui.row():
                    self.x = ui.number(PICK_LABELS["x_mm"], value=0.0, step=1).classes("w-56")
                    self.y = ui.number(PICK_LABELS["y_mm"], value=0.0, step=1).classes("w-56")
                    self.yaw = ui.number(PICK_LABELS["yaw_deg"], value=0.0, step=5).classes("w-56")
                ui.button("Test simulation", on_click=self.test_pick).props(
                    'data-testid="test-pick"'
                )
                self.error = error_label().props('data-testid="test-pick-error"')
                self.info = ui.markdown("").props('data-testid="test-info"')
                self.pose = picture("w-full max-w-md").props('data-testid="test-pose"')
                self.plot = picture()

    def use_pick(self, x: float, y: float, yaw: float, what: str) -> None:
        """A pick-point chosen elsewhere (tab 3's map) into the test fields."""
        self.x.value, self.y.value, self.yaw.value = x, y, yaw
        self.info.set_content(f"{what}: press Test simulation")
        self.plot.set_visibility(False)
        self.pose.set_visibility(False)
        ui.notify(f"{what} ({x:g}, {y:g}, {yaw:g}) is in tab 2's test simulation")

    async def test_pick(self) -> None:
        """Check and simulate the pick-point of the x, y and yaw fields, in a worker thread."""
        self.error.set_text("")
        if not need_object(self.state, self.error):
            return
        settings = self.form.read()
        if settings is None:
            return
        # each by its one rule (core.numbers), as a picks file's rows are checked
        pose = [
            checked(w, k) for w, k in ((self.x, "x_mm"), (self.y, "y_mm"), (self.yaw, "yaw_deg"))
        ]
        if any(v is None for v in pose):
            return
        self.info.set_content("simulating one pick-point ...")
        try:
            result = await run.io_bound(
                simulate_one_pick,
                self.state.obj,
                settings,
                *map(float, pose),
                self.form.backend.value,
            )
        except ConfigError as err:
            self.info.set_content("")
            self.error.set_text(str(err))
            return
        self.info.set_content(result["text"])
        show_picture(self.pose, result["pose"])
        if result["plot"] is not None:
            show_picture(self.plot, result["plot"])
        else:
            self.plot.set_visibility(False)
