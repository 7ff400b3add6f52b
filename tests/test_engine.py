"""The one simulation engine: results unchanged by the refactor that introduced it,
progress and cancellation between chunks, every study running through it."""

import ast
import json
import threading
from pathlib import Path

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.runner import Cancelled, Runner
from mjx_pick.engine.simulator import Simulator
from mjx_pick.studies.evaluation import evaluate
from mjx_pick.studies.sweeps import ParamSpec, sweep

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)
# the solver and pad contact the pinned results were taken with (pyramidal cones,
# impratio 1, 10 iterations, 8 line-search iterations, the whole pad colliding): these
# tests pin the engine's plumbing, not the physics, whose defaults may move on (issue
# 32 moved them to elliptic cones and the mean-radius pad box)
PINNED_SOLVER = mp.SolverParams(cone="pyramidal", impratio=1.0, iterations=10, ls_iterations=8)
# the contact of those days: the whole pad, no contact margin
PINNED_CONTACT = mp.ContactParams(pad_collision="pad", pad_margin_mm=0.0)

# Results of the code BEFORE the engine refactor (commit 513b28d, MuJoCo 4.0.0, jax
# 0.10, 2-core AMD EPYC), printed from evaluate(...).table / sweep(...).table with
# exactly the calls below (MuJoCo C backend). Labels must match exactly; the floats to
# 1e-6: on this machine they are bitwise equal, but the per-tick controller is XLA CPU
# code, which XLA compiles per CPU model (float32 reductions may round differently on
# CI's CPU), and 1e-6 is still far below any change a refactor bug would make. Changes
# since, on purpose: a successful pick's failure reason is its own (the old code gave
# these held picks "slipped_in_lift": the part lagged at the short lift's end), and it
# reads "success" (issue 21; it read "none", code 0 both times).
EVALUATE_DOOR_OPENER = {
    "pick_id": [12, 30, 41, 49, 50, 53],
    "success": [True, False, False, False, False, False],
    "failure": ["success"] + ["force_not_reached"] * 5,
    "score": [
        0.9564539790153503,
        0.26396703720092773,
        0.31415510177612305,
        0.29422780871391296,
        0.24497491121292114,
        0.27547377347946167,
    ],
    "t_reached_s": [0.47499969601631165, -1.0, -1.0, -1.0, -1.0, -1.0],
    "lift_height_mm": [4.89628267288208, 0.0, 0.0, 0.0, 0.0, 0.0],
}
SWEEP_BLOCK = {
    "variant": [0, 0, 0, 1, 1, 1, 2, 2, 2, 3, 3, 3],
    "pick_id": [0, 2, 4] * 4,
    "success": [True, False, True] * 4,
    "failure": ["success", "force_not_reached", "success"] * 4,
    "score": [
        0.9770233631134033,
        0.25076982378959656,
        0.940322995185852,
        0.9769618511199951,
        0.25417107343673706,
        0.9610767364501953,
        0.9765805006027222,
        0.25076982378959656,
        0.940322995185852,
        0.9762338995933533,
        0.25417107343673706,
        0.9552550315856934,
    ],
    "t_reached_s": [
        0.299999862909317,
        -1.0,
        0.47499969601631165,
        0.299999862909317,
        -1.0,
        0.44999971985816956,
        0.3249998390674591,
        -1.0,
        0.5049996972084045,
        0.3249998390674591,
        -1.0,
        0.47999969124794006,
    ],
    "lift_height_mm": [
        4.955718994140625,
        0.0,
        4.958987712860107,
        4.944531440734863,
        0.0,
        4.944886207580566,
        4.955569744110107,
        0.0,
        4.958508491516113,
        4.944658279418945,
        0.0,
        4.945271015167236,
    ],
}
FLOATS = ("score", "t_reached_s", "lift_height_mm")


def _check(table, expected):
    for name, want in expected.items():
        got = table[name].to_pylist()
        if name in FLOATS:
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-6, err_msg=name)
        else:
            assert got == want, name


def test_evaluate_results_unchanged_by_the_engine(door_opener):
    # two chunks of 4 (the second one short): the chunked path, not one batch
    ev = evaluate(
        door_opener,
        n=6,
        seed=3,
        grasp=SHORT,
        backend="mujoco",
        batch_size=4,
        chunk_size=4,
        n_traces=0,
        solver=PINNED_SOLVER,
        contact=PINNED_CONTACT,
    )
    _check(ev.table, EVALUATE_DOOR_OPENER)


def test_sweep_results_unchanged_by_the_engine(block):
    res = sweep(
        block,
        [
            ParamSpec.parse("controller.force_n=30,60"),
            ParamSpec.parse("contact.pad_friction=0.3,0.86"),
        ],
        mp.Settings(grasp=SHORT, solver=PINNED_SOLVER, contact=PINNED_CONTACT),
        n=3,
        seed=1,
        backend="mujoco",
    )
    _check(res.table, SWEEP_BLOCK)


def test_progress_and_cancel_between_chunks_then_resume(door_opener, tmp_path):
    out = tmp_path / "run"
    calls, cancel = [], threading.Event()

    def stop_after_first_chunk(done, total):
        calls.append((done, total))
        if done >= 2:
            cancel.set()

    common = dict(
        n=6,
        seed=3,
        grasp=SHORT,
        solver=PINNED_SOLVER,
        contact=PINNED_CONTACT,
        backend="mujoco",
        batch_size=2,
        chunk_size=2,
    )
    with pytest.raises(Cancelled):
        evaluate(
            door_opener,
            **common,
            out=out,
            n_traces=0,
            on_progress=stop_after_first_chunk,
            cancel=cancel,
        )
    assert calls == [(0, 6), (2, 6)]
    chunks = sorted(p.name for p in (out / "chunks").glob("part-*.parquet"))
    assert chunks == ["part-000000.parquet"], "the run stops before the next chunk"
    assert json.loads((out / "mjx_pick_run.json").read_text())["status"] == "cancelled"
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "cancelled" and run["timing"]["simulations"] == 2
    stamp = (out / "chunks" / chunks[0]).stat().st_mtime_ns

    calls.clear()
    ev = evaluate(
        door_opener,
        **common,
        out=out,
        n_traces=0,
        resume=True,
        keep_chunks=True,  # to show that the finished chunk was read, not redone
        on_progress=lambda d, t: calls.append((d, t)),
    )
    assert calls == [(0, 6), (2, 6), (4, 6), (6, 6)]
    assert (out / "chunks" / chunks[0]).stat().st_mtime_ns == stamp, "a finished chunk was redone"
    run = json.loads((out / "run.json").read_text())
    assert run["status"] == "complete" and run["timing"]["simulations"] == 4  # 2 were read
    # chunks of 2 on batches of 2 give the pinned results of chunks of 4 on batches of 4
    _check(ev.table, EVALUATE_DOOR_OPENER)


def test_a_swallowed_ctrl_c_still_stops_the_run_at_the_next_chunk(door_opener, tmp_path):
    """A SIGINT whose KeyboardInterrupt was swallowed (Python ignores exceptions raised
    in a garbage-collector callback, where JAX has one) is still recorded by the CLI's
    handler: the run stops before the next chunk, 'interrupted', its chunk kept."""
    from mjx_pick.engine import interrupts

    out = tmp_path / "run"

    def ctrl_c_swallowed_after_first_chunk(done, total):
        if done >= 2:
            interrupts.request()  # what the handler records besides raising

    common = dict(
        n=6, seed=3, grasp=SHORT, solver=PINNED_SOLVER, contact=PINNED_CONTACT, backend="mujoco"
    )
    try:
        with pytest.raises(KeyboardInterrupt):
            evaluate(
                door_opener,
                **common,
                batch_size=2,
                chunk_size=2,
                out=out,
                n_traces=0,
                on_progress=ctrl_c_swallowed_after_first_chunk,
            )
    finally:
        interrupts.clear()
    chunks = sorted(p.name for p in (out / "chunks").glob("part-*.parquet"))
    assert chunks == ["part-000000.parquet"], "the run stops before the next chunk"
    assert json.loads((out / "mjx_pick_run.json").read_text())["status"] == "interrupted"


def test_the_cli_handler_records_ctrl_c_and_forgets_it_after_the_command():
    import signal

    from mjx_pick.engine import interrupts

    before = signal.getsignal(signal.SIGINT)
    with pytest.raises(KeyboardInterrupt):
        with interrupts.catching_sigint():
            signal.raise_signal(signal.SIGINT)
    assert not interrupts.requested(), "cleared when the command ends"
    assert signal.getsignal(signal.SIGINT) is before
    with interrupts.catching_sigint():
        try:
            signal.raise_signal(signal.SIGINT)
        except KeyboardInterrupt:  # raised as Python's own handler does ...
            pass
        assert interrupts.requested()  # ... and recorded for the engine's next check
        with pytest.raises(KeyboardInterrupt):
            interrupts.raise_if_requested()


def test_simulator_reports_progress_over_all_jobs_and_honours_cancel(block):
    calls = []
    runner = Runner("mujoco", 2, chunk_size=2, on_progress=lambda d, t: calls.append((d, t)))
    sim = Simulator(block, runner=runner)
    picks = pp.generate_normal(block, mp.GripperSpec(), 3, seed=1, grasp=SHORT)
    base = mp.Settings(grasp=SHORT)
    strong = mp.Settings(
        grasp=GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05, grip_force_n=60.0)
    )
    a, b = sim.run([(base, picks), (strong, picks)])
    # both jobs share one structure: one batch of 6 pick-points in chunks of 2
    assert calls == [(0, 6), (2, 6), (4, 6), (6, 6)]
    assert len(sim.backends) == 1 and sim.rollouts == runner.rollouts == 6
    assert len(a["success"]) == len(b["success"]) == 3
    timing = runner.timing
    assert timing.n == 6 and timing.compile_s > 0 and timing.run_s > 0

    cancel = threading.Event()
    cancel.set()
    stopped = Simulator(block, runner=Runner("mujoco", 2, cancel=cancel))
    with pytest.raises(Cancelled):
        stopped.run([(base, picks)])
    assert stopped.runner.rollouts == 0


ROOT = Path(__file__).resolve().parents[1]
# only the engine layer builds and runs backends; everyone else goes through the engine
BACKEND_NAMES = {"make_backend", "make_rollout", "MjxBackend", "MujocoBackend", "make_warp_backend"}


def _names_used(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    used = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            used.add(node.id)
        elif isinstance(node, ast.Attribute):
            used.add(node.attr)
        elif isinstance(node, ast.ImportFrom):
            used.update(a.name for a in node.names)
    return used


def test_only_the_engine_builds_backends():
    # the engine's own folder builds them; everything above goes through its runner
    files = [p for p in (ROOT / "mjx_pick").rglob("*.py") if "engine" not in p.parts]
    assert len(files) > 10
    offenders = {str(p.relative_to(ROOT)): sorted(_names_used(p) & BACKEND_NAMES) for p in files}
    offenders = {k: v for k, v in offenders.items() if v}
    assert not offenders, f"simulate through mjx_pick.engine.runner, not a backend: {offenders}"


def test_the_backend_check_sees_a_direct_call(tmp_path):
    src = tmp_path / "m.py"
    src.write_text(
        "import mjx_pick.engine.backend as s\n\n"
        "def f(scene):\n    return s.make_backend('mujoco', scene)\n"
    )
    assert _names_used(src) & BACKEND_NAMES == {"make_backend"}


def test_a_cancelled_sweep_or_compare_marks_its_folder(block, tmp_path):
    # issue 21: a study stopped by its cancel event leaves its folder "cancelled", not
    # "running" (evaluate does the same and keeps its chunks for --resume)
    from mjx_pick.studies.comparison import compare

    cancel = threading.Event()
    cancel.set()
    params = [ParamSpec.parse("contact.pad_friction=0.3,0.86")]
    runs = {
        "sweep": lambda sim, out: sweep(
            block, params, mp.Settings(grasp=SHORT), n=2, out=out, simulator=sim
        ),
        "compare": lambda sim, out: compare(
            block,
            [mp.GripperSpec(name="test-jaw"), mp.load_gripper("robotiq-2f85")],
            mp.Settings(grasp=SHORT),
            n=2,
            out=out,
            simulator=sim,
        ),
    }
    for command, run in runs.items():
        out = tmp_path / command
        sim = Simulator(block, runner=Runner("mujoco", 2, cancel=cancel))
        with pytest.raises(Cancelled):
            run(sim, out)
        manifest = json.loads((out / "mjx_pick_run.json").read_text())
        assert manifest["command"] == command and manifest["status"] == "cancelled"
        assert json.loads((out / "run.json").read_text())["status"] == "cancelled"


def test_a_study_resumes_from_chunks_that_a_simulator_with_another_history_wrote(block, tmp_path):
    # a long-lived simulator carries the model fields of every variant it ran (one
    # compiled program for all of them); a chunk is named by its rows' settings and
    # inputs, not by that set, so a fresh simulator (a resumed run in a new process)
    # finds the chunks the long-lived one wrote
    params = [ParamSpec.parse("gripper.finger_width_mm=18,22")]
    run = {"n": 4, "seed": 1, "backend": "mujoco", "batch_size": 4}
    settings = mp.Settings(grasp=SHORT)
    used = Simulator(block, "mujoco", 4)
    sweep(block, [ParamSpec.parse("gripper.finger_mass_g=30,50")], settings, **run, simulator=used)
    out = tmp_path / "sw"

    def ctrl_c(done: int, _total: int) -> None:
        if done > 0:
            raise KeyboardInterrupt

    used.runner.on_progress = ctrl_c
    with pytest.raises(KeyboardInterrupt):
        sweep(block, params, settings, **run, simulator=used, out=out)
    used.runner.on_progress = None
    assert len(list((out / "chunks").glob("part-*.parquet"))) == 1
    resumed = sweep(block, params, settings, **run, out=out, resume=True)
    assert resumed.timing["chunks_resumed"] == 1 and resumed.table.num_rows == 8
    whole = sweep(block, params, settings, **run)
    assert resumed.table.equals(whole.table)


# the studies and the engine's shared modules imported, pick-points drawn and a scene
# built, in a fresh interpreter: which of JAX's modules did it load (none may be)
HOST_SIDE = """
import json, sys
import mjx_pick as mp
import mjx_pick.cli.commands, mjx_pick.engine.runner, mjx_pick.engine.simulator
import mjx_pick.studies.evaluation, mjx_pick.studies.sweeps, mjx_pick.studies.comparison
from mjx_pick.core import pickpoints as pp
obj, gripper = mp.load_object("door_opener"), mp.load_gripper("robotiq-2f85")
picks = pp.generate_normal(obj, gripper, 16, seed=0)
scene = mp.build_scene(obj, gripper)
jax = sorted(m for m in sys.modules if m.split(".")[0] in ("jax", "jaxlib"))
print(json.dumps({"picks": len(picks), "jax": jax}))
"""


def test_host_side_needs_no_jax():
    import os
    import subprocess
    import sys

    run = subprocess.run(
        [sys.executable, "-c", HOST_SIDE], env=dict(os.environ), capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.splitlines()[-1])
    assert got == {"picks": 16, "jax": []}


# a process with a backend that runs no JAX program (as the direct Warp backend): making
# it imports no JAX, and the C engine's host programs after it start JAX's CPU only
JAX_ON_CPU = """
import dataclasses, json, sys
import mjx_pick as mp
from mjx_pick.engine import backend, registry

class NoJax:
    def __init__(self, scene, grasp, batch_size, **options):
        self.scene = scene

registry.ENTRIES["no-jax"] = dataclasses.replace(
    registry.ENTRIES["warp"], name="no-jax", factory="__main__:NoJax", problem=None
)
scene = mp.build_scene(mp.load_object("block"), mp.load_gripper("robotiq-2f85"))
grasp = mp.GraspConfig()
backend.make_backend("no-jax", scene, grasp, 8)
imported = "jax" in sys.modules
backend.make_backend("mujoco", scene, grasp, 8)  # as Warp's buffers are sized
import jax
import jax.extend.backend
print(json.dumps({"imported": imported, "platforms": jax.config.jax_platforms,
                  "started": sorted(jax.extend.backend.backends())}))
"""


def test_jax_kept_on_the_cpu_beside_a_backend_without_jax():
    import os
    import subprocess
    import sys

    from mjx_pick.engine import registry

    Jax = registry.Jax
    assert {n: e.jax for n, e in registry.ENTRIES.items()} == {
        "warp": Jax.NONE,
        "mjx-warp": Jax.DEVICES,
        "mjx": Jax.DEVICES,
        "mujoco": Jax.CPU,
    }
    env = {k: v for k, v in os.environ.items() if k != "JAX_PLATFORMS"}
    run = subprocess.run(
        [sys.executable, "-c", JAX_ON_CPU], env=env, capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.splitlines()[-1])
    assert got == {"imported": False, "platforms": "cpu", "started": ["cpu"]}


def test_jax_on_the_cpu_refuses_what_would_need_a_gpu(monkeypatch):
    from jax._src import xla_bridge

    from mjx_pick.engine import devices

    monkeypatch.setattr(devices, "_jax_on_cpu", True)
    monkeypatch.setattr(devices, "nvidia_driver_present", lambda: True)
    with pytest.raises(mp.ConfigError, match="keeps JAX on the CPU"):
        devices.check_jax_devices()  # an MJX backend after the direct Warp one
    # JAX started a GPU platform before the direct Warp backend was made
    monkeypatch.setattr(xla_bridge, "backends_are_initialized", lambda: True)
    monkeypatch.setattr(xla_bridge, "backends", lambda: {"cpu": None, "cuda": None})
    with pytest.raises(mp.ConfigError, match="JAX has started cuda"):
        devices.keep_jax_on_cpu()


# Warp started on a thread of its own (the CLI's start_engine) while other threads ask
# for it: Warp's own init has no lock, so without devices.warp()'s lock a slow runtime
# start would be made twice (the sleep widens the window a race needs)
WARP_ONCE = """
import json, threading, time
import warp._src.context as context
made = []
start = context.Runtime.__init__
def counted(self, *args, **kwargs):
    made.append(threading.current_thread().name)
    time.sleep(0.3)
    start(self, *args, **kwargs)
context.Runtime.__init__ = counted
from mjx_pick.engine import devices
devices.nvidia_driver_present = lambda: True  # as on a GPU machine
devices.start_warp()
askers = [threading.Thread(target=devices.warp) for _ in range(3)]
for t in askers:
    t.start()
wp = devices.warp()
for t in askers:
    t.join()
print(json.dumps({"made": made, "initialised": context.runtime is not None}))
"""


def test_warp_started_on_a_thread_is_started_once():
    import os
    import subprocess
    import sys

    run = subprocess.run(
        [sys.executable, "-c", WARP_ONCE], env=dict(os.environ), capture_output=True, text=True
    )
    assert run.returncode == 0, run.stderr
    got = json.loads(run.stdout.splitlines()[-1])
    assert got == {"made": ["warp-start"], "initialised": True}
