"""Reports a person can read, made from an ``evaluate`` output folder.

Details: docs/outputs.md (outputs/reporting/__init__.py).
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
