"""A warm process for repeated answers (mjx_pick.Session): evaluate's pipeline on kept
backends, with the results of a new process's run of the same call.

No timing is asserted (benchmarks/time_to_answer.py measures it): that a later call
pays no fixed cost is checked by what it builds (backends, scenes), and its results by
equality with evaluate run on a runner of its own.
"""

import dataclasses
import json
import os
import threading

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core.config import ConfigError
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import runner as runner_mod

FAST = GraspConfig(close_timeout_s=0.8, lift_height_mm=20.0, hold_s=0.1)
RUN = {"backend": "mujoco", "batch_size": 8, "n_traces": 0}


@pytest.fixture()
def session():
    with mp.Session("mujoco", batch_size=8) as s:
        yield s


@pytest.fixture()
def makes(monkeypatch):
    """Count the backends runners build (every evaluate's, a session's included)."""
    calls = []
    real = runner_mod.Runner.make

    def counted(self, scene, grasp):
        calls.append(scene)
        return real(self, scene, grasp)

    monkeypatch.setattr(runner_mod.Runner, "make", counted)
    return calls


def same_table(a, b) -> None:
    assert a.column_names == b.column_names
    for name in a.column_names:
        x, y = a[name].to_pylist(), b[name].to_pylist()
        assert x == y or np.array_equal(np.asarray(x, float), np.asarray(y, float), True), name


def test_a_later_answer_builds_nothing_and_equals_a_new_runs(session, makes, tmp_path):
    """The same part again (another seed), another contact and another force: one backend
    for all (settings of one model structure share its program), every table that of
    evaluate on a runner of its own, and each call's timing its own."""
    block = session.object("block")
    assert session.object("block") is block  # kept
    session.evaluate("block", n=8, seed=0, grasp=FAST, out=tmp_path / "a", **RUN)
    assert len(makes) == 1
    calls = [
        {"seed": 1, "grasp": FAST},
        {"seed": 1, "grasp": FAST, "contact": mp.ContactParams(pad_friction=0.5)},
        {"seed": 1, "grasp": dataclasses.replace(FAST, grip_force_n=30.0)},
    ]
    answers = [
        session.evaluate(block, n=8, out=tmp_path / f"b{k}", **c, **RUN)
        for k, c in enumerate(calls)
    ]
    assert len(makes) == 1 and len(session.backends) == 1, "a later call built a backend"
    sim = session.simulator(block)
    assert sim.scenes == 1
    for call, answer in zip(calls, answers, strict=True):
        alone = mp.evaluate(block, n=8, **call, **RUN)
        same_table(alone.table, answer.table)
        assert answer.config["config_key"] == alone.config["config_key"]
    # each call's timing is its own: its simulations, not the session's so far
    run = json.loads((tmp_path / "b0" / "run.json").read_text())
    assert run["timing"]["simulations"] == len(answers[0].table)
    # the scene a call records is its own: its contact values in scene.xml
    assert (tmp_path / "b1" / "scene.xml").read_text() != (
        tmp_path / "b0" / "scene.xml"
    ).read_text()


def test_a_gripper_variant_and_tilted_grasps_answer_as_a_new_run(session):
    """A narrower finger shares the program on the C engine (its model fields carried
    per pick), and antipodal grasps (the gripper's tilt per pick) run through the kept
    backend: each table that of a run on a runner of its own."""
    block = session.object("block")
    narrow = dataclasses.replace(mp.load_gripper("robotiq-2f85"), finger_width_mm=12.0)
    for gripper, extra in [
        ("robotiq-2f85", {"grasps": "antipodal"}),
        (narrow, {}),
        ("robotiq-2f85", {}),
    ]:
        answer = session.evaluate(block, gripper, n=4, seed=2, grasp=FAST, **extra, **RUN)
        alone = mp.evaluate(block, gripper, n=4, seed=2, grasp=FAST, **extra, **RUN)
        same_table(alone.table, answer.table)
        if extra:
            assert np.any(np.asarray(answer.table["tilt_deg"]) > 1.0)  # tilted indeed
    assert len(session.backends) == 1


def test_what_a_session_refuses_names_the_input(session):
    block = session.object("block")
    with pytest.raises(ConfigError, match="backend = 'mjx'.*runs backend 'mujoco'"):
        session.evaluate(block, n=4, backend="mjx")
    with pytest.raises(ConfigError, match="batch_size = 4.*runs batch_size 8"):
        session.evaluate(block, n=4, batch_size=4)
    with pytest.raises(ConfigError, match="ray"):
        session.evaluate(block, n=4, ray="127.0.0.1:1")
    other = mp.load_object("block")  # equal, but not the simulator's object
    with pytest.raises(ConfigError, match="the simulator simulates 'block'"):
        mp.evaluate(other, n=4, simulator=session.simulator(block))
    with pytest.raises(ConfigError, match="takes an ObjectModel"):
        session.simulator("block")


def test_a_cancelled_call_leaves_the_session_answering(session):
    block = session.object("block")
    stop = threading.Event()
    stop.set()
    with pytest.raises(mp.Cancelled):
        session.evaluate(block, n=4, grasp=FAST, cancel=stop, **RUN)
    assert session.runner.cancel is None
    assert len(session.evaluate(block, n=4, grasp=FAST, **RUN).table) == 4


def test_a_changed_file_is_read_again(session, tmp_path):
    from PIL import Image

    path = tmp_path / "part.png"
    image = np.full((60, 80), 255, np.uint8)
    image[10:50, 10:70] = 0
    Image.fromarray(image).save(path)
    first = session.object(path, px_per_mm=2.0, thickness_mm=10.0, mass_g=5.0)
    assert session.object(path, px_per_mm=2.0, thickness_mm=10.0, mass_g=5.0) is first
    assert session.object(path, px_per_mm=4.0, thickness_mm=10.0, mass_g=5.0) is not first
    image[10:50, 10:40] = 255
    Image.fromarray(image).save(path)
    os.utime(path, ns=(1, 1))  # a new modification time, whatever the clock's resolution
    again = session.object(path, px_per_mm=2.0, thickness_mm=10.0, mass_g=5.0)
    assert again.area_mm2 < first.area_mm2
