"""Reports a person can read, made from an ``evaluate`` output folder.

``report(run_dir)`` (``mjx-pick report DIR``) writes, beside the results or into
``out``:

* ``forces_<pick>.png`` -- the paper's Figs. 8, 15, 17, 19 for each traced pick-point:
  left and right pad force, object-table force, F_d dashed, phase changes marked;
* ``score_map.png``, ``success_by_yaw.png``, ``score_hist.png``, ``failures.png`` --
  pick-points on the silhouette coloured by score; success rate over (x, y) per yaw
  bin; the score histogram; failure reasons;
* ``anim_<pick>.gif`` -- the traced pick-points replayed in MuJoCo's offscreen renderer
  (EGL or OSMesa), top and side cameras, time and phase written on every frame;
* ``template_a4.pdf`` / ``template_letter.pdf`` -- a printable 1:1 positioning template:
  one page per pick-point (n best, then n worst), the object's outline at its pose
  around a crosshair at the gripper centre, the finger footprints at the starting
  opening, a 100 mm scale bar; place the real object on the outline under the real
  gripper;
* ``robot_picks.json`` -- the top-k pick-points as gripper poses, optionally in a frame
  of the user's;
* ``report.html`` -- all of the above in one file that opens offline.

Traces come from ``traces.parquet`` (``evaluate(n_traces=...)``); every trace row holds
the whole joint state, so animations replay it and simulate nothing.
"""

from mjx_pick.reporting.animation import animate
from mjx_pick.reporting.figures import PHASE_COLOURS, force_plot, maps, phase_events
from mjx_pick.reporting.page import report
from mjx_pick.reporting.robot import frame_matrix, robot_picks
from mjx_pick.reporting.run import Run
from mjx_pick.reporting.template import PAPERS_MM, SCALE_BAR_COLOUR, positioning_template

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
]
