"""The numeric inputs of runs and studies that are no settings field: each one's rule.

A settings field declares its rule where it is defined (``config.setting``); every
other number a user gives -- how many pick-points, a seed, a study's draws, a report's
count, an object's scale -- is declared here once, as a :class:`~config.Number`. The
library checks its arguments with these rules, the CLI parses its flags with them and
the GUI its fields: one rule, one message, wherever the number comes from.
"""

from __future__ import annotations

from typing import Any

from mjx_pick.core.config import Number

SEED_MAX = 2**32 - 1  # JAX's and NumPy's generators take a 32-bit seed
# a mesh repair's default tolerances (core.meshrepair.Tolerance): a scan's pin-holes and
# folds change a part by far less; a guessed corner of a coarse CAD mesh by more
REPAIR_DEFAULTS = {"repair_volume_pct": 1.0, "repair_com_mm": 1.0, "repair_bounds_mm": 1.0}

INPUTS: dict[str, Number] = {
    # how a run runs
    "n": Number(1, 1e8, integer=True, unit="pick-points", doc="pick-points to simulate"),
    "seed": Number(0, SEED_MAX, integer=True, doc="seed: same seed, same pick-points"),
    "batch_size": Number(1, 1e7, integer=True, unit="simulations", doc="per backend call"),
    "chunk_size": Number(1, 1e8, integer=True, unit="pick-points", doc="per saved chunk"),
    # evaluate
    "n_traces": Number(0, 10_000, integer=True, unit="pick-points", doc="traced best and worst"),
    "until": Number(1, 1e9, integer=True, unit="pick-points", doc="good pick-points wanted"),
    "min_score": Number(0, 1, doc="score a good pick-point reaches, eq. (2)"),
    "max_n": Number(1, 1e9, integer=True, unit="pick-points", doc="most simulated"),
    "stability_um": Number(0, 100, unit="um", doc="shift of the stability check (0: off)"),
    "depth_mm": Number(0, 2000, unit="mm", doc="a grasp file's base-to-grasp-centre distance"),
    # sweep, compare, design
    "random": Number(1, 10_000, integer=True, unit="variants", doc="random variants"),
    "grid_points": Number(1, 1000, integer=True, unit="values", doc="values of a swept grid"),
    "variants": Number(1, 10_000, integer=True, unit="variants", doc="design variants"),
    "rounds": Number(1, 20, integer=True, unit="rounds", doc="successive-halving rounds"),
    "sweep_simulations": Number(
        1, 1e7, integer=True, unit="simulations", doc="a sweep's variants x pick-points"
    ),
    # robust
    "top_k": Number(1, 100_000, integer=True, unit="pick-points", doc="best ones tested"),
    "m": Number(1, 100_000, integer=True, unit="draws", doc="perturbed draws per pick-point"),
    "sigma_xy_mm": Number(0, 100, unit="mm", doc="vision error of x and y"),
    "sigma_yaw_deg": Number(0, 180, unit="deg", doc="vision error of yaw"),
    # calibrate
    "steps": Number(0, 1_000_000, integer=True, unit="steps", doc="estimator steps"),
    "split": Number(0, 1, lo_open=True, hi_open=True, doc="fraction of the trials' grasps fitted"),
    "budget": Number(1, 1e12, integer=True, unit="simulations", doc="simulation budget"),
    "lr": Number(0, 10, lo_open=True, doc="Adam step in the bounded space"),
    "samples": Number(1, 10_000, integer=True, doc="quadrature node pairs"),
    "sigma": Number(0, 10, lo_open=True, doc="smoothing spread in the bounded space"),
    "temperature_mm": Number(0, 1000, lo_open=True, unit="mm", doc="outcome smoothing"),
    "replicates": Number(1, 64, integer=True, doc="simulations per traced row"),
    "trace_window_s": Number(0, 10, lo_open=True, unit="s", doc="trace moving average"),
    "checkpoint_every": Number(1, 1e9, integer=True, unit="steps", doc="between checkpoints"),
    "log_every": Number(1, 1e9, integer=True, unit="steps", doc="between loss lines"),
    # report, view, gui
    "report_n": Number(0, 1000, integer=True, unit="pick-points", doc="best and worst shown"),
    "report_k": Number(0, 100_000, integer=True, unit="pick-points", doc="robot export rows"),
    "anim_every": Number(1, 10_000, integer=True, unit="ticks", doc="per animation frame"),
    "speed": Number(0, 100, lo_open=True, unit="x real time", doc="playback speed"),
    "port": Number(0, 65_535, integer=True, doc="TCP port (0: a free one)"),
    # trials
    "trials_n": Number(1, 1000, integer=True, unit="pick-points", doc="pick-points to try"),
    "repeats": Number(1, 1000, integer=True, unit="trials", doc="trials per pick-point"),
    "draws": Number(2, 1000, integer=True, unit="draws", doc="parameter draws"),
    "placements": Number(1, 1000, integer=True, doc="placements per pick-point and draw"),
    "jitter_mm": Number(0, 50, unit="mm", doc="placing error on x and y"),
    "jitter_deg": Number(0, 90, unit="deg", doc="placing error on yaw"),
    "pool": Number(1, 100_000, integer=True, unit="pick-points", doc="candidates simulated"),
    "info_share": Number(0, 1, doc="fraction chosen by expected information"),
    "next": Number(0, 1000, integer=True, unit="pick-points", doc="next round's pick-points"),
    # an object from an image or a mesh
    "px_per_mm": Number(0, 1000, lo_open=True, unit="px/mm", doc="image scale"),
    # a prism's thickness: from a sheet of paper's (thinner, no pad takes it from the
    # side, and its mesh cannot be built) to the largest object's 1 m
    "thickness_mm": Number(0.1, 1000, unit="mm", doc="object thickness"),
    # mass and density: positive here; what a solid can be is the object's own check
    # (objects.DENSITY_POSSIBLE_KG_M3, which names the density they make)
    "mass_g": Number(0, None, lo_open=True, unit="g", doc="object mass"),
    "density_kg_m3": Number(0, None, lo_open=True, unit="kg/m^3", doc="object density"),
    "pick_height_mm": Number(0, 2000, lo_open=True, unit="mm", doc="fingertip height"),
    "simplify_mm": Number(0, 5, unit="mm", doc="outline simplification"),
    # how much a mesh's repair may change it (core.meshrepair.Tolerance; REPAIR_DEFAULTS)
    "repair_volume_pct": Number(0, 100, unit="%", doc="a repair's volume in doubt"),
    "repair_com_mm": Number(0, 1000, unit="mm", doc="a repair's centre-of-mass change"),
    "repair_bounds_mm": Number(0, 1000, unit="mm", doc="a repair's bounds change"),
    # a pick-point given by the user (a picks CSV, a form)
    "x_mm": Number(-1000, 1000, unit="mm", doc="pick-point x offset"),
    "y_mm": Number(-1000, 1000, unit="mm", doc="pick-point y offset"),
    "yaw_deg": Number(-360, 720, unit="deg", doc="pick-point yaw"),
}


def check(name: str, value: Any, label: str | None = None) -> int | float:
    """value of the input `name` (:data:`INPUTS`), checked: ConfigError naming label
    (default name), the value and what is allowed; an int where the input is whole."""
    return INPUTS[name].check(label or name, value)


def check_optional(name: str, value: Any, label: str | None = None) -> int | float | None:
    """As :func:`check`, None passing through (an input left at its default)."""
    return None if value is None else check(name, value, label)
