"""The backend registry: every place that offers a backend reads it, 'auto' is resolved
in one place, and adding a backend is one module and one entry (docs/architecture.md)."""

import argparse
import ast
from pathlib import Path

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.cli.parser import build_parser
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine import cluster, registry, variants
from mjx_pick.engine.c_backend import MujocoBackend
from mjx_pick.gui import forms
from mjx_pick.studies.throughput import RunSpec

SHORT = GraspConfig(close_timeout_s=0.6, lift_height_mm=5.0, hold_s=0.05)
PACKAGE = Path(mp.__file__).parent
CPU_NODE = {"NodeID": "a", "Resources": {"CPU": 8.0}}
GPU_NODE = {"NodeID": "b", "Resources": {"CPU": 16.0, "GPU": 4.0}}


class SerialBackend(MujocoBackend):
    """The new backend of these tests: MuJoCo C run in batches of at most `serial`
    picks (a backend module's whole content: a factory returning a Backend)."""

    name = "serial"

    def __init__(self, scene, grasp, batch_size, nthread=None, serial: int = 2):
        super().__init__(scene, grasp, min(batch_size, serial), nthread=nthread)


SERIAL = registry.BackendEntry(
    "serial",
    f"{__name__}:SerialBackend",
    registry.Device.CPU,
    registry.BatchRule(cpu=2),
    "MuJoCo C, two picks per call",
    options=(registry.Option("serial", int, "picks per call"),),
)


@pytest.fixture()
def serial(monkeypatch):
    """SERIAL registered for one test: the one entry a new backend adds."""
    monkeypatch.setitem(registry.ENTRIES, SERIAL.name, SERIAL)
    return SERIAL


def backend_actions(parser: argparse.ArgumentParser):
    """(command, --backend action) of every (sub)command that offers a backend."""
    for action in parser._actions:
        if "--backend" in action.option_strings:
            yield parser.prog, action
        if isinstance(action, argparse._SubParsersAction):
            for sub in action.choices.values():
                yield from backend_actions(sub)


def test_every_backend_choice_is_the_registrys(serial):
    choices = ("auto", *registry.names())
    assert "serial" in choices and registry.choices() == choices
    # the CLI: every command's --backend, its help, the batch size's default
    parser = build_parser()
    actions = list(backend_actions(parser))
    assert {prog.split()[-1] for prog, _ in actions} >= {"evaluate", "sweep", "compare", "plan"}
    for prog, action in actions:
        assert tuple(action.choices) == choices, prog
    assert "serial: MuJoCo C, two picks per call" in registry.backend_help()
    assert "serial 2" in registry.batch_size_help()
    # the GUI's backend select: every backend that labels at the page's settings and
    # can run on this machine (one that needs a GPU where there is none is not offered)
    forms.backend_problems.cache_clear()  # this test's registry, not the one cached
    runnable = [c for c in choices if c != registry.differentiable()]
    runnable = [c for c in runnable if c not in forms.backend_problems()]
    assert forms.backend_choices() == runnable and "serial" in runnable
    assert registry.differentiable() in choices
    # the cluster: its choice, its actors and their batch
    assert cluster.cluster_backend("serial", [CPU_NODE]) == "serial"
    (slot,) = cluster.plan_slots("serial", CPU_NODE)
    assert (slot.num_gpus, slot.nthread) == (0, 8)
    assert registry.default_batch_size("serial", gpus=1, accelerator=True) == 2
    # variants: a backend without model_fields carries none (a program per variant)
    assert variants.carried_fields("serial") == frozenset()
    # throughput: the backend's options read from text
    spec = RunSpec.parse("serial:n=4:serial=1")
    assert spec.options == (("serial", 1),)
    with pytest.raises(ValueError, match="unknown key 'refill'"):
        RunSpec.parse("serial:n=4:refill=1")


def test_adding_a_backend_is_one_module_and_one_entry(serial, block, tmp_path, capsys):
    # chosen by name, the new backend runs every path: the runner, a study, the CLI
    n = 3
    c = mp.evaluate(block, n=n, grasp=SHORT, backend="mujoco", batch_size=4, progress=False)
    s = mp.evaluate(block, n=n, grasp=SHORT, backend="serial", progress=False)
    assert s.summary["backend"] == "serial" and s.config["batch_size"] == 2
    assert list(s.table["failure"]) == list(c.table["failure"])
    # the C engine in batches of 2 and of 4: the same physics, the per-tick kernel's
    # float32 rounding may differ with the batch's shape (engine.runner's docstring)
    np.testing.assert_allclose(s.table["score"], c.table["score"], atol=1e-5)
    argv = ["evaluate", "block", "--n", "2", "--backend", "serial", "--no-progress"]
    argv += ["--lift-height-mm", "5", "--hold-s", "0.05", "--out", str(tmp_path / "run")]
    assert main(argv) == 0
    assert '"backend": "serial"' in (tmp_path / "run" / "run.json").read_text()
    with pytest.raises(mp.ConfigError, match=r"takes no options \['refill'\]"):
        mp.Runner("serial", refill=True).make(mp.build_scene(block, mp.GripperSpec()), SHORT)


def test_auto_takes_the_first_backend_that_can_run(monkeypatch):
    # what a new GPU backend ranked first does to 'auto', here and on a cluster
    gpu = registry.BackendEntry(
        "gpu-first",
        f"{__name__}:SerialBackend",
        registry.Device.NVIDIA_GPU,
        registry.BatchRule(cpu=8, per_gpu=True),
        "a GPU backend tried before all others",
        auto_rank=-1,
        problem=f"{__name__}:no_gpu_here",
    )
    monkeypatch.setitem(registry.ENTRIES, gpu.name, gpu)
    assert registry.auto_order()[0] is gpu
    assert registry.resolve("auto") != "gpu-first"  # its problem: no GPU here
    assert registry.resolve("auto", gpus=2) == "gpu-first"
    assert cluster.cluster_backend("auto", [CPU_NODE, GPU_NODE]) == "gpu-first"
    assert cluster.cluster_backend("auto", [CPU_NODE]) == registry.resolve("auto", gpus=0)
    with pytest.raises(mp.ConfigError, match="--backend gpu-first --ray: the cluster has no GPU"):
        cluster.cluster_backend("gpu-first", [CPU_NODE])
    assert [len(cluster.plan_slots("gpu-first", n)) for n in (CPU_NODE, GPU_NODE)] == [0, 4]
    assert registry.default_batch_size("gpu-first", gpus=4) == 32
    monkeypatch.setattr(registry, "problem", lambda e: None)
    assert registry.resolve("auto") == "gpu-first"
    assert "auto: gpu-first where it can run, else" in registry.backend_help()


def no_gpu_here() -> str:
    return "this test's machine has no GPU"


def test_unknown_backends_are_refused_with_the_choices():
    with pytest.raises(mp.ConfigError, match="backend = 'gpu' is not allowed: choose one of"):
        registry.resolve("gpu")


# string constants that are a backend's name and yet no backend choice: the MuJoCo
# distribution and module, and MuJoCo's own optimiser
NOT_A_CHOICE = {
    ("cli/parser.py", "mujoco"): "the versions --version prints",
    ("engine/cluster.py", "mujoco"): "the versions every node must share",
    ("outputs/rundir.py", "mujoco"): "the versions a run folder records",
    ("outputs/display.py", "mujoco"): "whether the mujoco module is imported",
    ("engine/devices.py", "warp"): "the warp module (warp-lang)",
    ("engine/warp_buffers.py", "mujoco"): "the MuJoCo version in the buffer sizes' cache key",
    ("core/urdf_gripper.py", "mujoco"): "a URDF's <mujoco> compiler extension",
    ("studies/calibration/fit.py", "mujoco"): "mujoco's sysid optimiser",
}


def test_only_the_registry_and_the_backends_name_a_backend():
    # a backend named by a literal elsewhere is a choice the registry does not make
    own = {"engine/registry.py"}
    own |= {
        e.factory.partition(":")[0].split(".", 1)[1].replace(".", "/") + ".py"
        for e in registry.ENTRIES.values()
    }
    found = set()
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in own:
            continue
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Constant) and node.value in registry.names():
                found.add((rel, node.value))
    assert found - set(NOT_A_CHOICE) == set()
