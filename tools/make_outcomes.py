"""Write the example measured-outcomes file (synthetic: simulated, not measured).

Run from the repository root, with mjx_pick installed:  python tools/make_outcomes.py

It plays a real cell's test: the shipped block, made 1 kg (a lead-filled test block),
picked 24 times near its centre by an OnRobot RG2 at grip forces from 6 to 14 N (where
friction decides: about 9.5 N is needed at friction 0.62), one trial each, with the
pad friction hidden at 0.62 (the paper's 0.86 is the default a fit starts from). Each
row also records the time from the close command to the lift.
``mjx-pick calibrate block_1kg_rg2 block --mass-g 1000 --gripper onrobot-rg2 --out
runs/cal`` should find the hidden friction again.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.studies.calibration import synthetic_outcomes, write_outcomes
from mjx_pick.studies.calibration.synthetic_outcomes import synthetic_digest

HERE = Path(__file__).resolve().parents[1] / "mjx_pick" / "assets" / "outcomes"


def example():
    """The example's cell: the 1 kg block, the hidden settings (the RG2, pad friction
    0.62, every other setting the default) and the 24 rows' poses and grip forces."""
    obj = mp.load_asset("block", mass_g=1000.0)
    hidden = mp.Settings(
        gripper=mp.load_gripper("onrobot-rg2"),
        contact=dataclasses.replace(mp.ContactParams(), pad_friction=0.62),
    )
    rng = np.random.default_rng(2023)
    f = np.tile(np.linspace(6.0, 14.0, 12), 2)
    n = len(f)
    yaw = np.where(np.arange(n) < n // 2, 0.0, 180.0) + rng.uniform(-3, 3, n)
    return obj, hidden, rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), yaw, f


def main() -> None:
    obj, hidden, x, y, yaw, f = example()
    out = synthetic_outcomes(obj, hidden, x, y, yaw, f, lift_times=True)
    HERE.mkdir(exist_ok=True)
    write_outcomes(HERE / "block_1kg_rg2.csv", out)
    # what it was measured with: calibrate refuses to fit it to another set-up; and what
    # simulated it: tests/test_calibrate.py says when the physics no longer would
    (HERE / "block_1kg_rg2.toml").write_text(
        "# What block_1kg_rg2.csv was measured with (simulated: tools/make_outcomes.py).\n"
        "# `mjx-pick calibrate` refuses to fit it to another mass, gripper or procedure\n"
        "# (--force-mismatch fits anyway); studies/calibration/provenance.py reads it.\n"
        f'object = "block"\nmass_g = {obj.mass_kg * 1e3:.1f}\ngripper = "{hidden.gripper.name}"\n'
        f'synthetic = "{synthetic_digest(obj, hidden)}"\n'
    )
    print(f"{int(out.successes.sum())} of {len(f)} held; written to {HERE / 'block_1kg_rg2.csv'}")


if __name__ == "__main__":
    main()
