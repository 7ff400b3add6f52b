"""Reports a person can read, made from an ``evaluate`` output folder.

``report(run_dir)`` (``mjx-pick report DIR``) writes, beside the results or into
``out``:

* ``forces_<pick>.png`` -- the paper's Figs. 8, 15, 17, 19 for each traced pick-point:
  left and right pad force, object-table force, F_d dashed, phase changes marked; below
  them the gripper's and the object's lift, mm, so that a slip shows as a gap;
* ``score_map.png``, ``success_by_yaw.png``, ``score_hist.png``, ``failures.png`` --
  pick-points on the silhouette coloured by score; success rate over (x, y) per yaw
  bin; the score histogram; the outcomes (success, or why it failed);
* ``anim_<pick>.gif`` and ``anim_<pick>.mp4`` -- the traced pick-points replayed in
  MuJoCo's offscreen renderer (EGL or OSMesa), top and side cameras, time and phase
  written on every frame (the MP4: H.264, by the ffmpeg of the imageio-ffmpeg wheel);
* ``template_a4.pdf`` / ``template_letter.pdf`` -- a printable 1:1 positioning template:
  one page per pick-point (n best, then n worst), the object's outline at its pose
  around a crosshair at the gripper centre, the finger footprints at the starting
  opening, a 100 mm scale bar; place the real object on the outline under the real
  gripper;
* ``robot_picks.json`` -- the top-k pick-points as gripper poses, optionally in a frame
  of the user's;
* ``report.html`` -- all of the above in one file that opens offline.

Traces come from ``traces.parquet`` (``evaluate(n_traces=...)``); every trace row holds
the whole joint state, so animations replay it and simulate nothing -- as does
``view`` (``mjx-pick view RUN --pick ID``), in MuJoCo's interactive viewer.
"""

from mjx_pick.outputs.reporting.animation import animate
from mjx_pick.outputs.reporting.figures import PHASE_COLOURS, force_plot, maps, phase_events
from mjx_pick.outputs.reporting.page import report
from mjx_pick.outputs.reporting.robot import frame_matrix, robot_picks
from mjx_pick.outputs.reporting.run import Run
from mjx_pick.outputs.reporting.template import PAPERS_MM, SCALE_BAR_COLOUR, positioning_template
from mjx_pick.outputs.reporting.viewer import view

__all__ = [
    "PAPERS_MM",
    "PHASE_COLOURS",
    "SCALE_BAR_COLOUR",
    "Run",
    "animate",
    "force_plot",
    "frame_matrix",
    "maps",
    "phase_events",
    "positioning_template",
    "report",
    "robot_picks",
    "view",
]
