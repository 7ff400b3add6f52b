"""Many parts in one command: a folder of meshes or a manifest, each part evaluated into a
folder of its own, one results table with an object column.

Details: docs/studies.md ("Many parts in one command").
"""

from __future__ import annotations

import csv
import dataclasses
import io
import time
from pathlib import Path

import pyarrow as pa

from mjx_pick.core.config import ConfigError, read_text, write_json, write_parquet
from mjx_pick.core.gripper import GripperSpec, load_gripper
from mjx_pick.core.objects import MESH_SUFFIXES, load_object
from mjx_pick.outputs.rundir import claim, config_hash, fail, finish
from mjx_pick.studies.options import RunOptions, split_fields

# the manifest's columns: the mesh (relative to the manifest), then its mass or density
MANIFEST_COLUMNS = ("object", "mass_g", "density_kg_m3", "unit", "pose")
# the folder of each part's run inside the set's folder
PARTS = "objects"


@dataclasses.dataclass(frozen=True)
class Part:
    """One part of a set: its mesh and what its import needs."""

    name: str
    path: Path
    mass_g: float | None = None
    density_kg_m3: float | None = None
    unit: str = "m"
    pose: str = "as_given"


def is_object_set(source) -> bool:
    """Whether source names many parts: a folder, or a CSV manifest (a header with an
    ``object`` column and no ``grasp_pose``: that is a TRIALS.csv)."""
    path = Path(str(source))
    if path.is_dir():
        return True
    if path.suffix.lower() != ".csv" or not path.is_file():
        return False
    with path.open(encoding="utf-8-sig", errors="replace") as fh:
        columns = {c.strip() for c in fh.readline().split(",")}
    return "object" in columns and "grasp_pose" not in columns


def read_parts(
    source,
    *,
    mass_g: float | None = None,
    density_kg_m3: float | None = None,
    unit: str | None = None,
    pose: str = "as_given",
) -> list[Part]:
    """The parts a folder or a manifest names, checked before any work.

    A folder: every mesh file in it (STL, OBJ, PLY, GLB), each with density_kg_m3 (one
    mass cannot be every part's), unit and pose. A manifest (CSV): a row per part --
    ``object`` (a mesh path relative to the manifest), ``mass_g`` or ``density_kg_m3``,
    optional ``unit`` (default: unit, else m) and ``pose`` (as_given or stable).
    """
    path = Path(str(source))
    if path.is_dir():
        files = sorted(p for p in path.iterdir() if p.suffix.lower() in MESH_SUFFIXES)
        if not files:
            raise ConfigError(
                f"folder {str(path)!r} holds no mesh ({', '.join(sorted(MESH_SUFFIXES))})"
            )
        if mass_g is not None or density_kg_m3 is None:
            raise ConfigError(
                f"the parts of folder {str(path)!r} need a density (--density-kg-m3), one "
                "mass cannot be every part's; or give a manifest CSV with each part's mass_g"
            )
        parts = [Part(p.stem, p, None, density_kg_m3, unit or "m", pose) for p in files]
    else:
        parts = _manifest(path, unit)
    names = [p.name for p in parts]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise ConfigError(
            f"{str(path)!r}: parts named alike ({', '.join(twice)}): each part's folder is "
            "named after its file; rename one"
        )
    return parts


def _manifest(path: Path, unit: str | None) -> list[Part]:
    text = read_text(path, "parts manifest")
    rows = list(csv.DictReader(io.StringIO(text)))
    if not rows:
        raise ConfigError(f"manifest {path} names no part (a header and a row per part)")
    parts = []
    for line, row in enumerate(rows, start=2):
        cell = {k: (row.get(k) or "").strip() for k in MANIFEST_COLUMNS}
        mesh = path.parent / cell["object"]
        if not cell["object"] or not mesh.is_file():
            raise ConfigError(
                f"{path} line {line}, column object: {cell['object']!r} is not a mesh file "
                f"(paths are relative to the manifest: {path.parent})"
            )
        numbers = {}
        for key in ("mass_g", "density_kg_m3"):
            if cell[key]:
                try:
                    numbers[key] = float(cell[key])
                except ValueError:
                    raise ConfigError(
                        f"{path} line {line}, column {key}: {cell[key]!r} is not a number"
                    ) from None
        if len(numbers) != 1:
            raise ConfigError(
                f"{path} line {line}: give the part's mass_g or its density_kg_m3 (one of them)"
            )
        parts.append(
            Part(
                mesh.stem,
                mesh,
                numbers.get("mass_g"),
                numbers.get("density_kg_m3"),
                cell["unit"] or unit or "m",
                cell["pose"] or "as_given",
            )
        )
    return parts


@dataclasses.dataclass
class SetEvaluation:
    """What evaluate_set produced: every part's rows (an ``object`` column first), each
    part's summary, and the set's folder."""

    table: pa.Table
    summaries: dict
    out_dir: Path | None


def evaluate_set(
    parts: list[Part],
    gripper: GripperSpec | str = "robotiq-2f85",
    options: RunOptions | None = None,
    *,
    object_options: dict | None = None,
    **fields,
) -> SetEvaluation:
    """Evaluate each part (``evaluation.evaluate``, the fields of either its request or
    RunOptions by name) into ``out/objects/<part>/`` -- a run folder of its own, resumed
    on its own (--resume continues the parts not complete, reads back those that are) --
    then one results table with an ``object`` column (``out/results.parquet``) and every
    part's summary (``out/summary.json``). Every part's mesh is read and checked before
    the first simulation. object_options: ``load_object``'s keywords for every part (a
    repair's tolerances, a material, the largest body only, ...; one a mesh does not use
    is refused by it)."""
    from mjx_pick.studies.evaluation import EvaluateRequest, evaluate

    req, opts = split_fields(EvaluateRequest, None, options, fields)
    if req.picks is not None:
        raise ConfigError("a set of parts takes no picks file: each part draws its own grasps")
    gripper = gripper if isinstance(gripper, GripperSpec) else load_gripper(gripper)
    object_options = dict(object_options or {})
    objects = [_load(p, object_options) for p in parts]  # every part checked before any work
    out = Path(opts.out) if opts.out is not None else None
    key = config_hash(
        {
            "parts": [dataclasses.asdict(p) | {"path": str(p.path)} for p in parts],
            "gripper": dataclasses.asdict(gripper),
            "request": repr(req),
            "n": opts.n,
            "seed": opts.seed,
            **({"object_options": object_options} if object_options else {}),
        }
    )
    if out is not None:
        claim(out, "evaluate-set", key, resume=opts.resume, overwrite=opts.overwrite)
    t0 = time.perf_counter()
    try:
        tables, summaries = [], {}
        for part, obj in zip(parts, objects, strict=True):
            sub = None if out is None else out / PARTS / part.name
            resume = opts.resume and sub is not None and sub.is_dir()
            run = dataclasses.replace(opts, out=sub, resume=resume)
            ev = evaluate(obj, gripper, run, request=req)
            table = ev.table
            tables.append(table.add_column(0, "object", pa.array([part.name] * len(table))))
            summaries[part.name] = ev.summary
        table = pa.concat_tables(tables, promote_options="default")
        if out is not None:
            write_parquet(out / "results.parquet", table)
            write_json(out / "summary.json", _set_summary(summaries))
            finish(
                out,
                command="evaluate-set",
                config={"parts": [p.name for p in parts], "gripper": gripper.name},
                seed=opts.seed,
                backend=opts.backend,
                timing={"wall_s": round(time.perf_counter() - t0, 3)},
            )
        return SetEvaluation(table, summaries, out)
    except BaseException as err:
        if out is not None:
            fail(out, err, command="evaluate-set")
        raise


def _load(part: Part, object_options: dict):
    return load_object(
        part.path,
        mass_g=part.mass_g,
        density_kg_m3=part.density_kg_m3,
        unit=part.unit,
        pose=part.pose,
        **object_options,
    )


def _set_summary(summaries: dict) -> dict:
    """The set's summary: each part's, and the totals over them."""
    n = sum(int(s["n"]) for s in summaries.values())
    ok = sum(int(s["successes"]) for s in summaries.values())
    return {
        "parts": len(summaries),
        "n": n,
        "successes": ok,
        "success_rate": ok / n if n else None,
        "per_part": {
            k: {key: s.get(key) for key in ("n", "successes", "success_rate", "rejected")}
            for k, s in summaries.items()
        },
        "objects": summaries,
    }
