"""Failure outcomes: one enum (code, label, meaning) that every place reads."""

import ast
import inspect

from mjx_pick.core.metrics import COLUMNS
from mjx_pick.kernels import grasp as gk
from mjx_pick.kernels import types as kt


def test_outcomes_are_one_table():
    codes = [int(o) for o in kt.Outcome]
    assert codes == list(range(len(codes))), "codes are stored in results: 0..n-1, never reused"
    assert kt.FAILURES == tuple(o.label for o in kt.Outcome) and kt.FAILURES[0] == "success"
    assert len(set(kt.FAILURES)) == len(kt.FAILURES)
    assert all(o.means and o.means[0].islower() for o in kt.Outcome)
    # the results table's column says every label
    assert all(label in COLUMNS["failure"][1] for label in kt.FAILURES)


def test_every_outcome_has_its_condition_in_the_kernel():
    # adding a reason: its member in kernels.types.Outcome and its condition in
    # finalize's table (docs/architecture.md); the table is in priority order
    tree = ast.parse(inspect.getsource(gk.finalize))
    (table,) = [
        n.value
        for n in ast.walk(tree)
        if isinstance(n, ast.Assign) and getattr(n.targets[0], "id", "") == "conditions"
    ]
    keys = [k.attr for k in table.keys]
    assert sorted(keys) == sorted(o.name for o in kt.Outcome)
    assert keys[:2] == ["OK", "DIVERGED"]  # a success is never a failure; a blow-up first
