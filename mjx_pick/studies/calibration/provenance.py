"""What measured outcomes were measured with, and whether a fit's run matches it.

Details: docs/calibration.md (studies/calibration/provenance.py).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from mjx_pick.core.config import ConfigError, read_toml
from mjx_pick.core.procedure import GraspConfig

KEYS = ("object", "mass_g", "gripper", "synthetic", "grasp")
MASS_TOLERANCE = 0.02  # relative: a scale's reading and a model's volume x density


def read_measured(csv_path: str | Path) -> dict | None:
    """The record beside an outcomes CSV (its name with .toml), checked; None if none."""
    path = Path(csv_path).with_suffix(".toml")
    if not path.is_file():
        return None
    data = read_toml(path, "outcomes record")
    unknown = [k for k in data if k not in KEYS]
    if unknown:
        raise ConfigError(f"{path.name}: unknown key(s) {', '.join(unknown)}; allowed: {KEYS}")
    mass = data.get("mass_g")
    if mass is not None and (
        isinstance(mass, bool) or not isinstance(mass, int | float) or not mass > 0
    ):
        raise ConfigError(f"{path.name}: mass_g = {mass!r}: a mass in grams > 0")
    for key in ("object", "gripper"):
        if key in data and not isinstance(data[key], str):
            raise ConfigError(f"{path.name}: {key} = {data[key]!r}: a name in quotes")
    grasp = data.get("grasp", {})
    fields = {f.name for f in dataclasses.fields(GraspConfig)}
    if not isinstance(grasp, dict) or any(k not in fields for k in grasp):
        bad = sorted(set(grasp) - fields) if isinstance(grasp, dict) else grasp
        raise ConfigError(f"{path.name}: [grasp] {bad}: not GraspConfig fields")
    GraspConfig(**grasp)  # the values in range (a ConfigError naming the field)
    return {**data, "source": path.name}


def mismatches(measured: dict | None, obj, settings) -> list[str]:
    """Each way the run (object, settings) differs from what the outcomes were
    measured with, as one line; empty when nothing is recorded or all agree."""
    if not measured:
        return []
    out = []
    mass = measured.get("mass_g")
    run_mass = obj.mass_kg * 1e3
    if mass is not None and abs(run_mass - mass) > MASS_TOLERANCE * mass:
        what = f" ({measured['object']})" if measured.get("object") else ""
        out.append(f"mass: measured {mass:g} g{what}, the run's {obj.name} {run_mass:.4g} g")
    gripper = measured.get("gripper")
    if gripper is not None and gripper != settings.gripper.name:
        out.append(f"gripper: measured {gripper}, the run's {settings.gripper.name}")
    for field, value in measured.get("grasp", {}).items():
        run = getattr(settings.grasp, field)
        same = (
            math.isclose(float(run), float(value), rel_tol=1e-6, abs_tol=1e-12)
            if isinstance(value, int | float) and not isinstance(value, bool)
            else run == value
        )
        if not same:
            out.append(f"grasp.{field}: measured {value!r}, the run's {run!r}")
    return out


def check_measured(measured: dict | None, obj, settings, force: bool = False) -> list[str]:
    """Raise ConfigError listing the mismatches (:func:`mismatches`) unless force;
    returns them (forced: the caller says so)."""
    found = mismatches(measured, obj, settings)
    if found and not force:
        raise ConfigError(
            f"the outcomes were measured with other settings ({measured['source']}): "
            + "; ".join(found)
            + ". Fit with the run set as measured (--mass-g, --gripper, the procedure's "
            "flags), or pass --force-mismatch (Python: force_mismatch=True) to fit anyway"
        )
    return found
