"""Labels held against physical trials: each trial's grasp simulated, the confusion
matrix and its figures with intervals, per object too.

Details: docs/formats.md ("Physical trials") and docs/studies.md (validate).
"""

from __future__ import annotations

import csv
import dataclasses
import io
from pathlib import Path

import numpy as np
import pyarrow as pa

from mjx_pick.core.config import ConfigError, read_text, to_dict, write_json, write_parquet
from mjx_pick.core.grasp_checks import REASON_WORDS, REASONS, GraspChecker, feasible_batch
from mjx_pick.core.grasps import decompose, pose_numbers, quat_tilt_deg, rigid_poses, rz
from mjx_pick.core.gripper import load_gripper, preset_names
from mjx_pick.core.objects import ObjectModel, object_from_mesh
from mjx_pick.core.physics import ContactParams, SolverParams
from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.settings import Settings
from mjx_pick.engine.runner import Runner
from mjx_pick.engine.simulator import Simulator
from mjx_pick.outputs.rundir import claim, config_hash, fail, finish
from mjx_pick.studies.evaluation import settings_on
from mjx_pick.studies.grasp_sources import grasp_centres, to_object_frame
from mjx_pick.studies.options import RunOptions

REQUIRED = ("object", "mass_g", "gripper", "grasp_pose", "success", "trial")
OPTIONAL = ("object_pose", "depth_mm")
# resamples of the grasps for the intervals (a cluster bootstrap: a grasp's repeats
# stay together, so that five tries of one grasp count as one grasp's evidence)
BOOTSTRAP = 2000


@dataclasses.dataclass(frozen=True)
class Trials:
    """Physical trials as a TRIALS.csv holds them, checked ((T,) arrays, T trials).

    object, gripper: the mesh path (resolved) and the gripper (a preset name or a
    resolved TOML path) of each trial; object_pose: (T, 4, 4), NaN where the file
    leaves it to the mesh's most stable pose; grasp_pose: (T, 4, 4) the gripper's base
    in the mesh's frame (E's axes, m); depth_mm: (T,) the grasp centre's distance from
    it; success: (T,) bool; trial: (T,) ids; line: (T,) each trial's line in the file.
    """

    path: Path
    object: tuple[str, ...]
    mass_g: np.ndarray
    gripper: tuple[str, ...]
    object_pose: np.ndarray
    grasp_pose: np.ndarray
    depth_mm: np.ndarray
    success: np.ndarray
    trial: tuple[str, ...]
    line: np.ndarray

    def __len__(self) -> int:
        return len(self.trial)

    def groups(self) -> dict[tuple, np.ndarray]:
        """Trials by what makes one scene: (object, mass, gripper, object pose) ->
        their indices, in the file's order."""
        out: dict[tuple, list[int]] = {}
        for i in range(len(self)):
            pose = _pose_key(self.object_pose[i])
            key = (self.object[i], float(self.mass_g[i]), self.gripper[i], pose)
            out.setdefault(key, []).append(i)
        return {k: np.asarray(v) for k, v in out.items()}

    def grasp_index(self) -> np.ndarray:
        """(T,) the index of each trial's grasp: trials of one scene whose grasp pose and
        depth agree (to a nanometre) are repeats of one grasp."""
        keys: dict[tuple, int] = {}
        out = np.zeros(len(self), np.int64)
        for i in range(len(self)):
            key = (
                self.object[i],
                float(self.mass_g[i]),
                self.gripper[i],
                _pose_key(self.object_pose[i]),
                _pose_key(self.grasp_pose[i]),
                round(float(self.depth_mm[i]), 6),
            )
            out[i] = keys.setdefault(key, len(keys))
        return out


def _pose_key(pose: np.ndarray) -> tuple | None:
    """A pose as a dictionary key, to a nanometre; None for an object pose the file
    leaves to the mesh's most stable pose (all NaN: NaN never equals NaN, and each such
    trial was once a scene and a grasp of its own, its repeats never grouped)."""
    pose = np.asarray(pose, float)
    if np.isnan(pose).all():
        return None
    return tuple(np.round(pose.ravel(), 9))


def is_trials_file(path) -> bool:
    """Whether path is a TRIALS.csv (its header names grasp_pose and success)."""
    path = Path(path)
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    with path.open(encoding="utf-8-sig", errors="replace") as fh:
        header = fh.readline()
    columns = {c.strip() for c in header.split(",")}
    return {"grasp_pose", "success"} <= columns


def read_trials(path: str | Path) -> Trials:
    """A TRIALS.csv, read and checked before any work: every error names the line and
    the column (docs/formats.md gives the columns)."""
    path = Path(path)
    text = read_text(path, "trials")  # the one reader of a user's text files
    rows = list(csv.DictReader(io.StringIO(text)))
    if not rows:
        raise ConfigError(f"trials file {path} holds no trials (a header and a row per trial)")
    missing = [c for c in REQUIRED if c not in rows[0]]
    if missing:
        raise ConfigError(
            f"trials file {path} has no column(s) {', '.join(missing)} (its columns: "
            f"{', '.join(rows[0])}); a TRIALS.csv has {', '.join(REQUIRED + OPTIONAL)}"
        )
    base = path.parent
    objects, grippers, trials = [], [], []
    mass, success, depth, lines = [], [], [], []
    obj_pose, grasp_pose = [], []
    seen: dict[str, int] = {}

    def where(line: int, column: str) -> str:
        return f"{path} line {line}, column {column}"

    for line, row in enumerate(rows, start=2):
        cell = {k: (row.get(k) or "").strip() for k in REQUIRED + OPTIONAL}
        mesh = base / cell["object"]
        if not cell["object"] or not mesh.is_file():
            raise ConfigError(
                f"{where(line, 'object')}: {cell['object']!r} is not a mesh file "
                f"(paths are relative to the CSV: {base})"
            )
        objects.append(str(mesh.resolve()))
        mass.append(_number(cell["mass_g"], where(line, "mass_g"), lo_open=0.0))
        grippers.append(_gripper(cell["gripper"], base, where(line, "gripper")))
        if cell["success"] not in ("0", "1"):
            raise ConfigError(f"{where(line, 'success')}: {cell['success']!r} is not 0 or 1")
        success.append(cell["success"] == "1")
        if not cell["trial"]:
            raise ConfigError(f"{where(line, 'trial')}: empty: every trial needs an id")
        if cell["trial"] in seen:
            raise ConfigError(
                f"{where(line, 'trial')}: {cell['trial']!r} is the id of line "
                f"{seen[cell['trial']]} too: every trial's id must differ (repeats of one "
                "grasp share its grasp_pose, not its id)"
            )
        seen[cell["trial"]] = line
        trials.append(cell["trial"])
        depth.append(
            0.0 if not cell["depth_mm"] else _number(cell["depth_mm"], where(line, "depth_mm"), 0.0)
        )
        grasp_pose.append(pose_numbers(cell["grasp_pose"], where(line, "grasp_pose")))
        obj_pose.append(
            pose_numbers(cell["object_pose"], where(line, "object_pose"))
            if cell["object_pose"]
            else [np.nan] * 16
        )
        lines.append(line)
    names = [f"line {n}" for n in lines]
    grasp_t = rigid_poses(grasp_pose, f"{path}, column grasp_pose", names)
    obj_t = np.asarray(obj_pose, float).reshape(-1, 4, 4)
    given = ~np.isnan(obj_t).any(axis=(1, 2))
    if given.any():
        obj_t[given] = rigid_poses(
            obj_t[given], f"{path}, column object_pose", [names[i] for i in np.flatnonzero(given)]
        )
    return Trials(
        path=path,
        object=tuple(objects),
        mass_g=np.asarray(mass, float),
        gripper=tuple(grippers),
        object_pose=obj_t,
        grasp_pose=grasp_t,
        depth_mm=np.asarray(depth, float),
        success=np.asarray(success, bool),
        trial=tuple(trials),
        line=np.asarray(lines),
    )


def _number(text: str, where: str, lo: float | None = None, lo_open: float | None = None):
    try:
        value = float(text)
    except ValueError:
        raise ConfigError(f"{where}: {text!r} is not a number") from None
    if (
        not np.isfinite(value)
        or (lo is not None and value < lo)
        or (lo_open is not None and value <= lo_open)
    ):
        bound = f">= {lo:g}" if lo is not None else f"> {lo_open:g}"
        raise ConfigError(f"{where}: {text!r} is not allowed: a finite number {bound}")
    return value


def _gripper(text: str, base: Path, where: str) -> str:
    if text in preset_names():
        return text
    path = base / text
    if text.endswith(".toml") and path.is_file():
        return str(path.resolve())
    raise ConfigError(
        f"{where}: {text!r} is neither a gripper preset ({', '.join(preset_names())}) nor a "
        f"gripper TOML beside the CSV ({base})"
    )


@dataclasses.dataclass
class Validation:
    """What validate produced: the figures (validation.json) and the per-trial table."""

    report: dict
    table: pa.Table
    out_dir: Path | None


def validate(
    trials: str | Path | Trials,
    options: RunOptions | None = None,
    *,
    contact: ContactParams | None = None,
    solver: SolverParams | None = None,
    grasp: GraspConfig | None = None,
    keep_grasp: tuple[str, ...] | None = None,
    unit: str = "m",
    subset: np.ndarray | None = None,
) -> Validation:
    """Simulate the grasp of every physical trial and hold the labels against the real
    outcomes (docs/formats.md, "Physical trials").

    Each scene (object, mass, gripper, object pose) is prepared once and each grasp
    simulated once (its repeats share the label); a grasp the checks reject
    (``GraspChecker``) is a predicted failure, counted by reason. Figures: accuracy,
    precision, recall and F1 over trials (a success is the positive class), each with a
    95 % interval from a bootstrap over grasps; the confusion matrix; the same per
    object; how many trials that held on the real robot the checks rejected, and why.

    Args:
      trials: a TRIALS.csv path, or Trials read from one.
      options: how it runs (backend, batch size, seed of the bootstrap, out, overwrite).
      contact, solver, grasp: the physics and procedure (None: the defaults); the
        procedure's fields other than keep_grasp (None: all of a grasp given) are
        fitted to each gripper's ranges, as evaluate does.
      unit: the meshes' length unit.
      subset: trial indices to use (a held-out split); None: all.
    """
    opts = options or RunOptions()
    t = trials if isinstance(trials, Trials) else read_trials(trials)
    index = np.arange(len(t)) if subset is None else np.asarray(subset)
    settings_doc = {
        "trials": config_hash(t.path.read_text(encoding="utf-8-sig")),
        "subset": None if subset is None else [int(i) for i in index],
        "contact": to_dict(contact or ContactParams()),
        "solver": to_dict(solver or SolverParams()),
        "grasp": to_dict(grasp) if grasp is not None else None,
        "unit": unit,
        "backend": opts.backend,
        "seed": opts.seed,
    }
    key = config_hash(settings_doc)
    out_dir = Path(opts.out) if opts.out is not None else None
    if keep_grasp is None:
        keep_grasp = () if grasp is None else tuple(f.name for f in dataclasses.fields(grasp))
    # every input checked first
    runner = Runner(opts.backend, opts.batch_size)  # one for every scene's simulator
    scenes = _prepare(t, index, contact, solver, grasp, keep_grasp, unit, runner)
    if out_dir is not None:
        claim(out_dir, "validate", key, overwrite=opts.overwrite, settings=settings_doc)
    try:
        rows = _simulate(t, index, scenes, opts)
        report = _report(t, index, rows, opts.seed)
        report["settings"] = settings_doc
        table = pa.table(rows)
        if out_dir is not None:
            write_parquet(out_dir / "trials.parquet", table)
            write_json(out_dir / "validation.json", report)
            finish(
                out_dir,
                command="validate",
                config=settings_doc,
                seed=opts.seed,
                backend=opts.backend,
            )
        return Validation(report, table, out_dir)
    except BaseException as err:
        if out_dir is not None:
            fail(out_dir, err, command="validate")
        raise


@dataclasses.dataclass
class _Scene:
    """One scene of the trials: its object, settings, simulator and compiled scene (the
    simulator's own), the grasps of its trials in the object frame and each trial's
    grasp."""

    obj: ObjectModel
    settings: Settings
    sim: Simulator
    scene: object
    centres: np.ndarray  # (G, 4, 4) the scene's grasps in the object frame
    grasp_of: np.ndarray  # (T_s,) each of its trials' grasp, 0..G-1
    trials: np.ndarray  # (T_s,) its trials' indices in the file
    source: tuple = ()  # (mesh file, mass, gripper): what a scene sharing it must have


def _prepare(t: Trials, index, contact, solver, grasp, keep, unit, runner=None) -> list[_Scene]:
    """Every scene of the trials with its grasps, checked (a mesh, a gripper, a pose
    that cannot be used is refused here, before any simulation). runner: what their
    simulators run on (None: the default backend's)."""
    runner = runner or Runner()
    out: list[_Scene] = []
    grasp_ids = t.grasp_index()
    chosen = set(int(i) for i in index)
    for (mesh, mass_g, gripper_name, _), members in t.groups().items():
        members = np.asarray([i for i in members if int(i) in chosen])
        if not len(members):
            continue
        first = int(members[0])
        pose = t.object_pose[first]
        obj = object_from_mesh(
            mesh, unit=unit, mass_g=mass_g, pose="stable" if np.isnan(pose).any() else pose
        )
        gripper = load_gripper(gripper_name)
        ids, grasp_of = np.unique(grasp_ids[members], return_inverse=True)
        firsts = [int(members[np.flatnonzero(grasp_of == k)[0]]) for k in range(len(ids))]
        where = f"{t.path} (lines {t.line[members].min()}-{t.line[members].max()})"
        centres = grasp_centres(
            t.grasp_pose[firsts], t.depth_mm[firsts] * 1e-3, None, where, gripper.tcp_offset_mm
        )
        centres = to_object_frame(obj, centres, where)
        same = _same_scene(out, mesh, mass_g, gripper_name, obj)
        if same is not None:  # the part lies as in a scene already made, turned about z
            sc, turn = same
            moved = np.tile(np.eye(4), (len(centres), 1, 1))
            moved[:, :3, :3] = rz(turn)
            sc.grasp_of = np.concatenate([sc.grasp_of, grasp_of + len(sc.centres)])
            sc.centres = np.concatenate([sc.centres, moved @ centres])
            sc.trials = np.concatenate([sc.trials, members])
            continue
        settings = settings_on(gripper, contact, solver, grasp, keep)
        sim = Simulator(obj, runner=runner)  # the scene built once: checked and simulated
        source = (mesh, mass_g, gripper_name)
        scene = sim.exact_scene(settings)
        out.append(_Scene(obj, settings, sim, scene, centres, grasp_of, members, source))
    return out


# two posed parts are one solid when their vertices agree to this after a turn about z
# (the trials' rotations are rounded in their files: micrometres at a part's size)
SAME_SOLID_M = 1e-5


def _same_scene(scenes: list[_Scene], mesh: str, mass_g: float, gripper: str, obj):
    """(scene, yaw) of a scene already made whose part is obj's -- the same file, mass and
    gripper, lying the same way up -- turned by yaw (rad) about the vertical; None if
    there is none. A table is the same under any turn about the vertical, so such trials
    share one scene (a cube on any face: one)."""
    for sc in scenes:
        if sc.source != (mesh, mass_g, gripper):
            continue
        turn = _turn_onto(sc.obj.mesh.vertices, obj.mesh.vertices, SAME_SOLID_M)
        if turn is not None:
            return sc, turn
    return None


def _turn_onto(target: np.ndarray, points: np.ndarray, tol: float) -> float | None:
    """The turn about z (rad) that lays the point set `points` (V, 3) onto `target`
    within tol, or None."""
    from scipy.spatial import cKDTree

    if target.shape != points.shape:
        return None
    tree = cKDTree(target)
    radius = np.hypot(target[:, 0], target[:, 1])
    a = int(np.argmax(radius))
    r_p = np.hypot(points[:, 0], points[:, 1])
    near = np.flatnonzero(
        (np.abs(r_p - radius[a]) < tol) & (np.abs(points[:, 2] - target[a, 2]) < tol)
    )
    for b in near:
        turn = np.arctan2(target[a, 1], target[a, 0]) - np.arctan2(points[b, 1], points[b, 0])
        moved = points @ rz(turn).T
        if np.all(tree.query(moved)[0] < tol):
            return float(turn)
    return None


def _simulate(t: Trials, index, scenes: list[_Scene], opts: RunOptions) -> dict:
    """The per-trial table's columns: each trial with its grasp's check and label."""
    from mjx_pick.studies.evaluation import evaluate

    n = len(t)
    sim = np.zeros(n, bool)
    outcome = np.full(n, "", object)
    score = np.full(n, np.nan)
    grasp_col = np.full(n, -1, np.int64)
    tilt = np.full(n, np.nan)
    offset = 0
    for sc in scenes:
        checker = GraspChecker(sc.scene, opts.picks.safety_zone_mm)
        res = checker(sc.centres)
        ok = res["reason"] == 0
        labels = np.zeros(len(sc.centres), bool)
        what = np.array([f"rejected: {REASONS[r]}" for r in res["reason"]], object)
        scores = np.full(len(sc.centres), np.nan)
        if ok.any():
            batch = feasible_batch(np.arange(len(ok)), sc.centres, res, "trials")
            ev = evaluate(
                sc.obj,
                sc.settings.gripper,
                picks=batch,
                simulator=sc.sim,
                contact=sc.settings.contact,
                solver=sc.settings.solver,
                grasp=sc.settings.grasp,
                n_traces=0,
            )
            labels[ok] = np.asarray(ev.table["success"], bool)
            what[ok] = ev.table["failure"].to_pylist()
            scores[ok] = np.asarray(ev.table["score"], float)
        # a grasp from under the table (rejected: table) has no tilt: NaN
        tilt_deg = quat_tilt_deg(decompose(sc.centres)["tilt_quat"])
        for k, i in enumerate(sc.trials):
            g = sc.grasp_of[k]
            sim[i], outcome[i], score[i] = labels[g], what[g], scores[g]
            grasp_col[i], tilt[i] = offset + g, tilt_deg[g]
        offset += len(sc.centres)
    keep = np.asarray(index)
    return {
        "trial": [t.trial[i] for i in keep],
        "line": t.line[keep],
        "object": [Path(t.object[i]).name for i in keep],
        "gripper": [Path(t.gripper[i]).stem for i in keep],
        "grasp": grasp_col[keep],
        "success": t.success[keep],
        "sim_success": sim[keep],
        "sim_outcome": list(outcome[keep]),
        "score": score[keep],
        "tilt_deg": tilt[keep],
    }


def confusion(real: np.ndarray, sim: np.ndarray) -> dict:
    """tp, fp, fn, tn (success the positive class) and accuracy, precision, recall, F1
    (None where undefined: no predicted or no real success)."""
    real, sim = np.asarray(real, bool), np.asarray(sim, bool)
    tp, fp = int(np.sum(real & sim)), int(np.sum(~real & sim))
    fn, tn = int(np.sum(real & ~sim)), int(np.sum(~real & ~sim))
    n = tp + fp + fn + tn
    precision = tp / (tp + fp) if tp + fp else None
    recall = tp / (tp + fn) if tp + fn else None
    f1 = 2 * tp / (2 * tp + fp + fn) if tp else (0.0 if fp + fn else None)
    return {
        "tp": tp,
        "fp": fp,
        "fn": fn,
        "tn": tn,
        "accuracy": (tp + tn) / n if n else None,
        "precision": precision,
        "recall": recall,
        "f1": f1,
    }


METRICS = ("accuracy", "precision", "recall", "f1")


def figures(real, sim, grasp, seed: int = 0, resamples: int = BOOTSTRAP) -> dict:
    """n, each of METRICS as {"value", "ci95": [lo, hi]} (a percentile bootstrap over
    grasps: resampled with their repeats) and the confusion matrix."""
    real, sim, grasp = np.asarray(real, bool), np.asarray(sim, bool), np.asarray(grasp)
    point = confusion(real, sim)
    ids, inverse = np.unique(grasp, return_inverse=True)
    rng = np.random.default_rng(seed)
    # per grasp: counts of each cell, then a resample is a weighted sum of grasps
    cells = np.zeros((len(ids), 4))
    for k, (r, s) in enumerate(zip(real, sim, strict=True)):
        cells[inverse[k], _cell(r, s)] += 1
    draws = rng.multinomial(len(ids), np.full(len(ids), 1 / len(ids)), size=resamples)
    tp, fp, fn, tn = (draws @ cells).T
    with np.errstate(divide="ignore", invalid="ignore"):
        boot = {
            "accuracy": (tp + tn) / (tp + fp + fn + tn),
            "precision": tp / (tp + fp),
            "recall": tp / (tp + fn),
            "f1": 2 * tp / (2 * tp + fp + fn),
        }
    out = {"n": int(len(real)), "grasps": int(len(ids))}
    for name in METRICS:
        values = boot[name][np.isfinite(boot[name])]
        ci = (
            [float(np.percentile(values, 2.5)), float(np.percentile(values, 97.5))]
            if len(values)
            else [None, None]
        )
        out[name] = {"value": point[name], "ci95": ci}
    out["confusion"] = {k: point[k] for k in ("tp", "fp", "fn", "tn")}
    out["real_success_rate"] = float(real.mean()) if len(real) else None
    return out


def _cell(real: bool, sim: bool) -> int:
    """The confusion cell's column: tp 0, fp 1, fn 2, tn 3."""
    return {(True, True): 0, (False, True): 1, (True, False): 2, (False, False): 3}[
        (bool(real), bool(sim))
    ]


def _report(t: Trials, index, rows: dict, seed: int) -> dict:
    """validation.json's figures: overall, per object, and the checks against the world."""
    real, sim = np.asarray(rows["success"]), np.asarray(rows["sim_success"])
    grasp = np.asarray(rows["grasp"])
    report = figures(real, sim, grasp, seed)
    objects = np.asarray(rows["object"], object)
    report["per_object"] = {
        str(o): figures(real[objects == o], sim[objects == o], grasp[objects == o], seed)
        for o in sorted(set(objects))
    }
    outcome = np.asarray(rows["sim_outcome"], object)
    rejected = np.array([str(v).startswith("rejected: ") for v in outcome])
    reasons = {}
    for r in REASONS[1:]:
        mask = outcome == f"rejected: {r}"
        if mask.any():
            reasons[r] = {
                "trials": int(mask.sum()),
                "held_on_the_robot": int((mask & real).sum()),
                "means": REASON_WORDS[r],
            }
    report["checks"] = {
        "rejected_trials": int(rejected.sum()),
        "rejected_that_held": int((rejected & real).sum()),
        "by_reason": reasons,
    }
    failures = {}
    for v in outcome[~rejected]:
        failures[str(v)] = failures.get(str(v), 0) + 1
    report["simulated_outcomes"] = failures
    report["trials_file"] = str(t.path)
    return report


def split_by_grasp(
    t: Trials, fraction: float = 0.5, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(train, test) trial indices: the grasps shuffled (seeded) and split so that about
    `fraction` of them train; a grasp's repeats stay on one side."""
    if not 0.0 < fraction < 1.0:
        raise ConfigError(f"split = {fraction!r} is not allowed: a fraction in (0, 1)")
    grasp = t.grasp_index()
    ids = np.unique(grasp)
    if len(ids) < 2:
        raise ConfigError(f"{t.path} holds {len(ids)} grasp: a split needs two or more")
    order = np.random.default_rng(seed).permutation(ids)
    n_train = min(max(1, round(fraction * len(ids))), len(ids) - 1)
    train = np.isin(grasp, order[:n_train])
    return np.flatnonzero(train), np.flatnonzero(~train)


def trial_outcomes(
    t: Trials,
    subset,
    contact: ContactParams | None = None,
    solver: SolverParams | None = None,
    grasp: GraspConfig | None = None,
    keep_grasp: tuple[str, ...] = (),
    unit: str = "m",
    safety_zone_mm: float = 5.0,
):
    """The trials of subset as calibration's measured outcomes: (object, settings,
    Outcomes with one row per feasible grasp -- its repeats' trials and successes --
    and the grasps themselves). One scene only: a fit is of one part and gripper. Grasps
    the checks reject are left out (no parameter changes a rejection)."""
    from mjx_pick.studies.calibration.data import Outcomes

    scenes = _prepare(t, np.asarray(subset), contact, solver, grasp, keep_grasp, unit)
    if len(scenes) != 1:
        raise ConfigError(
            f"{t.path}: the trials chosen hold {len(scenes)} scenes (object, mass, gripper, "
            "object pose): a fit is of one part and gripper; give a TRIALS.csv of one"
        )
    sc = scenes[0]
    res = GraspChecker(sc.scene, safety_zone_mm)(sc.centres)
    ok = res["reason"] == 0
    if not ok.any():
        raise ConfigError(f"{t.path}: none of the chosen trials' grasps is feasible")
    batch = feasible_batch(np.arange(len(ok)), sc.centres, res, "trials")
    kept = np.flatnonzero(ok)
    real = t.success[sc.trials]
    trials = np.array([np.sum(sc.grasp_of == g) for g in kept], float)
    successes = np.array([np.sum(real[sc.grasp_of == g]) for g in kept], float)
    n = len(kept)
    force = np.full(n, sc.settings.grasp.grip_force_n)
    outcomes = Outcomes(
        batch.x_mm,
        batch.y_mm,
        batch.yaw_deg,
        force,
        trials,
        successes,
        np.full(n, np.nan),
        tuple([None] * n),
        None,
        batch,
    )
    return sc.obj, sc.settings, outcomes
