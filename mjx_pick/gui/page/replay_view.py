"""Tab 4's 3-D replay of a pick-point: its bodies in NiceGUI's three.js scene (orbit,
zoom, pan), a time slider in seconds, play and pause, and the forces with the time
marked. The shapes and the poses of every row go to the browser once; a time moves the
bodies and the marker there (``replay3d.js``), so scrubbing waits for no server."""

from __future__ import annotations

import time
from pathlib import Path

from nicegui import run, ui
from nicegui.elements.scene.scene_object3d import Object3D

from mjx_pick.core.gripper import GripperSpec
from mjx_pick.gui import views
from mjx_pick.gui.replay3d import SceneReplay, row_at

# how often the server moves the slider while playing, s (the browser poses each move)
PLAY_TICK_S = 0.04
SPEEDS = {0.1: "0.1 x", 0.25: "0.25 x", 0.5: "0.5 x", 1.0: "real time"}
AXES_M = 0.05  # length of the drawn frame axes
SCENE_PX = 380  # the 3-D view's height in the page


class PickBodies(Object3D, component="replay3d.js"):
    """The bodies of a replayed pick-point, posed in the browser.

    args (kept for a scene that mounts again): shapes, track, time (s), the force
    chart's element id (its marker follows the time)."""

    def __init__(self) -> None:
        super().__init__(None, None, 0.0, None)

    def follow(self, chart: ui.echart) -> None:
        """Move chart's marker (its first series' markLine) with the time."""
        self.args[3] = chart.id
        self.run_method("follow", chart.id)

    def set_shapes(self, shapes: dict) -> None:
        self.args[0], self.args[1] = shapes, None
        self.run_method("set_shapes", shapes)

    def set_track(self, track: dict, t: float) -> None:
        self.args[1], self.args[2] = track, t
        self.run_method("set_track", track, t)

    def show_time(self, t: float) -> None:
        self.args[2] = t
        self.run_method("show_time", t)


class ReplayView:
    """The replay card (hidden until a pick-point is shown)."""

    def __init__(self) -> None:
        self.replay: SceneReplay | None = None  # the scene whose shapes the browser has
        self.trace: dict | None = None
        self.playing_since: tuple[float, float] | None = None  # (clock, slider time)
        self.showing: object | None = None  # the latest show() call
        with ui.card().classes("w-full max-w-2xl") as self.box:
            ui.label(
                "Replay in 3-D (the simulated bodies; drag to orbit, scroll to zoom, "
                "right-drag to pan) with the forces: move the time slider or play"
            ).classes("font-bold text-sm")
            self.outcome = ui.label("").classes("text-sm").props('data-testid="replay-outcome"')
            self.scene = (
                ui.scene(
                    height=SCENE_PX,
                    grid=(1.0, 100),  # 1 cm squares on the table
                    camera=ui.scene.perspective_camera(fov=40, near=0.002, far=20),
                    background_color="#f3f4f6",
                )
                .classes("w-full")
                # its own height: a canvas first measured while hidden has none to regain
                .style(f"height: {SCENE_PX}px")
                .props('data-testid="replay-scene"')
            )
            with self.scene:
                ui.scene.axes_helper(AXES_M)
                for name, at in (
                    ("x", (AXES_M, 0, 0)),
                    ("y", (0, AXES_M, 0)),
                    ("z", (0, 0, AXES_M)),
                ):
                    ui.scene.text(name, "font-size: 0.8em; color: #444").move(*at)
                self.bodies = PickBodies()
            ui.label(
                "world frame, m: x red (a vertical gripper's fingers close along it; a "
                "tilted grasp's gripper is turned from it), y green, z blue (up); the table "
                "at z = 0, 1 cm grid"
            ).classes("text-xs text-gray-600")
            with ui.row().classes("w-full items-center no-wrap"):
                self.play = ui.button(icon="play_arrow", on_click=self.toggle_play).props(
                    'flat round dense data-testid="replay-play" aria-label="play"'
                )
                self.time = ui.slider(min=0, max=1, step=0.005, value=0, on_change=self.on_time)
                self.time.classes("grow").props('label data-testid="replay-time"')
                self.speed = ui.select(SPEEDS, value=1.0, label="speed").classes("w-28")
            self.clock = ui.label("").classes("text-sm").props('data-testid="replay-clock"')
            self.chart = ui.echart({}).classes("w-full h-64")
        self.bodies.follow(self.chart)
        # a move in the browser poses the bodies there at once; the server hears it later
        self.time.on(
            "update:model-value",
            js_handler=(
                f"(t) => getElement({self.scene.id})"
                f'.run_method_on_component("{self.bodies.id}", "show_time", t)'
            ),
        )
        self.timer = ui.timer(PLAY_TICK_S, self.tick, active=False)
        self.box.set_visibility(False)

    def hide(self) -> None:
        self.pause()
        self.showing = None
        self.box.set_visibility(False)
        self.trace = None

    async def show(
        self,
        scene_xml: Path,
        gripper: GripperSpec,
        trace: dict,
        grip_force_n: float,
        outcome: str,
        failed: bool,
    ) -> None:
        """A pick-point's replay from its trace: the bodies of scene_xml (loaded once per
        scene) posed at every row, the forces, the slider at the first row."""
        self.pause()
        self.showing = token = object()  # a later call supersedes this one
        replay = self.replay
        if replay is None or not replay.is_for(scene_xml, gripper):
            replay = await run.io_bound(SceneReplay, scene_xml, gripper)
            if self.showing is not token:
                return
            self.bodies.set_shapes(replay.shapes_payload())
            self.replay = replay
        track = await run.io_bound(replay.track_payload, trace, failed)
        if self.showing is not token:
            return
        self.trace = trace
        t = trace["t_s"]
        self.chart.options.clear()
        self.chart.options.update(views.force_chart(trace, grip_force_n))
        self.chart.update()
        start, end = _seconds(t[0]), _seconds(t[-1])
        # numbers, not a props string: Quasar computes the value of a click or a drag from
        # them, and a string min makes that arithmetic a concatenation ("toFixed is not a
        # function", the slider dead to the mouse)
        self.time.props.update(min=start, max=end, step=_step(t))
        self.time.set_value(start)
        self.bodies.set_track(track, start)
        self.outcome.set_text(
            f"outcome: {outcome}" + (" (the part drawn red: a failure)" if failed else "")
        )
        self.show_clock(0)
        first = not self.box.visible
        self.box.set_visibility(True)
        if first:  # the canvas measured itself while hidden
            self.scene.run_method("resize")
            self.scene.move_camera(0.19, -0.31, 0.21, 0.0, 0.0, 0.04, duration=0)

    def on_time(self, e) -> None:
        """The slider's time: the clock line, and where the server moved it (play, a new
        pick-point), the bodies and the force marker (a move in the browser posed them)."""
        if self.trace is None or e.value is None:
            return
        k = row_at(self.trace["t_s"], float(e.value))
        self.show_clock(k)
        t = float(self.trace["t_s"][k])
        # the server's copy of the marker (for a chart that mounts again), not sent: the
        # browser moved it already (replay3d.js), and sending the chart's whole options on
        # every move of a drag (about 100 kB each, 20 a second) froze the page
        with self.chart.props.suspend_updates():
            self.chart.options["series"][0]["markLine"]["data"] = [{"xAxis": round(t, 4)}]
        if self.playing_since is not None:
            self.bodies.show_time(float(e.value))

    def show_clock(self, k: int) -> None:
        tr = self.trace
        self.clock.set_text(
            f"t = {float(tr['t_s'][k]):.3f} s of {float(tr['t_s'][-1]):.3f} s, phase "
            f"{tr['phase'][k]}, pads {_newtons(tr['force_left_n'][k])} / "
            f"{_newtons(tr['force_right_n'][k])} N"
        )

    def toggle_play(self) -> None:
        if self.playing_since is None:
            self.start()
        else:
            self.pause()

    def start(self) -> None:
        if self.trace is None:
            return
        t = self.trace["t_s"]
        now = float(self.time.value or 0.0)
        if now >= _seconds(t[-1]):
            now = _seconds(t[0])  # played to the end: again from the start
        self.playing_since = (time.monotonic(), now)
        self.play.props('icon=pause aria-label="pause"')
        self.timer.activate()

    def pause(self) -> None:
        self.playing_since = None
        self.timer.deactivate()
        self.play.props('icon=play_arrow aria-label="play"')

    def tick(self) -> None:
        """While playing: the slider at the time the clock has reached (speed x real time)."""
        if self.playing_since is None or self.trace is None:
            return
        since, t0 = self.playing_since
        end = _seconds(self.trace["t_s"][-1])
        t = min(t0 + float(self.speed.value or 1.0) * (time.monotonic() - since), end)
        self.time.set_value(t)
        if t >= end:
            self.pause()


def _newtons(f) -> str:
    """A force to 0.1 N, a rounding's -0.0 written 0.0."""
    return f"{round(float(f), 1) + 0.0:.1f}"


def _seconds(t) -> float:
    """A trace time (float32) as the slider shows it, s: to the microsecond."""
    return round(float(t), 6)


def _step(t_s) -> float:
    """The slider's step, s: the trace's row interval."""
    return _seconds(t_s[1] - t_s[0]) if len(t_s) > 1 else 0.005
