"""Real-object benchmark (issue 16): the shipped YCB meshes grasped by a Robotiq 2F-85.

Per object: success rate with its Wilson 95 % interval, failure reasons, and (with
--backends) the labels of MuJoCo C against another backend on the same pick-points.
Light rigid parts grasped across by a 2F-85 at 50 N must mostly succeed; every failure
class that remains must be explained physically (benchmarks/results/history.md, "Pad
contact and real objects (issue 16)"); the current figures are in benchmarks/RESULTS.md.

    python benchmarks/real_objects.py --n 48 --out benchmarks/results/real_objects.json
    python benchmarks/real_objects.py --n 256 --backends mujoco,warp   # on a GPU machine
    python benchmarks/real_objects.py --n 32 --pictures benchmarks/out/real_objects
    python benchmarks/real_objects.py --n 512 --backends mujoco,warp --stability-um 1 \
        --objects door_opener,011_banana        # agreement on stable labels, GPU machine

--objects takes the YCB manifest's names and the shipped photo part ``door_opener``.
With --stability-um, every backend simulates each pick-point again with the object moved
that far (evaluate's ``label_stable``), and agreement is also reported on the pick-points
whose label is stable on the reference backend (the first) and on both.

With --certain-m M, every backend also runs `robustness` on the same pick-points (M
placements each, the object moved by N(0, --certain-xy-mm) in x and y and N(0,
--certain-yaw-deg) in yaw, as a robot's placement error moves it), and agreement is
reported on the labels that all M placements reproduce: a label that a placement
within the robot's precision flips is a coin toss, whichever engine computes it.

Agreement is also reported on the labels that are not decided by a hair on the
reference backend (and on both): |label_margin| >= each of --margin-bands (a label with
no margin -- never reached its force, diverged -- counts as clear). --tables DIR writes
each backend's results table per object (parquet), for per-pick comparison. With
--step-check, every backend also simulates each pick-point at half the time step
(evaluate's ``label_converged``), and agreement is reported on the converged labels.

--no-multiccd turns MuJoCo's multi-contact convex collision off in every scene (the
``multiccd`` disable flag, honoured by MuJoCo C and MuJoCo Warp alike): one contact per
pad and object piece, where each engine otherwise clips its own set of up to four.
A diagnostic of where the engines differ, not a setting to simulate with (a part
held at one point per pad turns in the grip).

With --pictures, one PNG per (object, failure class): the first pick-point of that
class re-simulated on MuJoCo C with its trace -- the pick in the gripper frame, the pad
forces, the object's lift against the gripper's (slip), and its rotation.
"""

from __future__ import annotations

import argparse
import collections
import contextlib
import re
import time
import tomllib
from importlib import resources
from pathlib import Path

import numpy as np

import mjx_pick as mp
from mjx_pick.core.config import load_toml, write_json
from mjx_pick.core.metrics import wilson_interval
from mjx_pick.kernels import grasp as gk


def without_multiccd(xml: str) -> str:
    """A scene's MJCF text with MuJoCo's ``multiccd`` disable flag set in its
    ``<option>`` element (one contact per convex pair, on MuJoCo C and Warp alike)."""
    xml, n = re.subn(r"(<option [^>]*?)/>", r'\1><flag multiccd="disable"/></option>', xml, count=1)
    assert n == 1, "scene_xml's <option> element changed"
    return xml


def pad_visual_size(xml: str) -> str:
    """A parametric jaw's pad as built (``pad_left_visual``): its box's MJCF ``size``
    attribute, the half-sizes "x y z" in m (x across the pad, towards the part)."""
    size = re.search(r'<geom name="pad_left_visual" type="box" size="([^"]+)"', xml)
    assert size, "scene_xml's parametric pad changed (or an MJCF gripper: not supported)"
    return size[1]


def with_sphere_pads(xml: str, ny: int, nz: int, radius_m: float) -> str:
    """A parametric jaw's scene with each pad's collision box and rim replaced by a
    ny x nz grid of spheres over the whole pad face (a candidate, not the library's):
    each sphere touches a part at one point wherever the collider is MuJoCo C's or
    Warp's, so the points a pad holds a part with are the model's, not the collider's.

    The spheres sit at the centres of ny x nz equal cells of the face; each one's crown
    is in the face's plane (radius_m behind it: between two spheres the face dips
    spacing^2 / (8 radius_m)). Pairs: condim 3, the pad pairs' friction, solref, solimp.
    """
    hx, hy, hz = (float(v) for v in pad_visual_size(xml).split())
    centres = [
        (-hy + (2 * j + 1) * hy / ny, -hz + (2 * k + 1) * hz / nz)
        for j in range(ny)
        for k in range(nz)
    ]
    for side, face in (("left", hx), ("right", -hx)):  # the face toward the part
        x = face - np.sign(face) * radius_m
        spheres = "\n".join(
            f'        <geom name="pad_{side}_s{i}" type="sphere" size="{radius_m:.9g}" '
            f'pos="{x:.9g} {y:.9g} {z:.9g}" mass="0" group="3"/>'
            for i, (y, z) in enumerate(centres)
        )
        xml, n = re.subn(rf'        <geom name="pad_{side}(_rim)?" type="box"[^>]*/>\n', "", xml)
        assert n >= 1, f"pad_{side}'s collision box not found"
        xml = xml.replace(
            f'<geom name="pad_{side}_visual"', spheres + f'\n        <geom name="pad_{side}_visual"'
        )
    pair = re.compile(
        r'    <pair name="(pad_left|pad_right)(_rim)?_piece(\d+)" geom1="\S+" (.*?)/>\n'
    )

    def per_sphere(m):
        if m[2]:  # the rim's pair: gone with the rim
            return ""
        rest = m[4].replace('condim="4"', 'condim="3"')
        return "".join(
            f'    <pair name="{m[1]}_s{i}_piece{m[3]}" geom1="{m[1]}_s{i}" {rest}/>\n'
            for i in range(len(centres))
        )

    xml, n = pair.subn(per_sphere, xml)
    assert n >= 2, "scene_xml's pad pairs changed"
    return xml


@contextlib.contextmanager
def rewriting_scenes(rewrite=None):
    """Every scene built inside is rewrite(its MJCF text); None: scenes as they are."""
    if rewrite is None:
        yield
        return
    from unittest import mock

    from mjx_pick.core import scene as scene_mod

    original = scene_mod.scene_xml
    with mock.patch.object(scene_mod, "scene_xml", lambda *a, **k: rewrite(original(*a, **k))):
        yield


def multiccd_off(off: bool = True):
    """Every scene built inside has multi-contact off (:func:`without_multiccd`);
    off=False: scenes as they are."""
    return rewriting_scenes(without_multiccd if off else None)


def sphere_grid(spec: str) -> tuple[int, int, float]:
    """ "NYxNZ:RADIUS_MM" (e.g. "4x6:20"; radius 20 mm if left out) as (ny, nz, radius
    in m); argparse.ArgumentTypeError naming what is allowed otherwise."""
    grid, _, radius = spec.partition(":")
    try:
        ny, nz = (int(v) for v in grid.split("x"))
        r_mm = float(radius or 20.0)
    except ValueError:
        ny = nz = r_mm = 0
    if not (1 <= ny <= 64 and 1 <= nz <= 64 and 0.5 <= r_mm <= 500):
        raise argparse.ArgumentTypeError(
            f"--sphere-pads = {spec!r}: allowed NYxNZ:RADIUS_MM, 1 <= NY, NZ <= 64 and "
            "0.5 <= RADIUS_MM <= 500 (e.g. 4x6:20)"
        )
    return ny, nz, r_mm * 1e-3


def sphere_pads(grid: tuple[int, int, float] | None):
    """Every scene built inside has sphere pads (:func:`with_sphere_pads`) by grid
    (ny, nz, radius m; :func:`sphere_grid`); None: scenes as they are."""
    if grid is None:
        return rewriting_scenes(None)
    return rewriting_scenes(lambda xml: with_sphere_pads(xml, *grid))


def ycb_manifest() -> dict:
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    return tomllib.loads((folder / "manifest.toml").read_text())


def load_ycb(name: str) -> mp.ObjectModel:
    """A shipped YCB part by its manifest name, with its published mass (or the shipped
    door opener, the paper's part, by its asset name)."""
    if name == "door_opener":
        return mp.load_asset(name)
    entry = ycb_manifest()[name]
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    with resources.as_file(folder / entry["file"]) as path:
        return mp.load_object(path, unit=entry["unit"], mass_g=entry["mass_g"])


def failure_picture(obj, table, failure: str, grasp, path: Path, gripper: str) -> None:
    """Re-simulate the first pick of a failure class with its trace and draw why."""
    from mjx_pick.core import pickpoints as pp
    from mjx_pick.engine.inputs import make_inputs
    from mjx_pick.engine.runner import Runner
    from mjx_pick.outputs.plots import new_figure, pick_on_axes, save_png

    gripper = mp.load_gripper(gripper)
    r = table[table["failure"] == failure].iloc[0]
    checker = pp.FeasibilityChecker(obj, gripper, grasp=grasp)
    picks = checker.batch(np.arange(1), [r.x_mm], [r.y_mm], [r.yaw_deg], "user")
    scene = mp.build_scene(obj, gripper, None, None, grasp)
    traces = (
        Runner("mujoco", 1)
        .simulate(scene, grasp, make_inputs(scene, grasp, picks), record=True)
        .traces
    )
    tr = {f: traces[0, :, i] for i, f in enumerate(gk.TRACE_FIELDS)}
    fig, (a0, a1, a2) = new_figure(1, 3, figsize=(15, 4.2))
    pick_on_axes(a0, obj, gripper, r.x_mm, r.y_mm, r.yaw_deg, r.opening_mm)
    t = tr["t_s"]
    a1.plot(t, tr["force_left_n"], label="left pad")
    a1.plot(t, tr["force_right_n"], label="right pad", ls="-.")
    a1.plot(t, tr["force_table_n"], label="table", color="0.5")
    a1.axhline(grasp.grip_force_n, color="k", ls="--", lw=1, label="F_d")
    a1.set_xlabel("t, s")
    a1.set_ylabel("N")
    a1.legend(fontsize=8)
    a1.set_title("forces")
    a2.plot(t, 1e3 * tr["lift_m"], label="gripper lift, mm")
    a2.plot(t, 1e3 * (tr["object_z_m"] - tr["object_z_m"][0]), label="object lift, mm")
    q = np.stack([tr["object_qw"], tr["object_qx"], tr["object_qy"], tr["object_qz"]], 1)
    turn = np.degrees(2 * np.arccos(np.clip(np.abs(q @ q[0]), 0, 1)))
    a2.plot(t, turn, label="rotation from start, deg")
    a2.set_xlabel("t, s")
    a2.legend(fontsize=8)
    a2.set_title(f"{obj.name}: {failure}")
    fig.tight_layout()
    save_png(fig, path, dpi=90)


def table_picks(obj, gripper, grasp, table, mode: str, pick_id=None):
    """The GraspBatch of a results table's rows (x_mm, y_mm, yaw_deg; pick_id: the
    table's own unless given), through the public feasibility checker."""
    from mjx_pick.core import pickpoints as pp

    checker = pp.FeasibilityChecker(obj, gripper, grasp=grasp)
    return checker.batch(
        table["pick_id"].to_numpy() if pick_id is None else pick_id,
        table["x_mm"].to_numpy(),
        table["y_mm"].to_numpy(),
        table["yaw_deg"].to_numpy(),
        mode,
    )


def placement_certain(
    obj, table, grasp, contact, solver, backend, certain, gripper: str
) -> np.ndarray:
    """(n,) bool: the pick-point's label is what every one of m placements around it
    gives (robustness with sigma_xy_mm, sigma_yaw_deg), in table's row order."""
    from mjx_pick.core.settings import Settings

    m, sigma_xy_mm, sigma_yaw_deg = certain
    gripper = mp.load_gripper(gripper)
    picks = table_picks(obj, gripper, grasp, table, "robustness")
    robust = mp.robustness(
        obj,
        picks,
        Settings(
            gripper=gripper,
            grasp=grasp,
            contact=contact or mp.ContactParams(),
            solver=solver or mp.SolverParams(),
        ),
        m=m,
        sigma_xy_mm=sigma_xy_mm,
        sigma_yaw_deg=sigma_yaw_deg,
        backend=backend,
    ).to_pandas()
    p = robust.set_index("pick_id").loc[table["pick_id"], "robust_p"].to_numpy()
    success = table["success"].to_numpy(bool)
    return np.where(success, p == 1.0, p == 0.0)


def agreement_on(what: str, same, on_ref, on_other, ids) -> dict:
    """Label agreement (same: (n,) bool) on the pick-points flagged `what` on the
    reference backend and on both, with the ids of those that differ on the reference's."""
    on_both = on_ref & on_other
    return {
        f"{what}_on_reference": float(np.mean(same[on_ref])) if on_ref.any() else None,
        f"n_{what}_on_reference": int(on_ref.sum()),
        f"{what}_on_both": float(np.mean(same[on_both])) if on_both.any() else None,
        f"n_{what}_on_both": int(on_both.sum()),
        f"differ_{what}_on_reference": [int(i) for i in ids[on_ref & ~same]],
    }


def run_object(
    name: str,
    entry: dict,
    n: int,
    seed: int,
    force_n: float,
    backends,
    pictures: str = "",
    contact=None,
    solver=None,
    stability_um: float = 0.0,
    certain: tuple[int, float, float] | None = None,
    gripper: str = "robotiq-2f85",
    margin_bands: tuple[float, ...] = (),
    tables: str = "",
    step_check: bool = False,
    grasps: str = "topdown",
) -> dict:
    """One object on each backend (the first is the reference for label agreement)."""
    t0 = time.perf_counter()
    obj = load_ycb(name)
    t_load = time.perf_counter() - t0
    grasp = mp.GraspConfig(grip_force_n=force_n)
    row = {
        "object": name,
        "gripper": gripper,
        "mass_g": round(obj.mass_kg * 1e3, 2),
        "height_mm": round(obj.height_mm, 2),
        "grasps": grasps,
    }
    labels, stable, certain_on, converged = {}, {}, {}, {}
    clear = {band: {} for band in margin_bands}
    for backend in backends:
        ev = mp.evaluate(
            obj,
            gripper,
            n=n,
            seed=seed,
            grasp=grasp,
            contact=contact,
            solver=solver,
            backend=backend,
            stability_um=stability_um,
            step_check=step_check,
            grasps=grasps,
        )
        if tables:
            from pyarrow import parquet

            Path(tables).mkdir(parents=True, exist_ok=True)
            parquet.write_table(ev.table, Path(tables) / f"{name}_{backend}.parquet")
        table = ev.table.to_pandas()
        margin = np.abs(table["label_margin"].to_numpy(float))
        for band in margin_bands:
            clear[band][backend] = ~(margin < band)  # NaN (no margin) counts as clear
        if stability_um:
            stable[backend] = table["label_stable"].to_numpy(bool)
        if step_check:
            converged[backend] = table["label_converged"].to_numpy(bool)
        k, m = int(table["success"].sum()), len(table)
        lo, hi = wilson_interval(k, m)
        labels[backend] = table["success"].to_numpy()
        if certain:
            certain_on[backend] = placement_certain(
                obj, table, grasp, contact, solver, backend, certain, gripper
            )
        if pictures and backend == "mujoco":
            for failure in sorted(set(table["failure"]) - {"none"}):
                png = Path(pictures) / f"{name}_{failure}.png"
                failure_picture(obj, table, failure, grasp, png, gripper)
        row[backend] = {
            "n": m,
            "success_rate": k / m,
            "wilson95": [round(lo, 3), round(hi, 3)],
            "failures": dict(collections.Counter(table["failure"])),
            "diverged": int(table["diverged"].sum()),
            "median_slip_mm": float(np.nanmedian(table["slip_mm"])),
            "median_phi_max_deg": float(np.nanmedian(table["phi_max_deg"])),
            "fingertip_height_mm": ev.config["scene"]["fingertip_height_mm"],
            "pad_patch_mm": ev.config["scene"]["pad_patch_mm"],
        }
    ref = backends[0]
    row["labels_agree"] = {
        b: float(np.mean(labels[ref] == labels[b])) for b in backends[1:] if b in labels
    }
    ids = table["pick_id"].to_numpy()
    both = {
        f"stable_clear{band:g}": {b: stable[b] & clear[band][b] for b in stable}
        for band in margin_bands
        if stable
    }
    for what, flags in (
        ("stable", stable),
        ("certain", certain_on),
        ("converged", converged),
        *((f"clear{band:g}", clear[band]) for band in margin_bands),
        *both.items(),
    ):
        if flags:
            row[f"{what}_share"] = {b: float(np.mean(v)) for b, v in flags.items()}
            row[f"labels_agree_{what}"] = {
                b: agreement_on(what, labels[ref] == labels[b], flags[ref], flags[b], ids)
                for b in backends[1:]
            }
    row["load_s"] = round(t_load, 1)
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=48, help="pick-points per object")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--gripper", default="robotiq-2f85", help="a preset or gripper TOML")
    ap.add_argument("--force-n", type=float, default=50.0, help="F_d, N")
    ap.add_argument("--objects", default="", help="comma-separated names (default: all)")
    ap.add_argument(
        "--backends",
        default="mujoco",
        help="comma-separated; labels of the others are compared with the first's",
    )
    ap.add_argument("--out", default="", help="JSON file for the figures")
    ap.add_argument("--pictures", default="", help="folder for one PNG per failure class")
    ap.add_argument("--contact", help="ContactParams TOML (default: the shipped defaults)")
    ap.add_argument("--solver", help="SolverParams TOML (default: the shipped defaults)")
    ap.add_argument(
        "--stability-um", type=float, default=0.0, help="label_stable's shift, um (0: off)"
    )
    ap.add_argument("--certain-m", type=int, default=0, help="placements per pick-point (0: off)")
    ap.add_argument("--certain-xy-mm", type=float, default=0.2, help="placement sigma, mm")
    ap.add_argument("--certain-yaw-deg", type=float, default=1.0, help="placement sigma, deg")
    ap.add_argument(
        "--margin-bands",
        default="0.05,0.1,0.2",
        help="agreement on labels with |label_margin| >= each (comma-separated; '' off)",
    )
    ap.add_argument("--tables", default="", help="folder for each backend's results tables")
    ap.add_argument("--step-check", action="store_true", help="label_converged (half step)")
    ap.add_argument(
        "--grasps", default="topdown", help="topdown pick-points or antipodal grasps (evaluate's)"
    )
    ap.add_argument("--no-multiccd", action="store_true", help="one contact per pair (diagnostic)")
    ap.add_argument(
        "--sphere-pads",
        type=sphere_grid,
        help="NYxNZ:RADIUS_MM: parametric pads as a grid of spheres (a candidate pad model)",
    )
    args = ap.parse_args()
    with multiccd_off(args.no_multiccd), sphere_pads(args.sphere_pads):
        run(args)


def run(args) -> None:
    """The objects of args, one after another (see the module's docstring)."""
    manifest = ycb_manifest()
    names = [s for s in args.objects.split(",") if s] or list(manifest)
    unknown = sorted(set(names) - set(manifest) - {"door_opener"})
    if unknown:
        raise SystemExit(f"--objects: unknown {unknown}; known: door_opener, {', '.join(manifest)}")
    backends = [b for b in args.backends.split(",") if b]
    from mjx_pick.engine.backend import plan_jax

    plan_jax(backends)  # before any backend: the C engine's JAX off the GPU beside Warp
    bands = tuple(float(b) for b in args.margin_bands.split(",") if b)
    rows = []
    for name in names:
        row = run_object(
            name,
            manifest.get(name, {}),
            args.n,
            args.seed,
            args.force_n,
            backends,
            args.pictures,
            load_toml(mp.ContactParams, args.contact) if args.contact else None,
            load_toml(mp.SolverParams, args.solver) if args.solver else None,
            args.stability_um,
            (args.certain_m, args.certain_xy_mm, args.certain_yaw_deg) if args.certain_m else None,
            args.gripper,
            bands,
            args.tables,
            args.step_check,
            args.grasps,
        )
        rows.append(row)
        c = row[backends[0]]
        print(
            f"{name:24s} {c['success_rate']:6.1%} [{c['wilson95'][0]:.2f}, "
            f"{c['wilson95'][1]:.2f}] {c['failures']}"
            + "".join(f" labels {b}={backends[0]} {v:.1%}" for b, v in row["labels_agree"].items())
            + "".join(
                f" stable {b}={backends[0]} {v['stable_on_reference']}"
                f" (n {v['n_stable_on_reference']})"
                for b, v in row.get("labels_agree_stable", {}).items()
            )
            + "".join(
                f" certain {b}={backends[0]} {v['certain_on_reference']}"
                f" (n {v['n_certain_on_reference']})"
                for b, v in row.get("labels_agree_certain", {}).items()
            )
            + "".join(
                f" converged {b}={backends[0]} {v['converged_on_reference']}"
                f" (n {v['n_converged_on_reference']})"
                for b, v in row.get("labels_agree_converged", {}).items()
            )
            + "".join(
                f" {key} {b}={backends[0]} {v[f'{key}_on_reference']}"
                f" (n {v[f'n_{key}_on_reference']})"
                for key in (f"clear{band:g}" for band in bands)
                for b, v in row.get(f"labels_agree_{key}", {}).items()
            ),
            flush=True,
        )
        if args.out:  # after each part: a run cut short keeps the parts it finished
            write_json(args.out, {"args": vars(args), "failure_codes": gk.FAILURES, "rows": rows})


if __name__ == "__main__":
    main()
