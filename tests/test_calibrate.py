"""Calibration: outcome and trace files and their errors, the parameter space and its
mapping through physics, the loss (a diverged row is never a fit), estimators on known
losses, identifiability from outcomes vs traces, the fit on synthetic outcomes with a
hidden friction (checkpoints and resume), the CLI and the contact file's provenance."""

import dataclasses
import json
import re
from pathlib import Path

import numpy as np
import pytest
from shapely.geometry import box

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core.config import PlausibilityWarning, to_toml
from mjx_pick.core.physics import load_contact
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.engine.inputs import pick_inputs, tree_leaves
from mjx_pick.studies import calibration as cal
from mjx_pick.studies.calibration import estimators as E
from mjx_pick.studies.calibration import loss as L
from mjx_pick.studies.calibration.parameters import contact_arrays_jnp, row_inputs

LIGHT = mp.GripperSpec(name="light-gripper", force_min_n=1.0)
GRASP = GraspConfig(close_timeout_s=0.6, lift_height_mm=30.0, hold_s=0.1)
# a shorter procedure for the tests that only evaluate the loss around a point
SHORT = GraspConfig(close_timeout_s=0.4, lift_height_mm=20.0, hold_s=0.05)
HIDDEN = 0.62
# the solver these fits were designed at (10 iterations, the earlier default): at the
# 50-iteration default the 24 synthetic rows no longer exclude high friction (the
# global slice stays under its threshold up to the bound), which the fit then honestly
# reports as not identified -- a data-design question, not the pipeline these tests pin
SOLVER = mp.SolverParams(iterations=10)
# and the pads: the box without the rim behind it (the default since). With the rim these
# 24 rows still lead the fit to 0.61, but the loss is rougher near it and the local
# identifiability tests find no quadratic basin, so the fit honestly reports the
# friction as not identified and writes its start (benchmarks/results/history.md)
PADS = mp.ContactParams(pad_collision="mean_radius")


@pytest.fixture(scope="module")
def heavy_block():
    return mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=1000, name="heavy")


@pytest.fixture(scope="module")
def synthetic(heavy_block):
    # 1 kg, lift accel 2 m/s^2: held iff F_d >~ m (g + a) / (2 mu) = 9.5 N at mu 0.62
    hidden = mp.Settings(
        LIGHT, dataclasses.replace(PADS, pad_friction=HIDDEN), grasp=GRASP, solver=SOLVER
    )
    f = np.repeat(np.linspace(6.0, 14.0, 12), 2)
    n = len(f)
    rng = np.random.default_rng(0)
    return cal.synthetic_outcomes(
        heavy_block,
        hidden,
        rng.uniform(-2, 2, n),
        rng.uniform(-2, 2, n),
        rng.uniform(-3, 3, n),
        f,
        lift_times=True,
    )


def _csv(tmp_path, text, name="o.csv"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_outcome_files_and_their_errors(tmp_path, heavy_block, synthetic):
    head = "x_mm,y_mm,yaw_deg,grip_force_n,trials,successes\n"
    with pytest.raises(mp.ConfigError, match="missing column.*successes"):
        cal.read_outcomes(_csv(tmp_path, "x_mm,y_mm,yaw_deg,grip_force_n,trials\n0,0,0,10,1\n"))
    with pytest.raises(mp.ConfigError, match="row 3, column successes: 4 must be.*0..trials"):
        cal.read_outcomes(_csv(tmp_path, head + "0,0,0,10,3,1\n0,0,0,10,3,4\n"))
    with pytest.raises(mp.ConfigError, match="row 2, column grip_force_n: 'ten' is not a number"):
        cal.read_outcomes(_csv(tmp_path, head + "0,0,0,ten,3,1\n"))
    with pytest.raises(mp.ConfigError, match="unknown column"):
        cal.read_outcomes(_csv(tmp_path, "x_mm,y_mm,yaw_deg,grip_force_n,trials,successes,z\n"))
    with pytest.raises(mp.ConfigError, match="force_trace.*does not exist"):
        cal.read_outcomes(_csv(tmp_path, head.strip() + ",force_trace\n0,0,0,10,1,1,nope.csv\n"))
    # a trace file with an unknown column, and one with a value that is not a number
    _csv(tmp_path, "t_s,speed\n0,1\n0.1,2\n", "bad1.csv")
    with pytest.raises(mp.ConfigError, match="column trace.*force_n, lift_mm, rotation_deg"):
        cal.read_outcomes(_csv(tmp_path, head.strip() + ",trace\n0,0,0,10,1,1,bad1.csv\n"))
    _csv(tmp_path, "t_s,lift_mm\n0,0\n0.1,x\n0.2,3\n", "bad2.csv")
    with pytest.raises(mp.ConfigError, match="row 3, column lift_mm: 'x' is not a number"):
        cal.read_outcomes(_csv(tmp_path, head.strip() + ",trace\n0,0,0,10,1,1,bad2.csv\n"))
    with pytest.raises(mp.ConfigError, match="unknown calibration parameter 'stiff'"):
        cal.canonical_params("pad_friction,stiff")
    off = cal.read_outcomes(_csv(tmp_path, head + "0,0,0,10,1,1\n200,0,0,10,1,0\n"))
    with pytest.raises(mp.ConfigError, match="1 of 2 measured pick-points are infeasible.*row 3"):
        cal.Problem(
            heavy_block, off, ["pad_friction"], mp.Settings(LIGHT, grasp=GRASP, solver=SOLVER)
        )
    with pytest.raises(
        mp.ConfigError, match=r"row 2 \(10 N\), column grip_force_n: outside robotiq-2f85"
    ):
        cal.Problem(heavy_block, off.take([0]), ["pad_friction"], mp.Settings(grasp=GRASP))
    # a round trip keeps everything, traces of every kind included (blank cells: a kind
    # measured at other times than another)
    tr = {
        "force_n": np.array([[0.0, 0.0], [0.1, 5.0]]),
        "rotation_deg": np.array([[0.05, 1.0], [0.1, 2.0], [0.2, 2.5]]),
    }
    traced = dataclasses.replace(synthetic, traces=(tr,) + synthetic.traces[1:])
    cal.write_outcomes(tmp_path / "round.csv", traced)
    back = cal.read_outcomes(tmp_path / "round.csv")
    np.testing.assert_allclose(back.grip_force_n, synthetic.grip_force_n, rtol=1e-5)
    np.testing.assert_array_equal(back.successes, synthetic.successes)
    for kind in tr:
        np.testing.assert_allclose(back.traces[0][kind], tr[kind])
    assert back.trace_kinds() == ("force_n", "rotation_deg")
    np.testing.assert_allclose(back.lift_time_s, synthetic.lift_time_s, atol=1e-4)


def test_parameters_bounds_priors_and_their_errors(heavy_block):
    s = mp.Settings()
    names = ["pad_friction", "pad_stiffness_n_per_mm", "force_offset_n", "torsion"]
    space = cal.param_space(names, s, heavy_block.mass_kg, grip_force_n=[20.0, 40.0])
    assert space.names[-1] == "pad_torsion_mm"
    for theta in ([-50.0] * 4, [0.0] * 4, [50.0] * 4):
        v = np.asarray(space.values(np.asarray(theta, np.float32)))
        # float32: within a few parts in a million of the bounds
        assert np.all(v >= space.lo - 1e-5 * abs(space.lo)) and np.all(
            v <= space.hi + 1e-5 * abs(space.hi)
        )
    # the stiffest stable contact at 1 ms is the cap: 1 kg / (2 ms)^2 = 250 N/mm; the force
    # offset may move the smallest F_d by 40 %
    assert space.hi[1] == pytest.approx(250.0)
    assert (space.lo[2], space.hi[2]) == pytest.approx((-8.0, 8.0))
    v = np.asarray(space.values(space.theta([0.62, 50.0, -1.0, 3.0])))
    assert v == pytest.approx([0.62, 50.0, -1.0, 3.0], rel=1e-4)
    with pytest.raises(mp.ConfigError, match="bounds of force_offset_n: -30 would make"):
        cal.param_space(["force_offset_n"], s, 1.0, {"force_offset_n": (-30, 5)}, grip_force_n=[20])
    with pytest.raises(mp.ConfigError, match="prior of pad_friction: mean 3 must lie"):
        cal.param_space(["pad_friction"], s, 1.0, priors={"pad_friction": (3.0, 0.1)})
    with pytest.raises(mp.ConfigError, match="bounds of pad_friction: 1..0.5 must have 0 < lo"):
        cal.param_space(["pad_friction"], s, 1.0, {"friction": (1.0, 0.5)})


def test_parameters_map_through_physics_as_settings_do(heavy_block, synthetic):
    # a parameter vector's inputs equal those of a scene built with those contact
    # parameters (physics.mujoco_contact: one mapping), F_d + offset per row; and the
    # differentiable (jnp) mapping gives the same arrays
    base = mp.Settings(LIGHT, grasp=GRASP, solver=SOLVER)
    names = [
        "pad_friction",
        "pad_torsion_mm",
        "table_friction",
        "pad_stiffness_n_per_mm",
        "table_damping_ns_per_mm",
        "force_offset_n",
    ]
    rows = synthetic.take(np.arange(4))
    problem = cal.Problem(heavy_block, rows, names, base, backend="mujoco")
    values = dict(zip(names, [0.7, 4.0, 0.3, 120.0, 0.5, 1.25], strict=True))
    got = row_inputs(problem.inputs, problem.scene, base, rows.grip_force_n, values)
    contact = dataclasses.replace(
        base.contact, **{k: v for k, v in values.items() if k != "force_offset_n"}
    )
    s2 = dataclasses.replace(base, contact=contact)
    want = pick_inputs(problem.scene, s2, problem.picks)
    np.testing.assert_allclose(got.pair_friction, want.pair_friction, rtol=1e-6)
    np.testing.assert_allclose(got.pair_solref, want.pair_solref, rtol=1e-6)
    np.testing.assert_allclose(got.params.grip_force_n, rows.grip_force_n + 1.25, rtol=1e-6)
    fr, ref, force = contact_arrays_jnp(
        names, list(values.values()), problem.inputs, problem.scene, base, heavy_block.mass_kg
    )
    np.testing.assert_allclose(np.asarray(fr), got.pair_friction, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(ref), got.pair_solref, rtol=1e-5)
    np.testing.assert_allclose(np.asarray(force), got.params.grip_force_n, rtol=1e-6)


def test_a_diverged_row_costs_the_worst_fit_not_a_perfect_one(heavy_block, synthetic):
    # the loss of outputs that match every row's measured outcome, then the same with
    # rows flagged diverged: each such row must cost what the most wrong prediction
    # costs (it once cost nothing -- a fit could prefer parameters that blow up)
    s = mp.Settings(LIGHT, grasp=GRASP, solver=SOLVER)
    problem = cal.Problem(
        heavy_block, synthetic, ["pad_friction"], s, time_weight=0.0, force_weight=0.0
    )
    held = synthetic.fraction >= 0.5
    high = problem.high_mm
    lift = np.where(held, high + 50.0, high - 50.0).astype(np.float32)  # clearly right
    t = np.zeros_like(lift)
    none = np.zeros(len(lift), bool)
    good, _ = problem.loss_terms(lift, t, none)
    wrong, _ = problem.loss_terms(
        np.where(held, high - 50.0, high + 50.0).astype(np.float32), t, none
    )
    some = none.copy()
    some[:3] = True
    blown, _ = problem.loss_terms(lift, t, some)
    every, _ = problem.loss_terms(lift, t, ~none)
    assert float(good) < float(blown) < float(every)
    assert float(every) == pytest.approx(float(wrong), rel=1e-5)


def test_fit_steers_away_from_a_diverging_region(heavy_block, synthetic, monkeypatch):
    # a stand-in for the simulation (the loss and the fit loop are what is tested):
    # held iff mu F_d > 5.9 N, and for mu > 1 every simulation blows up -- reporting
    # "perfect" lifts, as a blow-up's garbage may. Started inside that region, the fit
    # must leave it and find the hidden 0.62 (with zero cost for diverged rows it stayed)
    problem = cal.Problem(
        heavy_block,
        synthetic,
        ["pad_friction"],
        mp.Settings(LIGHT, grasp=GRASP, solver=SOLVER),
        time_weight=0.0,
        start={"pad_friction": 1.3},
    )
    f = synthetic.grip_force_n
    high = problem.high_mm

    def fake(thetas):
        mu = np.asarray(problem.space.values(np.atleast_2d(thetas)))[:, :1]
        held = mu * f[None] > 5.9
        blown = np.broadcast_to(mu > 1.0, held.shape)
        lift = np.where(held | blown, high + 5.0, high - 20.0).astype(np.float32)
        return {
            "lift_height_mm": lift,
            "t_reached_s": np.zeros_like(lift),
            "diverged": blown,
            "success": held & ~blown,
        }

    monkeypatch.setattr(problem, "simulate", fake)
    res = cal.calibrate(
        problem, estimator="smoothed", steps=40, learning_rate=0.3, sigma=0.5, identify=False
    )
    assert res.history[0]["diverged"] == len(synthetic)
    assert res.history[-1]["diverged"] == 0
    assert res.values["pad_friction"] == pytest.approx(HIDDEN, abs=0.08)


def test_a_nan_gradient_stops_the_fit_with_a_clear_error(heavy_block, synthetic, monkeypatch):
    # a NaN turned into a zero would be a silent "no change"
    problem = cal.Problem(
        heavy_block, synthetic, ["pad_friction"], mp.Settings(LIGHT, grasp=GRASP, solver=SOLVER)
    )
    monkeypatch.setattr(problem, "mjx_loss_and_grad", lambda th: (1.0, np.array([np.nan])))
    with pytest.raises(mp.ConfigError, match="step 0: the 'jvp' gradient is not finite at"):
        cal.calibrate(problem, steps=3, estimator="jvp", identify=False)


def test_estimators_on_known_losses():
    # smoothed gradient = the gradient on a quadratic; on a step, the Gaussian density
    def quad(th):
        return np.sum((np.asarray(th) - 1.0) ** 2, axis=-1)

    theta = np.array([0.3, -0.5], np.float32)
    loss, grad = E.smoothed_gradient(quad, theta, samples=2, sigma=0.3)
    assert loss == pytest.approx(np.sum((theta - 1) ** 2))
    assert grad == pytest.approx(2 * (theta - 1), rel=1e-4)
    _, grad = E.smoothed_gradient(
        lambda th: (np.asarray(th)[..., 0] > 0.1) * 1.0, np.zeros(2, np.float32), 8, 0.5
    )
    density = np.exp(-0.5 * (0.1 / 0.5) ** 2) / (0.5 * np.sqrt(2 * np.pi))
    assert grad[0] == pytest.approx(density, rel=0.1) and grad[1] == 0.0
    # every ask/tell estimator finds the minimum of a 3-parameter quadratic bowl
    target = np.array([0.8, -1.2, 0.4])
    for est, steps in (
        (E.smoothed(60, 0.3), 60),
        (E.cma_es(seed=1), 40),
        (E.random_search(64, seed=0), 40),
    ):
        state = est.init(np.zeros(3, np.float32))
        for _ in range(steps):
            th = est.ask(state)
            state = est.tell(state, th, np.sum((th - target) ** 2, axis=-1))
        tol = 0.35 if est.name == "random" else 0.05
        assert est.best(state) == pytest.approx(target, abs=tol), est.name
        # a state survives the checkpoint's round trip
        assert E.loads(E.dumps(state)).step == state.step


def test_identifiability_outcomes_against_traces(heavy_block):
    # outcomes alone pin pad friction and the gripper's force offset only loosely (the
    # outcome mostly sees mu x (F_d + offset)); a force gauge's traces narrow the offset
    # (the squeeze itself) -- less than tick-by-tick residuals claimed: their jumps made
    # a steep local curvature (results/history.md); pad friction barely (the force does not
    # see it until the part slips, and a slipping grasp's trace is chaotic). The table's
    # damping, which neither sees, is reported as not identified
    hidden = mp.Settings(LIGHT, mp.ContactParams(pad_friction=HIDDEN), grasp=SHORT)
    rng = np.random.default_rng(0)
    n = 8
    poses = rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), rng.uniform(-3, 3, n)
    f = np.linspace(6.0, 14.0, n)
    out = cal.synthetic_outcomes(heavy_block, hidden, *poses, f, force_offset_n=1.5)
    traced = cal.synthetic_outcomes(
        heavy_block, hidden, *poses, f, force_offset_n=1.5, traces=("force_n",)
    )
    names = ["pad_friction", "force_offset_n", "table_damping_ns_per_mm"]
    half = {}
    for label, data in (("outcomes", out), ("traces", traced)):
        problem = cal.Problem(heavy_block, data, names, hidden, backend="mujoco")
        theta = problem.space.theta([HIDDEN, 1.5, problem.start["table_damping_ns_per_mm"]])
        # the local tests only: the slice (test_identifiability_global_check_rejects_...)
        # and the profile's refit (test_identifiability_profile_sees_a_valley_...) are
        # tested on cheap problems; here the refit was most of the test's time
        ident = cal.identifiability(problem, theta, profile_points=0, profile_scales=())
        half[label] = {n: ident[n]["data_half_width_z"] or np.inf for n in names}
        assert not ident["table_damping_ns_per_mm"]["identified"], label
        lo, hi = ident["force_offset_n"]["interval"]
        assert lo < 1.5 < hi, label
    assert half["traces"]["force_offset_n"] < 0.75 * half["outcomes"]["force_offset_n"], half


def test_trace_loss_is_smooth_around_the_hidden_friction(heavy_block):
    # benchmarks/calibration.py's one-parameter problem: 16 rows whose traces slip and
    # drop. Compared tick by tick with one simulation per row, a 0.1 % step of pad
    # friction costs a large share of a 10 % one (the synthetic trace is one draw of a
    # sensitive grasp: only the exact hidden value redraws it); the replicas' likelihood
    # (loss.py) lowers that share. How much depends on the physics: with pyramidal cones
    # (chattering pads) tick by tick > 0.4 and replicas < 0.15; with the elliptic default
    # 0.32 and 0.20 (benchmarks/results/history.md). Without the pads' contact margin: with the
    # default 0.05 mm a 0.1 % step costs as much as a 10 % one tick by tick on two of
    # three draws of these poses, and the replicas no longer smooth it on one
    # (benchmarks/results/history.md, "A contact margin on the pads"): the margin's known cost
    hidden = mp.Settings(
        LIGHT, mp.ContactParams(pad_friction=HIDDEN, pad_margin_mm=0.0), grasp=GRASP
    )
    rng = np.random.default_rng(0)
    n = 16
    poses = rng.uniform(-3, 3, n), rng.uniform(-5, 5, n), rng.uniform(-5, 5, n)
    noise = {"force_n": 0.3, "lift_mm": 0.5, "rotation_deg": 1.0}
    data = cal.synthetic_outcomes(
        heavy_block, hidden, *poses, np.linspace(5, 14, n), traces=True, trace_noise=noise
    )
    steps = np.array([-0.1, -0.001, 0.0, 0.001, 0.1])  # relative to the hidden value
    problem = cal.Problem(heavy_block, data, ["pad_friction"], hidden, backend="mujoco")
    assert problem.replicates == 3 and problem.noise.trace_window_s == 0.05  # the defaults
    thetas = np.stack([problem.space.theta([HIDDEN * (1 + d)]) for d in steps])
    sim = problem.simulate(thetas)  # each row at its pick-point, then its replicas
    # the former residual: the pick-point's own simulation, tick by tick
    own = {k: v for k, v in sim.items() if not k.endswith("_replicas")}
    loss = {}
    for label, out, noise in (
        ("tick by tick", own, cal.Noise(trace_window_s=0.0)),
        ("replicas", sim, problem.noise),
    ):
        blocks = L.residuals(out, problem.data, noise)
        loss[label] = np.asarray(L.loss_of(blocks, problem.data.total_trials)[0])
    climb = {}
    for label, v in loss.items():
        # both: the 10 % steps climb above everything within 0.1 % of the hidden value
        assert max(v[1], v[2], v[3]) < min(v[0], v[4]), (label, v)
        # how far a 0.1 % step climbs towards a 10 % step's loss (negative: below)
        climb[label] = (max(v[1], v[3]) - v[2]) / (min(v[0], v[4]) - v[2])
    # tick by tick only the exact hidden value redraws the synthetic trace: a spike
    tick = loss["tick by tick"]
    assert tick[2] < min(tick[0], tick[1], tick[3], tick[4]), tick
    # the replicas flatten it to a basin: the small steps cost a smaller share of a 10 %
    # step, in either direction (at the rimmed default a 0.1 % step below the hidden
    # value scored lower than the value itself, within the replicas' noise)
    assert abs(climb["replicas"]) < 0.75 * climb["tick by tick"], (climb, loss)


def test_replicas_only_for_traced_rows_and_alike_in_numpy_and_jax(heavy_block):
    # rows 0 and 2 have a force trace: each gets K - 1 = 2 replicas, moved +-0.05 mm;
    # split() hands every measured row its own simulation and its replicas, the same in
    # numpy (the engine's path) and jax (the forward-mode path)
    import jax.numpy as jnp

    from mjx_pick.kernels.grasp import TRACE_FIELDS
    from mjx_pick.studies.calibration.problem import trace_outputs

    rows = cal.make_outcomes([0, 1, -1], [0, 0.5, 0], [0, 0, 5], [8, 9, 10])
    trace = {"force_n": np.array([[0.0, 0.0], [0.3, 5.0]])}
    rows = dataclasses.replace(rows, traces=(trace, None, trace))
    problem = cal.Problem(heavy_block, rows, ["pad_friction"], mp.Settings(LIGHT, grasp=SHORT))
    assert problem.row_of.tolist() == [0, 1, 2, 0, 2, 0, 2]
    assert np.allclose(problem.picks.x_mm, [0, 1, -1, 0.05, -0.95, -0.05, -1.05])
    n, t = len(problem.row_of), 4
    rng = np.random.default_rng(0)
    out = {
        "diverged": np.array([[0, 0, 0, 1, 0, 0, 0]], bool),
        "lift_height_mm": rng.normal(size=(1, n)),
    }
    traces = rng.normal(size=(1, n, t, len(TRACE_FIELDS))).astype(np.float32)
    a = problem.split(out, traces)
    b = problem.split({k: jnp.asarray(v) for k, v in out.items()}, jnp.asarray(traces), xp=jnp)
    assert a["force_n"].shape == (1, 3, t) and a["force_n_replicas"].shape == (1, 3, 2, t)
    for k in a:
        np.testing.assert_allclose(np.asarray(b[k]), a[k], rtol=1e-6, err_msg=k)
    own = a["force_n"][0]
    # row 2's second replica is simulated row 6 (replica-major: 0 1 2 | 0 2 | 0 2)
    sixth = trace_outputs(traces[:, 6])["force_n"][0]
    np.testing.assert_allclose(a["force_n_replicas"][0, 2, 1], sixth, rtol=1e-6)
    # row 1 has no trace: its "replicas" are its own simulation; row 0's first replica
    # (simulated row 3) diverged
    np.testing.assert_array_equal(a["force_n_replicas"][0, 1, 0], own[1])
    assert a["diverged_replicas"][0].tolist() == [[True, False], [False, False], [False, False]]
    assert not np.allclose(a["force_n_replicas"][0, 2, 0], own[2])


class _TwoBasins:
    """A stand-in Problem with known residuals (no simulation): parameter a has one
    quadratic basin at 0.3; parameter b has two equally deep ones, at 0.3 and 0.8 --
    smooth and curved around each, so that the local tests see nothing wrong."""

    def __init__(self):
        one = np.ones(2)
        self.space = cal.ParamSpace(("a", "b"), 0 * one, one, one < 0, 0.5 * one, 10 * one)
        self.outcomes = [None]
        self.data = dataclasses.make_dataclass("D", [("total_trials", float)])(1.0)
        self.rollouts = 0

    def evaluate(self, thetas):
        v = np.asarray(self.space.values(thetas), float)  # (S, 2)
        a, b = v[:, 0], v[:, 1]
        near = np.where(np.abs(b - 0.3) < np.abs(b - 0.8), 0.3, 0.8)
        w = np.linspace(1, 2, 20)  # 20 residuals per parameter, noise units
        res = np.concatenate([w * 20 * (a[:, None] - 0.3), w * 20 * (b - near)[:, None]], 1)
        self.rollouts += len(v)
        loss = 0.5 * np.sum(res**2, axis=1)
        return cal.Evaluation(loss, {}, np.zeros(len(v)), res, res.shape[1])


def test_identifiability_global_check_rejects_a_second_basin():
    problem = _TwoBasins()
    theta = problem.space.theta([0.3, 0.3])
    ident = cal.identifiability(problem, theta)
    a, b = ident["a"], ident["b"]
    assert a["identified"] and a["global"]["passed"]
    assert a["interval"][0] < 0.3 < a["interval"][1] and a["interval"][1] - a["interval"][0] < 0.1
    # the local tests are fooled by b's curved basin; the slice finds the other one
    assert b["local"] and b["locally_quadratic"]
    assert not b["global"]["passed"] and not b["identified"]
    lo, hi = b["global"]["interval"]
    assert lo < 0.3 and hi > 0.8
    # without the slice, b would pass: the check is what rejects it
    assert cal.identifiability(problem, theta, profile_points=0)["b"]["identified"]


class _Valley:
    """A stand-in Problem (no simulation) with a valley across two parameters, as pad
    friction against the gripper's force offset: the data see b - 0.5 a sharply (20
    residuals) and a itself only through a pin that saturates (tanh: at most ~0.9 of
    -log likelihood, under the 95 % threshold of 1.92). c: a plain basin at 0.5."""

    def __init__(self):
        one = np.ones(3)
        # priors: 95 % half-width = the bounds, so "narrow" is under a quarter of them
        self.space = cal.ParamSpace(("a", "b", "c"), 0 * one, one, one < 0, 0.5 * one, one / 1.96)
        self.outcomes = [None]
        self.data = dataclasses.make_dataclass("D", [("total_trials", float)])(1.0)
        self.rollouts = self.evaluations = 0

    def evaluate(self, thetas):
        self.evaluations += 1
        a, b, c = np.asarray(self.space.values(thetas), float).T
        w = np.linspace(1, 2, 20)
        res = np.concatenate(
            [
                w * 20 * (b - 0.3 - 0.5 * (a - 0.3))[:, None],
                w * 0.2 * np.tanh((a - 0.3) / 0.02)[:, None],
                w * 20 * (c - 0.5)[:, None],
            ],
            1,
        )
        self.rollouts += len(a)
        loss = 0.5 * np.sum(res**2, axis=1)
        return cal.Evaluation(loss, {}, np.zeros(len(a)), res, res.shape[1])


def test_identifiability_profile_sees_a_valley_across_parameters():
    problem = _Valley()
    theta = problem.space.theta([0.3, 0.3, 0.5])
    # the local tests and the slice (the others held at theta) call all three identified
    held = cal.identifiability(problem, theta, profile_scales=())
    assert all(held[n]["identified"] for n in "abc")
    assert held["a"]["interval"][1] - held["a"]["interval"][0] < 0.15
    spent, calls = problem.rollouts, problem.evaluations
    ident = cal.identifiability(problem, theta)
    # the profile refits the others: b follows a along the valley, every point fits
    for n in "ab":
        info = ident[n]
        assert info["slice_identified"] and not info["identified"], n
        refit = info["profile"]["refit"]
        assert refit["open"] and all(q["kept"] for q in refit["points"]), n
        assert info["interval"][1] - info["interval"][0] > 2.5 * (
            info["slice_interval"][1] - info["slice_interval"][0]
        )
    far = [q for q in ident["a"]["profile"]["refit"]["points"] if q["scale"] == 3.0][0]
    assert far["others"]["b"] == pytest.approx(0.3 + 0.5 * (far["value"] - 0.3), abs=0.01)
    # c's profile rises beyond its interval: still identified, its interval kept
    c = ident["c"]
    assert c["identified"] and not c["profile"]["refit"]["open"]
    assert c["interval"] == pytest.approx(c["slice_interval"])
    assert [q["kept"] for q in c["profile"]["refit"]["points"]] == [True, False, False] * 2
    # batched: the slice's batch, then the refit's two starts and 4 generations
    assert problem.evaluations - calls == 1 + 1 + 4
    assert ident["profile_rollouts"] == 3 * 6 * (2 + 6 * 4)
    assert problem.rollouts - spent == ident["rollouts"]
    # the fit's own vectors alone (no refit): vectors along the valley widen a
    v = np.linspace(0.02, 0.62, 11)
    seen = problem.space.theta(np.stack([v, 0.3 + 0.5 * (v - 0.3), np.full(11, 0.5)], 1))
    nll = problem.evaluate(seen).loss
    emp = cal.identifiability(problem, theta, visited=(seen, nll), profile_steps=0)["a"]
    assert not emp["profile"]["empirical"]["passed"] and emp["profile"]["refit"] is None
    assert emp["interval"][0] < 0.1 and emp["interval"][1] > 0.5
    with pytest.raises(mp.ConfigError, match="visited must be"):
        cal.identifiability(problem, theta, visited=(seen[:, :2], nll))
    with pytest.raises(mp.ConfigError, match="profile_scales"):
        cal.identifiability(problem, theta, profile_scales=(0.5,))


def test_fit_moves_friction_to_the_hidden_value_and_resumes(tmp_path, heavy_block, synthetic):
    assert 0 < synthetic.successes.sum() < len(synthetic), "the data must hold both outcomes"
    # the fit starts below the hidden value: this loss is not monotone between 0.62 and
    # Table 1's 0.86, where a local gradient fit stalls; below 0.62 it falls
    start = dataclasses.replace(PADS, pad_friction=0.45)
    base = mp.Settings(LIGHT, start, grasp=GRASP, solver=SOLVER)
    problem = cal.Problem(heavy_block, synthetic, ["pad_friction"], base, backend="mujoco")
    # every simulation of this fit, by its parameter vectors: the resumed fit below asks
    # for the same vectors (a resume that restored another state asks for others, which
    # are simulated), and the C engine's results are a function of them alone -- the
    # second fit's 13 steps of 24 rows x 5 vectors each were a third of this test's time
    # -- keyed by the problem's simulation inputs too, so that a resumed problem built
    # on other pick-points or settings misses and is simulated
    simulated = {}
    simulate = problem.simulate

    def sim_key(pr, thetas) -> bytes:
        leaves = [np.asarray(a) for a in tree_leaves(pr.inputs)]
        return b"".join(a.tobytes() for a in leaves) + np.asarray(thetas, np.float32).tobytes()

    def simulate_and_keep(thetas):
        key = sim_key(problem, np.atleast_2d(thetas))
        simulated[key] = simulate(thetas)
        return simulated[key]

    problem.simulate = simulate_and_keep
    before = problem.loss(problem.space.theta([0.45])[None])[0]
    # the smoothed gradient from below: on these 24 outcome + lift-time rows CMA-ES (the
    # default) stopped in 8 steps at 0.72, a local basin of this loss (results/history.md)
    kw = dict(estimator="smoothed", steps=12, checkpoint_every=6)
    whole = cal.calibrate(problem, **kw)
    mu = whole.values["pad_friction"]
    assert mu == pytest.approx(HIDDEN, rel=0.15)
    assert problem.loss(problem.space.theta([mu])[None])[0] < before
    info = whole.identifiability["pad_friction"]
    assert info["identified"] and info["interval"][0] < mu < info["interval"][1]
    # a well-pinned parameter passes the profile too: the fit's own vectors (the
    # empirical profile) and the likelihood beyond its interval's ends (fitted alone,
    # there are no others to refit) exclude what lies outside
    prof = info["profile"]
    assert prof["passed"] and prof["empirical"]["vectors"] == 12 * 5
    assert not prof["refit"]["open"] and prof["refit"]["points"][-1]["nll_rise"] > 1.92

    # killed after the checkpoint of step 6, resumed: the same fit as without the kill
    class Killed(Exception):
        pass

    def kill_at_7(entry):
        if entry["step"] == 6:
            raise Killed

    p2 = cal.Problem(heavy_block, synthetic, ["pad_friction"], base, backend="mujoco")
    simulate_p2 = p2.simulate
    asked = []

    def simulated_before(thetas):
        key = sim_key(p2, np.atleast_2d(thetas))
        asked.append(key in simulated)
        return simulated[key] if key in simulated else simulate_p2(thetas)

    p2.simulate = simulated_before
    with pytest.raises(Killed):
        cal.calibrate(p2, **kw, out=tmp_path, log=kill_at_7, identify=False)
    assert not (tmp_path / "contact.toml").exists()
    assert (tmp_path / "checkpoint").is_dir()  # what the resume reads
    resumed = cal.calibrate(p2, **kw, out=tmp_path, resume=True, identify=False)
    assert not (tmp_path / "checkpoint").exists()  # removed once the fit is complete
    assert resumed.values["pad_friction"] == pytest.approx(mu, abs=1e-5)
    assert len(resumed.history) == 12
    assert asked and all(asked)  # the killed and resumed fits asked for the whole fit's vectors
    fitted, meta = load_contact(tmp_path / "contact.toml")
    assert fitted.pad_friction == pytest.approx(mu, abs=1e-6)
    assert meta["fitted_for"]["object"] == "heavy"
    assert meta["fitted_for"]["gripper"] == "light-gripper"
    assert meta["fitted_for"]["procedure"]["hold_s"] == pytest.approx(0.1)
    report = json.loads((tmp_path / "calibration.json").read_text())
    assert report["fitted"]["pad_friction"] == pytest.approx(mu, abs=1e-6)
    assert (tmp_path / "loss.png").is_file() and (tmp_path / "report.md").is_file()
    # a complete fit's folder (its checkpoints gone) is still refused to another fit
    with pytest.raises(mp.ConfigError, match="holds `mjx-pick calibrate` results"):
        cal.calibrate(p2, steps=1, out=tmp_path)


def test_cli_calibrate_and_the_contact_files_provenance(tmp_path, synthetic, capsys):
    cal.write_outcomes(tmp_path / "outcomes.csv", synthetic)
    (tmp_path / "grasp.toml").write_text(to_toml(GRASP))
    (tmp_path / "light.toml").write_text(to_toml(LIGHT))
    # the same 1 kg block, from the shipped block image with its mass overridden
    obj = ["block", "--mass-g", "1000"]
    args = [
        "calibrate",
        str(tmp_path / "outcomes.csv"),
        *obj,
        "--gripper-file",
        str(tmp_path / "light.toml"),
        "--grasp",
        str(tmp_path / "grasp.toml"),
        "--backend",
        "mujoco",
        "--steps",
        "3",
        "--budget",
        "100",
        "--no-identify",
        "--out",
        str(tmp_path / "fit"),
    ]
    assert main(args) == 0
    captured = capsys.readouterr()
    assert "pad_friction: 0.86 ->" in captured.out
    # the steps' progress on stderr, the loss lines on stdout
    assert re.search(r"calibrating \(cma\): +\d+% \d/3 step", captured.err), captured.err
    assert captured.out.count("step    0  loss") == 1
    contact = tmp_path / "fit" / "contact.toml"
    assert contact.is_file()
    run = json.loads((tmp_path / "fit" / "run.json").read_text())
    assert run["command"] == "calibrate" and run["status"] == "complete"
    assert run["backend"] == "mujoco" and run["timing"]["simulations"] > 0
    assert run["timing"]["rollouts"] > 0 and run["config"]["steps"] == 3
    assert main(args[:-1] + [str(tmp_path / "fit2"), "--params", "pad_friction,nope"]) == 2
    assert "unknown calibration parameter 'nope'" in capsys.readouterr().err
    assert main(args[:-1] + [str(tmp_path / "fit3"), "--bounds", "pad_friction=0.3"]) == 2
    assert "--bounds 'pad_friction=0.3': expected NAME=A:B" in capsys.readouterr().err
    # evaluate with the fitted contact: silent on the set-up it was fitted for, a
    # warning naming each difference on another gripper and hold
    ev = ["evaluate", *obj, "--contact", str(contact), "--n", "2", "--backend", "mujoco"]
    same = ev + [
        "--gripper-file",
        str(tmp_path / "light.toml"),
        "--grasp",
        str(tmp_path / "grasp.toml"),
        "--out",
        str(tmp_path / "ev1"),
    ]
    assert main(same) == 0
    assert "fitted for another set-up" not in capsys.readouterr().err
    assert main(ev + ["--hold-s", "0.3", "--out", str(tmp_path / "ev2")]) == 0
    err = capsys.readouterr().err
    assert "fitted for another set-up" in err
    assert "gripper 'light-gripper' (this run: 'robotiq-2f85')" in err
    assert "grasp.hold_s 0.1 (this run: 0.3)" in err


@pytest.mark.mjx
def test_forward_mode_gradient_through_mjx(heavy_block, synthetic, monkeypatch):
    # reverse mode cannot pass MJX's solver while_loop (upstream #2259); forward mode
    # runs and is finite. No finite-difference check can hold over a whole pick: the
    # pathwise derivative of 2,600 steps of contact is not the derivative of its outcome
    # (benchmarks/calibration.py measures the disagreement; RESULTS.md)
    import jax
    import jax.numpy as jnp

    from mjx_pick.engine.mjx_backend import make_rollout
    from mjx_pick.studies.calibration import problem as problem_module

    rows = synthetic.take([0, len(synthetic) - 1])
    # MJX runs the differentiable physics alone (at the default's elliptic cones its
    # forward-mode gradient is NaN): a problem on it refuses the defaults when it is made,
    # before anything runs, and says what to pass; the jvp path of a problem on another
    # backend refuses them too
    default = mp.Settings(LIGHT, mp.ContactParams(), grasp=SHORT)
    with pytest.raises(mp.ConfigError, match="solver.cone = 'elliptic'.*pyramidal"):
        cal.Problem(heavy_block, rows, ["pad_friction"], default, backend="mjx")
    on_c = cal.Problem(heavy_block, rows, ["pad_friction"], default, backend="mujoco")
    with pytest.raises(mp.ConfigError, match="solver.cone = 'elliptic'.*pyramidal"):
        on_c.mjx_loss_and_grad(on_c.space.theta([0.75]))
    # the pad box without the rim: the rim's pairs make MJX several times slower on a
    # CPU, and the gradient's plumbing, tested here, does not depend on the pads
    box = mp.ContactParams.differentiable(mp.ContactParams(pad_collision="mean_radius"))
    base = mp.Settings(LIGHT, box, mp.SolverParams.differentiable(), grasp=SHORT)
    problem = cal.Problem(heavy_block, rows, ["pad_friction"], base, backend="mjx")
    # the rollout the problem differentiates (mjx_backend.make_rollout, through
    # simulator.differentiable_rollout), kept for the reverse-mode check below: the same
    # jitted function on the same shapes, whose trace JAX then reuses instead of tracing
    # MJX's Python a second time (half this test's time on a CPU)
    made = []

    def keep(*args):
        made.append(make_rollout(*args))
        return made[-1]

    monkeypatch.setattr(problem_module, "differentiable_rollout", keep)
    loss, grad = problem.mjx_loss_and_grad(problem.space.theta([0.75]))
    assert np.isfinite(loss) and np.all(np.isfinite(grad))
    (roll,) = made
    inp = problem.inputs

    def lift(mu):
        fr, ref, force = contact_arrays_jnp(
            ["pad_friction"], [mu], inp, problem.scene, base, heavy_block.mass_kg
        )
        params = inp.params._replace(grip_force_n=force)
        out, _ = roll(inp.qpos0, params, fr, ref, inp.pair_solimp)
        return jnp.sum(out["lift_height_mm"])

    # traced, not run: JAX raises when it transposes the solver's while_loop, before
    # anything is compiled (called eagerly, jax.grad first compiles and runs the whole
    # forward pass -- a second full compile of the rollout -- and then raises the same)
    with pytest.raises(ValueError, match="Reverse-mode differentiation does not work"):
        jax.eval_shape(jax.grad(lift), jnp.float32(0.7))


class _Line:
    """A stand-in Problem with one parameter, pad_friction, whose data pull it towards
    `best` (20 residuals of `weight` noise units per unit) under a prior of 95 %
    half-width `prior_half` around 0.86, within bounds 0.05-2."""

    def __init__(self, best, weight=20.0, prior_half=10.0):
        self.best, self.weight = best, weight
        one = np.ones(1)
        self.space = cal.ParamSpace(
            ("pad_friction",), 0.05 * one, 2.0 * one, one < 0, 0.86 * one, prior_half / 1.96 * one
        )
        self.names = ("pad_friction",)
        self.outcomes = [None]
        self.data = dataclasses.make_dataclass("D", [("total_trials", float)])(1.0)
        self.rollouts = 0

    def evaluate(self, thetas):
        v = np.asarray(self.space.values(thetas), float)[:, 0]
        res = np.linspace(1, 2, 20) * self.weight * (v - self.best)[:, None]
        self.rollouts += len(v)
        return cal.Evaluation(0.5 * np.sum(res**2, axis=1), {}, np.zeros(len(v)), res, 20)


def test_a_fit_at_a_bound_is_never_identified():
    # the data want 2.4; the bounds stop the fit at 1.992: a narrow, curved loss there
    problem = _Line(best=2.4)
    u = (1.992 - 0.05) / 1.95  # the estimators search in theta = logit(u), to the bound
    theta = np.log([u / (1 - u)]).astype(np.float32)
    info = cal.identifiability(problem, theta)["pad_friction"]
    assert info["at_bound"] == "upper" and not info["identified"]
    # well inside the bounds the same data identify it
    inside = _Line(best=1.5)
    info = cal.identifiability(inside, inside.space.theta([1.5]))["pad_friction"]
    assert info["at_bound"] is None and info["identified"]


def test_the_written_value_lies_inside_the_reported_interval():
    from mjx_pick.studies.calibration.fit import _finish, kept_value

    # data that put friction near 0.55 (95 % about +-0.2) yet too loosely for the
    # narrow prior to call it identified: the start 0.86 is outside their interval
    problem = _Line(best=0.55, weight=1.5, prior_half=0.3)
    res = _finish(
        problem,
        problem.space.theta([0.55]),
        {"pad_friction": 0.86},
        [],
        None,
        None,
        True,
        "cma",
        None,
        mp.ContactParams(),
    )
    info = res.identifiability["pad_friction"]
    lo, hi = info["interval"]
    assert not info["identified"] and hi < 0.86
    assert lo <= res.values["pad_friction"] <= hi
    assert res.contact.pad_friction == res.values["pad_friction"] == pytest.approx(hi)
    assert kept_value(0.86, (0.3, 0.9)) == 0.86  # inside: the start is kept


def test_outcomes_of_another_mass_or_gripper_are_refused_unless_forced(tmp_path, capsys):
    rows = cal.read_outcomes("block_1kg_rg2")
    assert rows.measured["mass_g"] == 1000 and rows.measured["gripper"] == "onrobot-rg2"
    rg2 = mp.Settings(mp.load_gripper("onrobot-rg2"))
    light = mp.load_asset("block")  # 43 g: not the 1 kg block that was measured
    with pytest.raises(mp.ConfigError, match=r"mass: measured 1000 g \(block\), .* 43.2 g"):
        cal.Problem(light, rows, ["pad_friction"], rg2)
    with pytest.raises(mp.ConfigError, match="gripper: measured onrobot-rg2, the run's rob"):
        cal.Problem(mp.load_asset("block", mass_g=1000), rows, ["pad_friction"])
    with pytest.warns(UserWarning, match="forced"):
        cal.Problem(light, rows, ["pad_friction"], rg2, force_mismatch=True)
    cal.Problem(mp.load_asset("block", mass_g=1000), rows, ["pad_friction"], rg2)  # as measured
    # the CLI: one line, before the output folder is claimed
    out = tmp_path / "cal"
    args = ["calibrate", "block_1kg_rg2", "block", "--gripper", "onrobot-rg2", "--out", str(out)]
    assert main(args) == 2
    err = capsys.readouterr().err
    assert "mass: measured 1000 g" in err and "--force-mismatch" in err
    assert not out.exists()
    # a record with an unknown key or a bad mass is refused
    csv = tmp_path / "mine.csv"
    csv.write_text("x_mm,y_mm,yaw_deg,grip_force_n,trials,successes\n0,0,0,10,1,1\n")
    (tmp_path / "mine.toml").write_text("mass_g = -1\n")
    with pytest.raises(mp.ConfigError, match="mine.toml: mass_g = -1"):
        cal.read_outcomes(csv)
    (tmp_path / "mine.toml").write_text("weight = 3\n")
    with pytest.raises(mp.ConfigError, match="mine.toml: unknown key"):
        cal.read_outcomes(csv)


def test_the_shipped_synthetic_outcomes_are_what_the_physics_makes():
    # block_1kg_rg2.csv is simulated (tools/make_outcomes.py): when the defaults or the
    # model it was made with change, the example and README's fit of it no longer hold.
    # Cheap: the digest of its hidden settings and model, and four rows simulated again.
    import importlib.util

    from mjx_pick.studies.calibration.synthetic_outcomes import (
        synthetic_digest,
        synthetic_outcomes,
    )

    root = Path(__file__).resolve().parents[1]
    spec = importlib.util.spec_from_file_location("make_outcomes", root / "tools/make_outcomes.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    with pytest.warns(PlausibilityWarning):  # a lead-filled block: denser than solids
        obj, hidden, x, y, yaw, f = tool.example()
    rows = cal.read_outcomes("block_1kg_rg2")
    regenerate = "regenerate it: python tools/make_outcomes.py, and check README's fit"
    assert rows.measured["synthetic"] == synthetic_digest(obj, hidden), (
        f"block_1kg_rg2.csv was simulated with other settings or another model; {regenerate}"
    )
    np.testing.assert_allclose(rows.grip_force_n, f, atol=1e-4)
    np.testing.assert_allclose(rows.yaw_deg, yaw, atol=1e-4)
    some = [3, 4, 16, 17]  # rows on both sides of the force that just holds the part
    again = synthetic_outcomes(obj, hidden, x[some], y[some], yaw[some], f[some])
    assert list(again.successes) == list(rows.successes[some]), (
        f"block_1kg_rg2.csv's outcomes are not what the physics gives now; {regenerate}"
    )
