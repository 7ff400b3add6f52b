"""The template-and-trial loop (``mjx-pick trials``): the information a trial carries and
the choice of pick-points, the agreement's arithmetic, the plan's folder (sheet, 1:1
templates, predictions), every bad input refused before simulating, the prompt, and the
whole loop on synthetic "real" outcomes simulated with a hidden pad friction: plan ->
fill -> agree -> fit -> agreement again -> next round.

Small and fast: the shipped block at 1 kg with a light gripper and a short procedure at
F_d = 10 N, where pad friction decides which grasps hold (as tests/test_calibrate.py)."""

import csv
import json
import shutil

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.cli import main
from mjx_pick.core.metrics import wilson_interval
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.studies import calibration as cal
from mjx_pick.studies.calibration import trials as CT
from mjx_pick.studies.calibration.trials import loop as T

LIGHT = mp.GripperSpec(name="light-gripper", force_min_n=1.0)
PROC = GraspConfig(close_timeout_s=1.0, lift_height_mm=20.0, hold_s=0.05, grip_force_n=10.0)
HIDDEN = 0.70  # the "real" cell's pad friction; the run simulates Table 1's 0.86
N, REPEATS = 8, 2


@pytest.fixture(scope="module")
def heavy():
    return mp.load_asset("block", mass_g=1000)


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory, heavy):
    out = tmp_path_factory.mktemp("trials") / "run"
    # the default solver, with the pads the loop's small fit budgets were designed at
    # (the pad box without the rim behind it, with which 0.70 and 0.86 give the same
    # labels on all 8 planned picks): the run's settings are what the trials
    # re-simulate and fit. (The earlier 10 iterations do not converge impratio 100's
    # friction rows: a planned pick then came out otherwise when re-simulated through
    # the fit's parameter path.) No pad contact margin either: at the default 0.05 mm
    # the 6-step fit found no friction that explains these 8 picks better than the
    # start (the margin makes a heavy part's slip more sensitive to small changes of
    # the contact: benchmarks/results/history.md, "A contact margin on the pads")
    solver = mp.SolverParams()
    contact = mp.ContactParams(pad_collision="mean_radius", pad_margin_mm=0.0)
    mp.evaluate(
        heavy,
        LIGHT,
        n=24,
        grasp=PROC,
        contact=contact,
        solver=solver,
        backend="mujoco",
        out=out,
        n_traces=0,
    )
    return out


@pytest.fixture(scope="module")
def planned(tmp_path_factory, run_dir, heavy):
    out = tmp_path_factory.mktemp("trials") / "plan"
    plan = T.plan(
        run_dir,
        heavy,
        out,
        n=N,
        repeats=REPEATS,
        draws=4,
        placements=2,
        pool=12,
        backend="mujoco",
    )
    return out, plan


def _copy(planned, tmp_path, name="t"):
    dst = tmp_path / name
    shutil.copytree(planned[0], dst)
    return dst


def _rows(folder):
    with (folder / "trials.csv").open(newline="") as fh:
        return list(csv.DictReader(fh))


def _write(folder, rows, header=None):
    header = header or list(rows[0])
    CT.write_sheet(folder / "trials.csv", header, rows)


def test_information_and_choice_on_known_draws():
    # BALD: draws that all agree teach nothing; sure draws that disagree teach 1 bit;
    # a pick-point every draw gives 50 % (placement noise) teaches nothing either
    p_draws = np.array([[1.0, 0.0, 0.5], [1.0, 1.0, 0.5]])
    bits = CT.entropy_bits(p_draws.mean(0)) - CT.entropy_bits(p_draws).mean(0)
    assert bits == pytest.approx([0.0, 1.0, 0.0])
    assert CT.entropy_bits([0.0, 1.0, 0.5]) == pytest.approx([0.0, 0.0, 1.0])

    def row(x, success, score, bits, p=0.0):
        pose = {"x_mm": x, "y_mm": 0.0, "yaw_deg": 0.0}
        sim = {"success": success, "score": score, "failure": "none", "p_nominal": p}
        return pose | sim | {"bits": bits, "p_lo": 0.0, "p_hi": 1.0}

    rows = [
        row(0.0, False, 0.2, 1.0),
        row(1.0, False, 0.2, 0.9),  # the same template as row 0 (1 mm away)
        row(10.0, True, 0.9, 0.5),
        row(20.0, True, 0.95, 0.0),
        row(30.0, False, 0.1, 0.0),
        row(40.0, True, 0.5, 0.0, p=0.5),
    ]
    chosen, why = CT.choose(rows, 4, info_share=0.5)
    # two by information (row 1 skipped: same template), then the best predicted success
    # and the worst predicted failure, as the paper chose
    assert chosen == [0, 2, 3, 4]
    assert why[0].startswith("informative: 1.00 bits") and why[2].startswith("check: predicted s")
    assert "worst" in why[3]
    # no share by information: the paper's best and worst, alternately, the successes
    # going on once the failures run out; more than there are distinct templates: fewer
    chosen, why = CT.choose(rows, 6, info_share=0.0)
    assert chosen == [3, 4, 2, 0, 5]
    assert all(w.startswith("check: ") for w in why)


def test_agreement_counts_interval_baseline_and_notes():
    predicted = [1, 1, 0, 0, 1]
    trials = [5, 5, 5, 5, 2]
    successes = [5, 0, 0, 3, 1]  # real: success, failure, failure, success, split (success)
    a = CT.agreement(predicted, trials, successes)
    assert a["confusion"] == {
        "sim_success_real_success": 2,
        "sim_success_real_failure": 1,
        "sim_failure_real_success": 1,
        "sim_failure_real_failure": 1,
    }
    assert (a["correct"], a["pick_points"], a["trials"]) == (3, 5, 22)
    assert a["accuracy_ci"] == pytest.approx(wilson_interval(3, 5))
    assert a["sensitivity"]["value"] == pytest.approx(2 / 3)
    assert a["specificity"]["value"] == pytest.approx(1 / 2)
    assert a["trials_agreeing"] == 5 + 0 + 5 + 2 + 1
    assert a["baseline"] == {"predict": "success", "correct": 3, "accuracy": 0.6}
    notes = " | ".join(a["notes"])
    assert "wide" in notes and "no better than predicting 'success'" in notes
    assert "exactly half their trials" in notes
    assert [r["agrees"] for r in a["rows"]] == [True, False, True, False, True]
    assert a["rows"][1]["real_ci"] == pytest.approx(wilson_interval(0, 5), abs=1e-4)
    # a model that is right where the baseline is not says so by beating it
    b = CT.agreement([1, 0, 0, 0], [5] * 4, [4, 0, 1, 0])
    assert b["correct"] == 4 and not any("no better" in n for n in b["notes"])
    assert any("every tried" not in n for n in b["notes"])


def test_plan_writes_the_sheet_templates_and_a_mix(planned, run_dir):
    from pypdf import PdfReader

    folder, plan = planned
    rnd = plan["rounds"][0]
    picks = rnd["picks"]
    assert len(picks) == N and [p["page"] for p in picks] == list(range(1, N + 1))
    # the sheet: the calibration columns, every successes cell blank, trials prefilled
    rows = _rows(folder)
    assert list(rows[0]) == list(CT.SHEET_COLUMNS)
    assert [int(r["pick_id"]) for r in rows] == [p["pick_id"] for p in picks]
    assert all(r["successes"] == "" and r["trials"] == str(REPEATS) for r in rows)
    # one printed 1:1 page per pick-point
    assert len(PdfReader(folder / "templates_round1.pdf").pages) == N
    # round 1's predictions are the run's own results
    import pyarrow.parquet as pq

    table = pq.read_table(run_dir / "results.parquet").to_pylist()
    by_id = {r["pick_id"]: r for r in table}
    for p in picks:
        assert p["sim_success"] == by_id[p["pick_id"]]["success"]
        assert p["sim_failure"] == by_id[p["pick_id"]]["failure"]
    # both kinds of prediction, the informative ones first and their bits as defined
    assert {p["sim_success"] for p in picks} == {True, False}
    info = [p for p in picks if p["why"].startswith("informative")]
    assert info and picks[: len(info)] == info
    for p in picks:
        d = np.asarray(p["p_draws"])
        want = CT.entropy_bits(d.mean()) - CT.entropy_bits(d).mean()
        assert p["info_bits"] == pytest.approx(want, abs=1e-3)
    bits = [p["info_bits"] for p in info]
    assert bits == sorted(bits, reverse=True) and min(bits) >= CT.MIN_BITS
    assert all(np.ptp(p["p_draws"]) > 0 for p in info)  # the draws disagree there
    # no candidate left out teaches more than the least informative one chosen, unless
    # it is the same template as one chosen (none is here: all are apart)
    chosen = {p["pick_id"] for p in picks}
    others = [c["bits"] for c in rnd["candidates_info"] if c["pick_id"] not in chosen]
    assert len(rnd["candidates_info"]) == 12
    assert max(others, default=0.0) <= min(bits) + 1e-9
    run = json.loads((folder / "run.json").read_text())
    assert run["command"] == "trials" and run["status"] == "complete"
    assert run["timing"]["simulations"] == rnd["simulations"] > 0


def test_bad_inputs_are_refused_before_simulating(planned, run_dir, heavy, tmp_path):
    folder = _copy(planned, tmp_path)
    with pytest.raises(mp.ConfigError, match="no trial recorded yet"):
        T.agree(folder)
    rows = _rows(folder)
    rows[0]["successes"] = "1"
    _write(folder, rows)
    with pytest.raises(mp.ConfigError, match=r"row\(s\) 3, 4, .* have no successes yet.*--partial"):
        T.agree(folder)
    assert T.agree(folder, partial=True)["overall"]["pick_points"] == 1
    rows[1]["successes"] = "3"  # of 2 trials
    _write(folder, rows)
    with pytest.raises(mp.ConfigError, match=r"row 3, column successes: 3 must be.*0..trials"):
        T.agree(folder, partial=True)
    rows[1]["successes"] = ""
    moved = [dict(r) for r in rows]
    moved[2]["x_mm"] = str(float(moved[2]["x_mm"]) + 3.0)
    _write(folder, moved)
    with pytest.raises(
        mp.ConfigError, match=r"row 4 \(pick_id \d+\), column x_mm: .* not the plan"
    ):
        T.agree(folder, partial=True)
    foreign = [dict(r) for r in rows]
    foreign[3]["pick_id"] = "99999"
    _write(folder, foreign)
    with pytest.raises(mp.ConfigError, match="pick_id 99999 is not planned in this folder"):
        T.agree(folder, partial=True)
    _write(folder, [{k: v for k, v in r.items() if k != "successes"} for r in rows])
    with pytest.raises(mp.ConfigError, match=r"missing column\(s\) successes"):
        T.agree(folder, partial=True)
    _write(folder, [r | {"notes": "x"} for r in rows])
    with pytest.raises(mp.ConfigError, match=r"unknown column\(s\) notes"):
        T.agree(folder, partial=True)
    _write(folder, rows)
    # another object (the same block at another mass), another folder kind, a run's folder
    light_block = mp.load_asset("block", mass_g=500)
    with pytest.raises(mp.ConfigError, match="differ in mass_g"):
        T.fit(folder, light_block, partial=True, backend="mujoco")
    with pytest.raises(mp.ConfigError, match="differ in mass_g"):
        T.plan(run_dir, light_block, tmp_path / "p2", backend="mujoco")
    with pytest.raises(mp.ConfigError, match="holds the results of `mjx-pick trials`"):
        T.plan(folder, heavy, tmp_path / "p3", backend="mujoco")
    with pytest.raises(mp.ConfigError, match="holds the results of `mjx-pick evaluate`"):
        T.plan(run_dir, heavy, run_dir, backend="mujoco")
    with pytest.raises(mp.ConfigError, match="is not a trials folder"):
        T.agree(run_dir)
    with pytest.raises(mp.ConfigError, match="--paper 'a3' is not allowed"):
        T.plan(run_dir, heavy, tmp_path / "p4", paper="a3")
    with pytest.raises(mp.ConfigError, match="pool = 4 is out of range"):
        T.plan(run_dir, heavy, tmp_path / "p5", n=8, pool=4)
    for p in ("p2", "p3", "p4", "p5"):  # nothing was simulated nor claimed
        assert not (tmp_path / p / "trials.json").exists()


def test_record_asks_blind_and_writes_each_answer(planned, tmp_path):
    folder = _copy(planned, tmp_path)
    prompts, said = [], []
    answers = iter(["x", "2", "", "1/3", "5", "0", "q"])

    def ask(prompt):
        prompts.append(prompt)
        return next(answers)

    done = T.record(folder, ask, said.append)
    # "x" and "5" (of 2 trials) are refused and asked again; Enter skips; q stops
    assert done == {"filled": 3, "skipped": 1, "left": N - 3}
    assert len(said) == 2 and "0..2" in said[1]
    rows = _rows(folder)
    assert [(r["successes"], r["trials"]) for r in rows[:4]] == [
        ("2", "2"),
        ("", "2"),
        ("1", "3"),
        ("0", "2"),
    ]
    assert "page 1" in prompts[0] and f"of {REPEATS} trials" in prompts[0]
    for prompt in prompts:  # the prediction is never shown to the person at the robot
        assert "success" not in prompt.replace("successes", "") and "sim" not in prompt


def test_the_loop_on_synthetic_outcomes_of_a_hidden_friction(planned, heavy, tmp_path):
    folder = _copy(planned, tmp_path)
    # the "real" cell: pad friction 0.70, every trial at the template pose
    filled = T.synthetic_trials(
        folder, heavy, {"pad_friction": HIDDEN}, jitter_mm=0, jitter_deg=0, backend="mujoco"
    )
    assert filled == N
    res = T.agree(folder)
    a = res["overall"]
    assert sum(a["confusion"].values()) == N and a["trials"] == N * REPEATS
    assert (folder / "agreement.md").is_file()
    assert json.loads((folder / "agreement.json").read_text())["overall"]["correct"] == a["correct"]
    # the tried rows, in the calibrate format: they feed `mjx-pick calibrate` directly
    outcomes = cal.read_outcomes(folder / "outcomes.csv")
    assert len(outcomes) == N and outcomes.trials.sum() == N * REPEATS

    fit = T.fit(folder, heavy, steps=6, popsize=4, next_n=3, backend="mujoco")
    before, after = fit.before, fit.after
    # re-simulated at the run's parameters, the tried rows agree as planned
    assert before["correct"] == a["correct"] and fit.rerun_differs == 0
    assert before["correct"] < N, "the hidden friction must make the run wrong somewhere"
    # the fit: never worse; where the data pin the friction it is used, else its optimum
    # is reported (and must explain the outcomes better than the start)
    assert after["correct"] >= before["correct"]
    best = fit.report["at_optimum"] or after
    assert best["correct"] > before["correct"]
    mu = fit.result.optimum["pad_friction"]
    assert abs(mu - HIDDEN) < abs(0.86 - HIDDEN)
    written = json.loads((fit.out_dir / "agreement.json").read_text())
    assert written["after"]["correct"] == after["correct"]
    assert (fit.out_dir / "contact.toml").is_file() and (fit.out_dir / "agreement.md").is_file()
    assert any(note.startswith("in-sample") for note in fit.notes)
    # the next round: appended untried to the sheet, with its templates; its draws come
    # from where the fit left doubt, narrower than the prior's round 1 drew from
    rnd = fit.next_round
    assert rnd["round"] == 2 and len(rnd["picks"]) == 3
    assert rnd["planned_with"]["source"] == "the fit of fit-round1"
    rows = _rows(folder)
    assert [r["round"] for r in rows] == ["1"] * N + ["2"] * 3
    assert all(r["successes"] == "" for r in rows[N:])
    tried_ids = {int(r["pick_id"]) for r in rows[:N]}
    assert not tried_ids & {p["pick_id"] for p in rnd["picks"]}
    from pypdf import PdfReader

    assert len(PdfReader(folder / "templates_round2.pdf").pages) == 3
    first = np.ptp(planned[1]["rounds"][0]["draws"])
    assert np.ptp(rnd["draws"]) < first
    # round 2 untried: agreement of round 1 only, with --partial; a second fit of the
    # same round is refused unless asked to replace it
    again = T.agree(folder, partial=True)
    assert list(again["by_round"]) == ["1"] and len(again["untried_rows"]) == 3
    with pytest.raises(mp.ConfigError, match="holds an earlier fit of round 1.*--overwrite"):
        T.fit(folder, heavy, partial=True, backend="mujoco")
    # round 2 tried: its agreement is the fit's prediction made before its trials (the
    # honest test), reported apart; the next fit takes every tried row, round 1's too
    assert (
        T.synthetic_trials(
            folder, heavy, {"pad_friction": HIDDEN}, jitter_mm=0, jitter_deg=0, backend="mujoco"
        )
        == 3
    )
    both = T.agree(folder)
    assert list(both["by_round"]) == ["1", "2"]
    assert both["by_round"]["2"]["planned_with"] == "the fit of fit-round1"
    assert both["by_round"]["2"]["pick_points"] == 3 and both["overall"]["pick_points"] == N + 3
    second = T.fit(folder, heavy, steps=1, popsize=4, identify=False, next_n=0, backend="mujoco")
    assert second.out_dir.name == "fit-round2" and second.report["rows"] == N + 3
    assert second.next_round is None and len(_rows(folder)) == N + 3


def test_cli_trials(planned, run_dir, tmp_path, capsys, monkeypatch):
    folder = _copy(planned, tmp_path)
    rows = _rows(folder)
    for r, k in zip(rows, [2, 0, 1, 0, 2, 0, 0, 0], strict=True):
        r["successes"] = str(k)
    _write(folder, rows)
    assert main(["trials", "agree", str(folder)]) == 0
    out = capsys.readouterr().out
    assert "pick-points agree" in out and "simulated success" in out and "agreement.md" in out
    # record needs a terminal
    import io

    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    assert main(["trials", "record", str(folder)]) == 2
    assert "stdin is not one" in capsys.readouterr().err
    # a plan from the command line, checked and written (the object given as on evaluate)
    obj = ["block", "--mass-g", "1000"]
    out_dir = tmp_path / "cli-plan"
    args = ["trials", "plan", str(run_dir), *obj, "--n", "2", "--pool", "2", "--draws", "2"]
    args += ["--placements", "1", "--backend", "mujoco", "--blind", "--out", str(out_dir)]
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "templates_round1.pdf" in out and "trials record" in out
    with (out_dir / "trials.csv").open(newline="") as fh:
        header = next(csv.reader(fh))
    assert "sim_success" not in header and "successes" in header  # blind
    assert main(["trials", "fit", str(folder), "block", "--backend", "mujoco"]) == 2
    assert "differ in mass_g" in capsys.readouterr().err
