"""Which labels two simulations agree on, by how each label was decided.

Reads the per-part results tables that ``real_objects.py --tables DIR`` writes
(``{part}_{backend}.parquet``) for two sides -- two engines, or one engine at two time
steps -- and reports, per part, label agreement on all pick-points and on those flagged
as not decided by a hair:

* ``stable``: the label a 1 um move of the part leaves as it is (``label_stable``);
* ``converged``: the label half the time step leaves as it is (``label_converged``);
* ``sure``: both; ``clear``: |label_margin| >= --band (no margin counts as clear);

each on side A's flags, on side B's, and on both. With --flags FOLDER:BACKEND the rows are
selected by a third run's flags instead (``ref``): two Warp runs compared on the labels
MuJoCo C marks stable measure Warp's own run-to-run spread on the set that Warp against C
is judged on. The pick-points of both sides are
written to --save-picks (a gzipped CSV), from which the figures can be read again
without the tables (``--picks FILE``).

    python benchmarks/label_trust.py --a OUT/margin_tables:mujoco --b OUT/margin_tables:warp
    python benchmarks/label_trust.py --picks benchmarks/results/label_trust_picks_h100_1024.csv.gz
    python benchmarks/label_trust.py --a dt1:mujoco --b dt05:mujoco   # the time step itself
    python benchmarks/label_trust.py --a runA:warp --b runB:warp --flags runA:mujoco
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from mjx_pick.core.config import write_json

KEEP = ("pick_id", "success", "failure", "label_margin", "label_stable", "label_converged")


def read_side(spec: str) -> pd.DataFrame:
    """FOLDER:BACKEND -> every part's rows (KEEP columns that exist, plus "part")."""
    folder, backend = spec.rsplit(":", 1)
    frames = []
    for path in sorted(Path(folder).glob(f"*_{backend}.parquet")):
        t = pd.read_parquet(path)
        t = t[[c for c in KEEP if c in t.columns]].copy()
        t.insert(0, "part", path.name[: -len(f"_{backend}.parquet")])
        frames.append(t)
    if not frames:
        raise SystemExit(f"{spec}: no *_{backend}.parquet in {folder}")
    return pd.concat(frames, ignore_index=True)


def flags(side: pd.DataFrame, band: float) -> dict[str, np.ndarray]:
    """Each criterion's (n,) bool of one side's rows (missing flags: not computed)."""
    out = {"all": np.ones(len(side), bool)}
    if "label_stable" in side:
        out["stable"] = side["label_stable"].to_numpy(bool)
    if "label_converged" in side:
        out["converged"] = side["label_converged"].to_numpy(bool)
    if "stable" in out and "converged" in out:
        out["sure"] = out["stable"] & out["converged"]
    margin = np.abs(side["label_margin"].to_numpy(float))
    out[f"clear{band:g}"] = ~(margin < band)
    return out


def agreement(
    a: pd.DataFrame, b: pd.DataFrame, band: float, ref: pd.DataFrame | None = None
) -> dict:
    """Per part and criterion: share of equal labels, rows, and rows that differ.

    With ``ref`` (a third side on the same pick-points) the criteria are also taken on
    its flags ("_ref"): the rows a third run marks stable, converged, clear.
    """
    rows = {}
    for part in a["part"].unique():
        pa_, pb = a[a["part"] == part], b[b["part"] == part]
        pr = None if ref is None else ref[ref["part"] == part]
        for other in (pb,) if pr is None else (pb, pr):
            if not np.array_equal(pa_["pick_id"].to_numpy(), other["pick_id"].to_numpy()):
                raise SystemExit(f"{part}: the sides hold different pick-points")
        same = pa_["success"].to_numpy(bool) == pb["success"].to_numpy(bool)
        fa, fb = flags(pa_, band), flags(pb, band)
        fr = {} if pr is None else flags(pr, band)
        row = {}
        # a criterion only the third run computed (two Warp runs without the stability
        # copies, C's flags) is taken on its flags alone
        for what in [*fa, *(w for w in fr if w not in fa)]:
            masks = {"A": fa[what]} if what in fa else {}
            if what != "all" and what in fa and what in fb:
                masks |= {"B": fb[what], "both": fa[what] & fb[what]}
            if what != "all" and what in fr:
                masks["ref"] = fr[what]
            for side, mask in masks.items():
                key = what if what == "all" else f"{what}_{side}"
                n = int(mask.sum())
                row[key] = {
                    "agree": round(float(same[mask].mean()), 4) if n else None,
                    "n": n,
                    "differ": int((~same[mask]).sum()),
                }
        rows[str(part)] = row
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", help="side A: FOLDER:BACKEND (real_objects --tables)")
    ap.add_argument("--b", help="side B: FOLDER:BACKEND")
    ap.add_argument("--flags", help="a third run, FOLDER:BACKEND, whose flags select rows too")
    ap.add_argument("--picks", help="instead of --a/--b: a CSV written by --save-picks")
    ap.add_argument("--band", type=float, default=0.1, help="clear: |label_margin| >= band")
    ap.add_argument("--save-picks", default="", help="write both sides' rows here (.csv.gz)")
    ap.add_argument("--out", default="", help="JSON file for the figures")
    args = ap.parse_args()
    if args.picks:
        both = pd.read_csv(args.picks)
        a = both[both["side"] == "A"].drop(columns="side").reset_index(drop=True)
        b = both[both["side"] == "B"].drop(columns="side").reset_index(drop=True)
    elif args.a and args.b:
        a, b = read_side(args.a), read_side(args.b)
    else:
        raise SystemExit("give --a and --b, or --picks")
    if args.save_picks:
        pd.concat([a.assign(side="A"), b.assign(side="B")]).to_csv(args.save_picks, index=False)
    rows = agreement(a, b, args.band, read_side(args.flags) if args.flags else None)
    for part, row in rows.items():
        cells = "  ".join(
            f"{k} {v['agree']:.4f} ({v['differ']}/{v['n']})"
            for k, v in row.items()
            if v["agree"] is not None
        )
        print(f"{part:22s} {cells}")
    if args.out:
        write_json(args.out, {"args": vars(args), "rows": rows})


if __name__ == "__main__":
    main()
