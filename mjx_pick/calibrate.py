"""Calibration's former single module, kept for existing imports
(``from mjx_pick import calibrate as cal``; ``cal.Problem``, ``cal.calibrate``, ...).

The code lives in the ``mjx_pick.calibration`` package, one module per responsibility
(its docstring lists them); this module re-exports its public names.
"""

from mjx_pick.calibration import *  # noqa: F403
from mjx_pick.calibration import __all__  # noqa: F401
