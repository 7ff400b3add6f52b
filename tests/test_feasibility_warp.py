"""The feasibility checks' Warp kernel (kernels.feasibility_warp) on Warp's CPU device
against numpy's checks (kernels.feasibility, the reference), and a search on either.

The kernel follows numpy's float32 arithmetic operation for operation, so the bar is
bit for bit: the same reasons, and each float the same 32 bits (NaN where numpy has NaN,
the sign of a zero included) -- no tolerance. On a CUDA device the same kernel is held
to the same bar by ``benchmarks/feasibility.py --device cuda:0``.
"""

import platform
import types
from importlib import resources

import numpy as np
import pytest
import shapely
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.core import pickpoints as pp
from mjx_pick.core.objects import rasterize_window
from mjx_pick.engine.devices import checks_device
from mjx_pick.kernels import feasibility as fk

wp = pytest.importorskip("warp")

from mjx_pick.kernels import feasibility_warp as fw  # noqa: E402

DEVICE = "cpu"  # Warp's CPU device: the kernel as CUDA runs it, on one host thread
GRIPPERS = ("robotiq-2f85", "robotiq-2f140")
FIELDS = ("reason", "opening_mm", "coverage", "gap_left_mm", "gap_right_mm")
YCB = resources.files("mjx_pick.assets") / "objects" / "ycb"
# numpy casts NaN and out-of-range floats to INT32_MIN on x86 only (elsewhere the
# reference's own result for a non-finite pose is another): the kernel mirrors x86
X86 = platform.machine().lower() in ("x86_64", "amd64")


def assert_bitwise(numpy_out, warp_out):
    """check_candidates' five (N,) arrays equal bit for bit."""
    for name, a, b in zip(FIELDS, numpy_out, warp_out, strict=True):
        assert (a.dtype, a.shape) == (b.dtype, b.shape), name
        bad = np.flatnonzero(a.view(np.int32) != b.view(np.int32))
        assert not len(bad), (
            f"{name}: {len(bad)} differ, e.g. at {bad[:4]}: {a[bad[:4]]} != {b[bad[:4]]}"
        )


def poses(rng, n: int, reach: float, stack, band):
    """(N,) x, y (mm), yaw (rad), openings (mm): off the part too, yaw of several turns
    either way with the fold's and the bins' edges, fixed openings (narrower than the
    part, wider than the stroke, an ulp either side of it, 0, < 0, inf) among NaN ones
    (chosen), and openings whose finger faces or footprints' ends fall exactly on a
    profile column's centre (where the footprints' searches must break a tie as numpy's)
    or on its edge (where a finger just lands on the part)."""
    x, y = rng.uniform(-reach, reach, n), rng.uniform(-reach, reach, n)
    yaw = rng.uniform(-3 * np.pi, 5 * np.pi, n)
    k = len(stack.crops)
    edges = np.arange(-2 * k, 4 * k) * 0.5 * np.pi / k  # bins' centres and edges
    yaw[: len(edges)] = edges
    stroke = np.float32(band.stroke_mm)
    centres = np.abs(fk._columns(band, stack.res_mm))
    special = np.concatenate(
        [
            [0.0, -5.0, np.inf, -np.inf],
            [np.nextafter(stroke, np.float32(-np.inf)), stroke, np.nextafter(stroke, np.inf)],
            2 * centres,  # a finger's inner face on a centre ...
            2 * centres + stack.res_mm,  # ... on a column's edge: the part's extent
            2 * (centres - band.finger_depth_mm),  # a footprint's outer end on one
            rng.uniform(0, band.stroke_mm + 10, 200),
        ]
    )
    opening = np.where(rng.random(n) < 0.4, rng.choice(special, n), np.nan)
    return x, y, yaw, opening


def checker_of(obj, gripper: str, **config):
    return pp.FeasibilityChecker(obj, mp.load_gripper(gripper), pp.PickConfig(**config))


def assert_kernel_is_numpy(checker, seed: int, n: int = 3 * fk.BLOCK + 7):
    """Random poses over the part and past it: numpy's blocks on threads and the one
    launch agree bit for bit; every check decides some."""
    reach = 0.5 * checker.object.length_mm + 0.6 * checker.band.stroke_mm  # past the fingers
    x, y, yaw, opening = poses(np.random.default_rng(seed), n, reach, checker.stack, checker.band)
    ref = fk.check_candidates(checker.stack, checker.band, x, y, yaw, opening)
    got = fw.check_candidates(checker.stack, checker.band, x, y, yaw, opening, device=DEVICE)
    assert_bitwise(ref, got)
    seen = set(np.unique(ref[0]).tolist())
    assert {fk.FEASIBLE, fk.OFF_OBJECT, fk.CLEARANCE, fk.COVERAGE} <= seen, seen
    chosen = fk.check_candidates(checker.stack, checker.band, x, y, yaw)  # every opening chosen
    assert_bitwise(
        chosen, fw.check_candidates(checker.stack, checker.band, x, y, yaw, device=DEVICE)
    )


@pytest.mark.parametrize("gripper", GRIPPERS)
@pytest.mark.parametrize("asset", ["door_opener", "ring"])
def test_kernel_is_numpy_bit_for_bit(asset, gripper, door_opener):
    obj = door_opener if asset == "door_opener" else mp.load_asset(asset)
    assert_kernel_is_numpy(checker_of(obj, gripper), seed=len(asset) + len(gripper))


@pytest.mark.parametrize("name, mass_g", [("040_large_marker", 15.8), ("037_scissors", 82.0)])
def test_kernel_is_numpy_on_scanned_parts(name, mass_g, hull_pieces):
    # a long thin part and one with holes (the scissors' loops), at a 1 mm raster
    with resources.as_file(YCB / f"{name}.stl") as path:
        obj = mp.load_object(path, unit="m", mass_g=mass_g)
    assert_kernel_is_numpy(checker_of(obj, "robotiq-2f85", resolution_mm=1.0), seed=5)


def test_kernel_is_numpy_for_a_tiny_gripper_on_a_fine_raster():
    # a 6 mm stroke on a 3 x 2 mm part at 0.05 mm pixels: the stroke's 1e-6 mm
    # tolerance survives float32 here (not at 85 mm), and a pixel is not a power of 2
    part = box(-1.5, -1.0, 1.5, 1.0).difference(box(-0.3, -0.3, 0.3, 0.3))
    radius = float(np.hypot(*shapely.get_coordinates(part).T).max())
    stack = fk.build_stack(rasterize_window, part, 0.05, radius)
    band = fk.GripperBand(6.0, 1.3, 0.7, 0.4, 0.35)
    x, y, yaw, opening = poses(np.random.default_rng(8), 20_000, 4.0, stack, band)
    ref = fk.check_candidates(stack, band, x, y, yaw, opening)
    assert_bitwise(ref, fw.check_candidates(stack, band, x, y, yaw, opening, device=DEVICE))
    assert set(np.unique(ref[0]).tolist()) == set(range(len(fk.REASONS) - 1))  # no pad_path


def test_kernel_is_numpy_on_poses_numpy_barely_defines(door_opener):
    # NaN and infinite poses, far-off poses past int32's pixels: numpy's casts decide
    # (INT32_MIN on x86); the kernel must neither read out of bounds nor differ
    checker = checker_of(door_opener, "robotiq-2f85")
    bad = np.array([np.nan, np.inf, -np.inf, 1e12, -1e12, 3e9, 0.0, 10.0])
    x, y, yaw = (a.ravel() for a in np.meshgrid(bad, bad, bad, indexing="ij"))
    got = fw.check_candidates(checker.stack, checker.band, x, y, yaw, device=DEVICE)
    assert np.isin(got[0], range(len(fk.REASONS))).all()
    if X86:
        assert_bitwise(fk.check_candidates(checker.stack, checker.band, x, y, yaw), got)


def test_no_candidates_and_one(door_opener):
    checker = checker_of(door_opener, "robotiq-2f85")
    empty = fw.check_candidates(checker.stack, checker.band, [], [], [], device=DEVICE)
    assert [a.shape for a in empty] == [(0,)] * 5
    assert [a.dtype for a in empty] == [np.int32] + [np.float32] * 4
    one = (0.0, 0.0, 0.3)  # scalars, as numpy's takes them
    assert_bitwise(
        fk.check_candidates(checker.stack, checker.band, *one),
        fw.check_candidates(checker.stack, checker.band, *one, device=DEVICE),
    )


def test_other_stacks_and_batch_sizes_build_nothing_again(door_opener):
    # the kernel takes the stack, the band and N as arguments: one build per device
    fw.prepare(DEVICE)
    module = fw.check_kernel.module
    built = dict(module.execs)
    for gripper in GRIPPERS:
        checker = checker_of(door_opener, gripper)
        for n in (1, 100, 5000):
            fw.check_candidates(checker.stack, checker.band, np.zeros(n), 0.0, 0.0, device=DEVICE)
    assert module.execs == built and all(module.execs[k] is v for k, v in built.items())


def test_a_search_finds_the_same_picks_with_the_kernel(door_opener):
    # the seeded draw stays on the host; the device checks groups of up to DEVICE_GROUP
    # blocks at once instead of two per thread: the same picks, the same counts
    gripper = mp.load_gripper("robotiq-2f85")
    host = pp.generate_normal(door_opener, gripper, 2500, seed=3)
    device = pp.generate_normal(door_opener, gripper, 2500, seed=3, device=DEVICE)
    assert host.n_candidates >= 4 * pp.CANDIDATE_BLOCK  # more than one group
    assert device.n_candidates == host.n_candidates and device.rejected == host.rejected
    for k in ("pick_id", "x_mm", "y_mm", "yaw_deg", "opening_mm", "coverage", "gap_left_mm"):
        np.testing.assert_array_equal(getattr(device, k), getattr(host, k), err_msg=k)
    np.testing.assert_array_equal(device.gap_right_mm, host.gap_right_mm)

    def score(batch):
        return np.linspace(0, 1, len(batch))

    runs = [
        pp.optimize(door_opener, gripper, score, 50, 0.9, 600, 200, seed=2, device=d)
        for d in (None, DEVICE)
    ]
    np.testing.assert_array_equal(runs[1].picks.pick_id, runs[0].picks.pick_id)
    assert runs[1].picks.n_candidates == runs[0].picks.n_candidates
    np.testing.assert_array_equal(runs[1].scores, runs[0].scores)


def test_checks_run_on_the_direct_warp_backends_cuda_device_only():
    warp_on = lambda name: types.SimpleNamespace(name="warp", device_name=name)  # noqa: E731
    assert checks_device(warp_on("cuda:0")) == "cuda:0"
    assert checks_device(types.SimpleNamespace(parts=[warp_on("cuda:1"), warp_on("cuda:2")])) == (
        "cuda:1"
    )
    assert checks_device(warp_on("cpu")) is None  # MJX_PICK_WARP_CPU=1: numpy's threads
    # MuJoCo C, MJX and MJX's Warp bridge name no Warp device; a Ray cluster's neither
    assert checks_device(types.SimpleNamespace(name="mjx-warp", device="gpu:H200")) is None


def test_evaluate_checks_on_the_device_its_backend_names(monkeypatch, block):
    # as a run on the `warp` backend's GPU would, with Warp's CPU device standing in:
    # the kernel checks evaluate's candidates, and the picks are numpy's
    from mjx_pick.studies import evaluation

    launches = []
    monkeypatch.setattr(evaluation, "checks_device", lambda backend: DEVICE)
    real = fw.check_candidates
    monkeypatch.setattr(
        fw, "check_candidates", lambda *a, **k: launches.append(k["device"]) or real(*a, **k)
    )
    fast = mp.GraspConfig(close_timeout_s=0.8, lift_height_mm=30.0, hold_s=0.2)
    ev = evaluation.evaluate(block, grasp=fast, backend="mujoco", batch_size=8, n=8, n_traces=0)
    assert launches and set(launches) == {DEVICE}
    host = pp.generate_normal(block, mp.GripperSpec(), 8, seed=0, grasp=fast)
    np.testing.assert_array_equal(np.asarray(ev.table["pick_id"]), host.pick_id)
    np.testing.assert_array_equal(np.asarray(ev.table["x_mm"]), host.x_mm)
