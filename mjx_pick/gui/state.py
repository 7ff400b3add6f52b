"""What the tabs of one browser tab share (no web framework).

Tab 1 imports an object, tab 4 opens a run; the later tabs and the studies read them.
That shared state is this one small object, passed to each tab that needs it -- nothing
else is shared between tabs except the gripper tab's settings form
(:mod:`mjx_pick.gui.page.settings_form`) and the job panel that owns the current run
(:mod:`mjx_pick.gui.page.job_panel`), both passed explicitly too.
"""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path
from typing import TYPE_CHECKING

from mjx_pick.gui import workfolder

if TYPE_CHECKING:
    from mjx_pick.core.objects import ObjectModel
    from mjx_pick.outputs.reporting import Run

RUN_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9._-]{0,79}$")
RUN_NAME_RULE = "letters, digits, '.', '_' and '-' only (at most 80)"


def server_log(workdir: Path) -> Path:
    """The GUI server's log file in a work folder (see :attr:`PageState.server_log`)."""
    return Path(workdir) / "logs" / "_gui-server.log"


@dataclasses.dataclass
class PageState:
    """One browser tab's shared state; every field is set by one tab only."""

    workdir: Path  # every run's output folder is workdir/<run name>
    obj: ObjectModel | None = None  # the imported object (tab 1, import)
    obj_args: list[str] = dataclasses.field(default_factory=list)  # obj as CLI arguments
    run: Run | None = None  # the evaluate folder open in tab 4 (analyze)

    @property
    def uploads(self) -> Path:
        """Where uploaded files are stored."""
        return self.workdir / "inputs" / "uploads"

    def log(self, name: str) -> Path:
        """The log file of a run the page starts."""
        return self.workdir / "logs" / f"{name}.log"

    @property
    def server_log(self) -> Path:
        """The server's own log (errors of the page's handlers with their tracebacks);
        no run's log has its name (a run's name starts with a letter or a digit)."""
        return server_log(self.workdir)

    def where(self, path: Path) -> str:
        """A file of the work folder as the page names it: relative to the work folder."""
        try:
            return f"{Path(path).relative_to(self.workdir)} in the work folder"
        except ValueError:
            return str(path)

    def inside(self, text: str) -> Path | None:
        """The folder a user typed, when it lies inside the work folder (a relative name
        is read from the work folder; links are followed before the test), else None:
        the page opens nothing else, so a server reachable beyond this machine cannot
        be used to read it."""
        text = (text or "").strip()
        if not text:
            return None
        return workfolder.inside(text, self.workdir)

    def run_folder(self, name: str) -> Path | None:
        """The output folder of a run named name, or None if the name is not allowed."""
        name = name.strip()
        return self.workdir / name if RUN_NAME.match(name) else None
