"""The result tables of four user commands, pinned: a change meant to leave behaviour
alone (a refactor, a layout move) must leave them as they are.

``tests/pinned/make_pinned.py`` runs a door-opener evaluate, a pad-friction sweep, a
gripper comparison and a calibration on MuJoCo C and writes each table as CSV; this test
runs the same commands and compares. Labels, failure reasons and ids must match exactly;
floats must match to 1e-6 relative (bit-identical on one machine; the margin is for
another CPU's floating-point code paths). A change that is meant to move the physics
regenerates the tables in its own commit, saying why.
"""

import csv
import math
from pathlib import Path

import pytest
from pinned.make_pinned import RUNS, cell, run_table, to_rows

PINNED = Path(__file__).resolve().parent / "pinned"


def read_pinned(name: str) -> list[dict]:
    with open(PINNED / f"{name}.csv", newline="") as f:
        return [{k: cell(v) for k, v in r.items()} for r in csv.DictReader(f)]


def same(a, b) -> bool:
    if isinstance(a, float) and isinstance(b, float):
        if math.isnan(a) or math.isnan(b):
            return math.isnan(a) and math.isnan(b)
        return math.isclose(a, b, rel_tol=1e-6, abs_tol=1e-9)
    return a == b


@pytest.mark.parametrize("name", list(RUNS))
def test_pinned_table_unchanged(name, tmp_path):
    want = read_pinned(name)
    got = [{k: cell(repr(v)) for k, v in r.items()} for r in to_rows(run_table(name, tmp_path))]
    assert len(got) == len(want), f"{name}: {len(got)} rows, pinned {len(want)}"
    assert list(got[0]) == list(want[0]), f"{name}: columns changed"
    diffs = [
        (i, k, w[k], g[k])
        for i, (g, w) in enumerate(zip(got, want, strict=True))
        for k in w
        if not same(g[k], w[k])
    ]
    assert not diffs, f"{name}: {len(diffs)} values differ, first: {diffs[:5]}"
