"""Labels against physical trials: validate at the default physics, and calibrate on a
split of the grasps with the held-out rest validated before and after.

Reads TRIALS.csv files where they lie (the public cube trials: ../shared/data, never
copied into the project) and writes one JSON per file to benchmarks/results/:

    python benchmarks/physical_trials.py --trials ../shared/data/ipc_graspsim_cube/trials.csv \
        --params pad_friction,pad_stiffness_n_per_mm --steps 40 --splits 0,1,2

Per grasp it also records what decides a disagreement: the real successes of its
repeats, the simulated label and outcome, the share of the pads' face that meets the
part (``GraspChecker``'s coverage) and the approach's tilt.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import time
import warnings
from pathlib import Path

import numpy as np

from mjx_pick.core.grasp_checks import GraspChecker
from mjx_pick.studies import calibration as cal
from mjx_pick.studies.options import RunOptions
from mjx_pick.studies.validation import (
    _prepare,
    read_trials,
    split_by_grasp,
    trial_outcomes,
    validate,
)

OUT = Path(__file__).resolve().parent / "results"


def per_grasp(trials, table) -> list[dict]:
    """Each grasp's real successes, its simulated label and the pads' coverage."""
    table = {
        "line": np.asarray(table["line"]),
        "sim_success": np.asarray(table["sim_success"]),
        "sim_outcome": np.asarray(table["sim_outcome"].to_pylist(), object),
    }
    scenes = _prepare(trials, np.arange(len(trials)), None, None, None, (), "m")
    rows, offset = [], 0
    for sc in scenes:
        res = GraspChecker(sc.scene)(sc.centres)
        for g in range(len(sc.centres)):
            members = sc.trials[sc.grasp_of == g]
            sim = table["sim_success"][np.isin(table["line"], trials.line[members])]
            outcome = table["sim_outcome"][np.isin(table["line"], trials.line[members])]
            rows.append(
                {
                    "grasp": offset + g,
                    "trials": int(len(members)),
                    "real_successes": int(trials.success[members].sum()),
                    "sim_success": bool(sim[0]),
                    "sim_outcome": str(outcome[0]),
                    "coverage": float(res["coverage"][g]),
                    "centre_height_mm": float(sc.centres[g, 2, 3] * 1e3),
                }
            )
        offset += len(sc.centres)
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--trials", nargs="+", required=True, help="TRIALS.csv files")
    ap.add_argument("--backend", default="mujoco")
    ap.add_argument("--params", default="pad_friction", help="calibrate's --params")
    ap.add_argument("--steps", type=int, default=40, help="calibrate's CMA-ES steps")
    ap.add_argument("--splits", default="0", help="split seeds (comma-separated)")
    args = ap.parse_args()
    warnings.simplefilter("ignore")
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    for path in args.trials:
        trials = read_trials(path)
        t0 = time.perf_counter()
        v = validate(trials, RunOptions(backend=args.backend))
        doc = {
            "trials_file": str(path),
            "commit": commit,
            "date": time.strftime("%Y-%m-%d"),
            "backend": args.backend,
            "default": {k: v.report[k] for k in v.report if k != "settings"},
            "default_wall_s": round(time.perf_counter() - t0, 1),
            "per_grasp": per_grasp(trials, v.table),
            "splits": [],
        }
        names = cal.canonical_params(args.params.split(","))
        for seed in (int(s) for s in args.splits.split(",")):
            train, test = split_by_grasp(trials, 0.5, seed)
            obj, settings, outcomes = trial_outcomes(trials, train)
            problem = cal.Problem(obj, outcomes, names, settings, backend=args.backend)
            t1 = time.perf_counter()
            fit = cal.calibrate(problem, RunOptions(seed=seed), steps=args.steps)
            before = validate(trials, RunOptions(backend=args.backend), subset=test).report
            after = validate(
                trials, RunOptions(backend=args.backend), subset=test, contact=fit.contact
            ).report
            doc["splits"].append(
                {
                    "seed": seed,
                    "train_grasps": int(len(np.unique(trials.grasp_index()[train]))),
                    "test_grasps": int(len(np.unique(trials.grasp_index()[test]))),
                    "fitted": fit.values,
                    "optimum": fit.optimum,
                    "not_identified": list(fit.not_identified),
                    "before": {k: before[k] for k in ("n", "accuracy", "f1", "confusion")},
                    "after": {k: after[k] for k in ("n", "accuracy", "f1", "confusion")},
                    "wall_s": round(time.perf_counter() - t1, 1),
                }
            )
        name = Path(path).parent.name or Path(path).stem
        out = OUT / f"physical_trials_{name}.json"
        out.write_text(json.dumps(doc, indent=1, default=float))
        d = doc["default"]
        print(
            f"{path}: n {d['n']}, accuracy {d['accuracy']['value']:.3f}, F1 "
            f"{d['f1']['value']:.3f} {d['f1']['ci95']}; splits: "
            + "; ".join(
                f"seed {s['seed']}: F1 {s['before']['f1']['value']:.3f} -> "
                f"{s['after']['f1']['value']:.3f} ({s['fitted']})"
                for s in doc["splits"]
            )
        )
        print(f"wrote {out}")


if __name__ == "__main__":
    main()
