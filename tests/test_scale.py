"""Scale: sharding over several devices, chunked runs that survive a kill and resume."""

import dataclasses
import json
import os
import signal
import subprocess
import sys
import time

import jax
import numpy as np
import pyarrow.parquet as pq
import pytest

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.config import to_toml
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.backend import make_backend
from mjx_pick.engine.inputs import make_inputs
from mjx_pick.kernels import grasp as gk
from mjx_pick.studies.evaluation import evaluate

FAST = GraspConfig(close_timeout_s=0.3, lift_height_mm=5.0, hold_s=0.05)


@pytest.mark.mjx
def test_mjx_sharded_over_four_devices_matches_one_and_does_not_recompile(block, count_compiles):
    # conftest gives the CPU 4 devices (XLA_FLAGS=--xla_force_host_platform_device_count=4)
    assert len(jax.local_devices()) == 4
    gripper = mp.GripperSpec()
    # the pad box without the rim behind it: MJX's JAX physics computes every pair's
    # contacts every step, and the rim's pairs make it several times slower on a CPU;
    # what is tested here is the sharding, not the pads
    contact = mp.ContactParams.differentiable(mp.ContactParams(pad_collision="mean_radius"))
    scene = mp.build_scene(block, gripper, contact, mp.SolverParams.differentiable())
    # the pads at this physics reach the force 0.27-0.36 s into a pick: a close timeout of
    # 0.5 s keeps every held label off that threshold (FAST's 0.3 s flipped one)
    grasp = dataclasses.replace(FAST, close_timeout_s=0.5)
    # pick-points well inside the pads' collision box: no label hangs on rounding (the
    # sharded program reduces in another order; a pad meeting the part at the box's edge
    # can flip between no contact and force not reached)
    x, y = np.meshgrid(np.linspace(-2, 2, 4), np.linspace(-2, 2, 4))
    checker = pp.FeasibilityChecker(block, gripper)
    picks = checker.batch(np.arange(16), x.ravel(), y.ravel(), np.zeros(16), "user")
    assert len(picks) == 16
    first_inputs = make_inputs(scene, grasp, picks.take(slice(0, 8)))
    # the part moved 0.2 m away from four of them (the pads close on air: no contact), so
    # that each device's two picks -- held or not -- form a pattern of their own: a
    # device's slice run elsewhere, or a slice's picks swapped, changes the labels
    air = np.array([1, 2, 6, 7])  # devices' slices: (held, air) (air, held) (held, held) (air, air)
    first_inputs.qpos0[air, scene.index.object_qpos] += 0.2
    sharded = make_backend("mjx", scene, grasp, batch_size=8)
    assert sharded.sharding.num_devices == 4 and sharded.batch_size == 8
    first, _ = sharded.run(first_inputs)
    n = count_compiles(lambda: sharded.run(make_inputs(scene, grasp, picks.take(slice(8, 16)))))
    assert n == 0, f"{n} compilations on the second batch"
    # each device runs its own slice: no cross-device collective in the program (the
    # partitioner used to all-reduce the solver loop's test at every iteration)
    hlo = next(iter(sharded._compiled.values())).as_text()
    for op in ("all-reduce", "all-gather", "collective-permute", "all-to-all"):
        assert op not in hlo, f"{op} in the sharded rollout"
    single = make_backend("mjx", scene, grasp, batch_size=8, devices=jax.local_devices()[:1])
    alone, _ = single.run(first_inputs)
    held = np.setdiff1d(np.arange(8), air)
    assert alone["success"][held].all() and (alone["failure"][air] == gk.Outcome.NO_CONTACT).all()
    for key in ("success", "failure"):
        np.testing.assert_array_equal(first[key], alone[key], err_msg=key)
    # not bitwise: the sharded program reduces in another order (float32), and contact
    # dynamics amplify that; labels above are equal. At this physics (pyramidal cones,
    # MJX's collider making one edge contact on a flat pad) the force is reached a few
    # control ticks apart and the scores move: on 16 held picks of this grid, measured up
    # to 6 ticks and 0.11 apart (0.02 on these); the air picks, never touched, agree
    tick_s = grasp.substeps(scene.solver) * scene.model.opt.timestep
    np.testing.assert_allclose(first["t_reached_s"], alone["t_reached_s"], atol=8.01 * tick_s)
    np.testing.assert_allclose(first["score"], alone["score"], atol=0.12)
    lift = "lift_height_mm"
    np.testing.assert_allclose(first[lift][air], alone[lift][air], atol=1e-3)


def test_uneven_batch_rounds_up_to_devices(block):
    contact, solver = mp.ContactParams.differentiable(), mp.SolverParams.differentiable()
    scene = mp.build_scene(block, mp.GripperSpec(), contact, solver)
    backend = make_backend("mjx", scene, FAST, batch_size=10)
    assert backend.batch_size == 12  # 4 devices x 3


def test_kill_mid_run_then_resume_equals_uninterrupted(tmp_path, block):
    grasp_file = tmp_path / "grasp.toml"
    grasp = dataclasses.replace(FAST, close_timeout_s=0.6, lift_height_mm=20.0, hold_s=0.2)
    grasp_file.write_text(to_toml(grasp))
    out = tmp_path / "killed"
    cmd = [
        sys.executable,
        "-m",
        "mjx_pick.cli",
        "evaluate",
        "block",
        "--n",
        "80",
        "--chunk-size",
        "8",
        "--batch-size",
        "8",
        "--backend",
        "mujoco",
        "--grasp",
        str(grasp_file),
        "--out",
        str(out),
        "--no-progress",
        "--traces",
        "0",
    ]
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "XLA_FLAGS": ""}
    log = tmp_path / "killed.log"
    with log.open("wb") as sink:
        # cwd outside the checkout: "-m mjx_pick.cli" must find the installed package,
        # not the source folder (whose kernels/ lives beside it)
        proc = subprocess.Popen(cmd, env=env, stdout=sink, stderr=subprocess.STDOUT, cwd=tmp_path)
        deadline = time.monotonic() + 300
        chunks = out / "chunks"
        while time.monotonic() < deadline and proc.poll() is None:
            if len(list(chunks.glob("part-*.parquet"))) >= 2:
                break
            time.sleep(0.05)
        alive = proc.poll() is None
        proc.send_signal(signal.SIGKILL)
        proc.wait()
    assert alive, f"the run ended before it could be killed: {log.read_text()}"
    done_before = len(list(chunks.glob("part-*.parquet")))
    assert 2 <= done_before < 10 and not (out / "results.parquet").exists()
    plan = json.loads((chunks / "plan.json").read_text())
    assert plan["chunk_sizes"] == {"evaluate": 8}, "the chunk plan survives the kill"
    stamps = {p.name: p.stat().st_mtime_ns for p in chunks.glob("part-*.parquet")}

    # resumed without --chunk-size (the automatic size differs): the plan on disk is kept,
    # so chunk k still means the same pick-points
    resumed = evaluate(
        block,
        n=80,
        grasp=grasp,
        backend="mujoco",
        batch_size=8,
        out=out,
        resume=True,
        n_traces=0,
        keep_chunks=True,  # to show that no finished chunk was redone
    )
    # nothing finished was redone, nothing was lost
    for name, stamp in stamps.items():
        assert (chunks / name).stat().st_mtime_ns == stamp, f"{name} was redone"
    assert resumed.table.num_rows == 80
    whole = evaluate(
        block,
        n=80,
        grasp=grasp,
        backend="mujoco",
        batch_size=8,
        chunk_size=8,
        out=tmp_path / "whole",
        n_traces=0,
    )
    assert resumed.table.equals(whole.table)
    assert pq.read_table(out / "results.parquet").equals(whole.table)
