"""A mesh's repair into a closed solid, with what it changed; its shells checked.

Details: docs/model.md (core/meshrepair.py).
"""

from __future__ import annotations

import dataclasses
import json
import logging
from pathlib import Path

import numpy as np
import trimesh

from mjx_pick.core import numbers
from mjx_pick.core.config import ConfigError

log = logging.getLogger(__name__)

# the default tolerances of a repair (the user sets them: object_from_mesh's repair_*)
VOLUME_PCT = numbers.REPAIR_DEFAULTS["repair_volume_pct"]
COM_MM = numbers.REPAIR_DEFAULTS["repair_com_mm"]
BOUNDS_MM = numbers.REPAIR_DEFAULTS["repair_bounds_mm"]
# a part's shell is checked for crossing another on at most this many of its vertices
SHELL_SAMPLES = 256


@dataclasses.dataclass(frozen=True)
class Repair:
    """What a repair changed in a mesh (all zero: nothing was).

    Faces are compared by their corners' coordinates, before (the file's, scaled) and
    after. Each region of changed faces (a filled hole and the triangles around it
    that were taken out) leaves the solid undecided within the convex hull of its
    corners: its volume is what a hole's filling may add or take ("in doubt").

    Attributes:
      faces_removed: triangles taken out: of no area (a corner repeated), copies of
        another (a fold: a triangle and its reverse), or cut out by the hole filler.
      faces_added: triangles added to close holes.
      holes: regions of the surface that the repair changed by adding triangles.
      turned: whether triangles were turned (inconsistent or inside-out winding).
      volume_mm3: the closed solid's volume after the repair.
      volume_doubt_mm3: volume within the changed regions' convex hulls.
      com_doubt_mm: the most the centre of mass may move if that volume were solid
        or empty (each region's volume times its farthest corner from the centre of
        mass, over the whole volume).
      bounds_change_mm: the largest move of a face of the axis-aligned bounding box.
      tool: what closed holes ("" when none was closed).
    """

    faces_removed: int = 0
    faces_added: int = 0
    holes: int = 0
    turned: bool = False
    volume_mm3: float = 0.0
    volume_doubt_mm3: float = 0.0
    com_doubt_mm: float = 0.0
    bounds_change_mm: float = 0.0
    tool: str = ""

    @property
    def changed(self) -> bool:
        """Whether the surface changed at all (faces in or out, or turned)."""
        return bool(self.faces_removed or self.faces_added or self.turned)

    @property
    def volume_doubt_pct(self) -> float:
        return 100.0 * self.volume_doubt_mm3 / self.volume_mm3 if self.volume_mm3 > 0 else 0.0

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> Repair:
        return cls(**json.loads(text))

    def mass_doubt_g(self, density: float) -> float:
        """The mass's doubt at a given density (kg/m^3), g."""
        return density * self.volume_doubt_mm3 * 1e-6

    def density_doubt(self, density: float) -> float:
        """The density's doubt (kg/m^3) where it follows from a given mass."""
        return density * self.volume_doubt_pct / 100.0

    def figures(self, mass_kg: float, density: float, density_given: bool) -> dict:
        """Plain values for a summary: the counts, the volume and its doubt (mm^3, %),
        the mass (g) and density (kg/m^3), and the doubt of the one that followed from
        the other (the mass at a given density, or the density of a given mass), the
        centre of mass's and the bounds' change (mm)."""
        out = {
            "faces_removed": self.faces_removed,
            "faces_added": self.faces_added,
            "holes": self.holes,
            "turned": self.turned,
            "tool": self.tool,
            "volume_mm3": _sig(self.volume_mm3),
            "volume_doubt_mm3": _sig(self.volume_doubt_mm3),
            "volume_doubt_pct": _sig(self.volume_doubt_pct),
            "mass_g": _sig(mass_kg * 1e3),
            "density_kg_m3": _sig(density),
            "com_doubt_mm": _sig(self.com_doubt_mm),
            "bounds_change_mm": _sig(self.bounds_change_mm),
        }
        if density_given:
            out["mass_doubt_g"] = _sig(self.mass_doubt_g(density))
        else:
            out["density_doubt_kg_m3"] = _sig(self.density_doubt(density))
        return out

    def describe(self, density: float | None = None, density_given: bool = False) -> str:
        """The repair in a sentence (density, kg/m^3: with the mass's or the density's
        doubt, whichever followed from the other)."""
        what = []
        if self.faces_removed:
            what.append(f"{_count(self.faces_removed, 'triangle')} taken out")
        if self.faces_added:
            what.append(
                f"{_count(self.faces_added, 'triangle')} added to close "
                f"{_count(self.holes, 'hole')} ({self.tool})"
            )
        if self.turned:
            what.append("triangles turned to face outward")
        text = (
            f"{', '.join(what) or 'nothing changed'}: volume {self.volume_mm3:.6g} mm^3 +- "
            f"{self.volume_doubt_mm3:.4g} mm^3 ({self.volume_doubt_pct:.3g} %)"
        )
        if density is not None and density_given:
            mass = density * self.volume_mm3 * 1e-6
            doubt = self.mass_doubt_g(density)
            text += f", mass {mass:.6g} g +- {doubt:.4g} g at {density:g} kg/m^3"
        elif density is not None:
            doubt = self.density_doubt(density)
            text += f", density {density:.6g} +- {doubt:.4g} kg/m^3 of the given mass"
        return (
            f"{text}, centre of mass within {self.com_doubt_mm:.3g} mm, bounds moved "
            f"{self.bounds_change_mm:.3g} mm"
        )


def _sig(x: float) -> float:
    """x as a plain float to 9 significant digits (a summary's figure)."""
    return float(f"{float(x):.9g}")


def _count(n: int, noun: str) -> str:
    return f"{n} {noun}{'' if n == 1 else 's'}"


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """How much a mesh's repair may change it and still be accepted.

    Attributes:
      volume_pct: the volume in doubt, % of the solid's volume.
      com_mm: the centre of mass's possible move, mm.
      bounds_mm: the bounding box's largest change, mm.
    """

    volume_pct: float = VOLUME_PCT
    com_mm: float = COM_MM
    bounds_mm: float = BOUNDS_MM

    def __post_init__(self):
        numbers.check("repair_volume_pct", self.volume_pct)
        numbers.check("repair_com_mm", self.com_mm)
        numbers.check("repair_bounds_mm", self.bounds_mm)

    def check(self, path: Path, rep: Repair, density: float, density_given: bool) -> None:
        """Refuse a repair beyond a tolerance, naming the mesh and each changed figure."""
        over = []
        if rep.volume_doubt_pct > self.volume_pct:
            over.append(
                f"volume {rep.volume_doubt_pct:.3g} % in doubt (allowed: repair_volume_pct = "
                f"{self.volume_pct:g} %, --repair-volume-pct)"
            )
        if rep.com_doubt_mm > self.com_mm:
            over.append(
                f"centre of mass within {rep.com_doubt_mm:.3g} mm (allowed: repair_com_mm = "
                f"{self.com_mm:g} mm, --repair-com-mm)"
            )
        if rep.bounds_change_mm > self.bounds_mm:
            over.append(
                f"bounds moved {rep.bounds_change_mm:.3g} mm (allowed: repair_bounds_mm = "
                f"{self.bounds_mm:g} mm, --repair-bounds-mm)"
            )
        if over:
            raise ConfigError(
                f"mesh {str(path)!r} is not a closed solid, and its repair changes it beyond "
                f"the tolerances: {'; '.join(over)} ({rep.describe(density, density_given)}); "
                "close its holes where you know the part's shape (CAD, or MeshLab's 'close "
                "holes'), or raise the tolerance if the figures are acceptable"
            )


# ------------------------------------------------------------------------- repair


def repair(mesh: trimesh.Trimesh, path: Path) -> tuple[trimesh.Trimesh, Repair]:
    """A closed, outward-wound solid made of mesh (its frame kept, no vertex moved),
    and what changed; or a ConfigError naming what could not be closed.

    Triangles that hold no volume are taken out (a repeated corner; a triangle and its
    reverse, as decimation leaves them); holes left are closed by MeshFix (pymeshfix),
    which adds triangles inside them only; winding is made consistent and outward.
    """
    v0, f0 = np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int64)
    faces = _without_void_faces(f0)
    fixed = trimesh.Trimesh(v0, faces, process=False)
    tool = ""
    if not fixed.is_watertight:
        fixed, tool = _filled(fixed, path), "MeshFix"
    turned = False
    if fixed.is_watertight and not fixed.is_winding_consistent:
        trimesh.repair.fix_winding(fixed)
        turned = True
    if fixed.is_watertight and fixed.is_winding_consistent and fixed.volume < 0:
        fixed.invert()  # wound inside out: the same solid
        turned = True
    if not (fixed.is_watertight and fixed.is_winding_consistent and fixed.volume > 0):
        raise ConfigError(f"mesh {str(path)!r} is not a closed solid: {_open_edges(fixed)}")
    fixed.remove_unreferenced_vertices()
    # no triangle taken out or added (turned at most): no face to compare, none changed
    same = len(faces) == len(f0) and not tool
    return fixed, _measured(v0, f0, fixed, turned, tool, same)


def _without_void_faces(faces: np.ndarray) -> np.ndarray:
    """faces (F, 3) less those that bound no volume: a corner repeated (no area), and
    copies of one triangle -- opposite copies cancel (a fold), same-facing ones are one
    triangle counted twice; a triangle repeated keeps one copy facing its majority."""
    degenerate = (faces[:, 0] == faces[:, 1]) | (faces[:, 1] == faces[:, 2])
    degenerate |= faces[:, 0] == faces[:, 2]
    keep = ~degenerate
    ordered = np.sort(faces, axis=1)
    # +1 where a triangle's corners are an even turn of their sorted order, else -1
    even = np.zeros(len(faces), bool)
    for k in range(3):
        even |= (faces == np.roll(ordered, k, axis=1)).all(axis=1)
    _, group, count = np.unique(ordered, axis=0, return_inverse=True, return_counts=True)
    group = group.ravel()
    for g in np.flatnonzero(count > 1):
        copies = np.flatnonzero((group == g) & keep)
        if len(copies) < 2:
            continue
        net = int(np.where(even[copies], 1, -1).sum())
        keep[copies] = False
        if net:
            keep[copies[np.flatnonzero(even[copies] == (net > 0))[0]]] = True
    return faces[keep]


def _filled(mesh: trimesh.Trimesh, path: Path) -> trimesh.Trimesh:
    """mesh with its holes closed by MeshFix's hole filling (triangulated, refined
    and faired inside each hole; the vertices around it kept where they are)."""
    try:
        import pymeshfix
    except ImportError:
        raise ConfigError(
            f"mesh {str(path)!r} is not a closed solid ({_open_edges(mesh)}); closing its "
            "holes needs pymeshfix (GPL-3, an optional extra): pip install "
            "\"mjx-pick[repair]\", or close them yourself (MeshLab's 'close holes')"
        ) from None
    log.info("%s: closing holes (MeshFix) ...", path.name)
    tin = pymeshfix.PyTMesh()
    tin.set_quiet(True)
    tin.load_array(np.asarray(mesh.vertices, np.float64), np.asarray(mesh.faces, np.int32))
    tin.fill_small_boundaries(nbe=0, refine=True)
    vertices, faces = tin.return_arrays()
    return trimesh.Trimesh(np.asarray(vertices, np.float64), np.asarray(faces), process=False)


def _open_edges(mesh: trimesh.Trimesh) -> str:
    """What keeps a surface from being a closed solid, in words."""
    _, count = np.unique(mesh.edges_sorted, axis=0, return_counts=True)
    said = []
    if (count == 1).any():
        said.append(f"{int((count == 1).sum())} edges bound a hole")
    if (count > 2).any():
        said.append(f"{int((count > 2).sum())} edges are shared by more than two triangles")
    if not said and not mesh.is_winding_consistent:
        said.append("its triangles face inconsistently")
    if not said:
        said.append("it encloses no volume")
    return "; ".join(said) + " (mass properties need a closed, consistently wound surface)"


def _measured(
    v0: np.ndarray, f0: np.ndarray, after: trimesh.Trimesh, turned: bool, tool: str, same: bool
) -> Repair:
    """Repair's figures: faces compared by their corners' coordinates (before: v0, f0;
    after; same: the faces are known to be the same), the changed regions' hulls, the
    bounds of the faces' corners."""
    volume = float(after.volume)
    removed, added, regions = (0, 0, []) if same else _changed_regions(v0, f0, after)
    com = np.asarray(after.center_mass)
    doubt = com_doubt = 0.0
    holes = 0
    for corners, with_added in regions:
        if not with_added:  # only triangles that bound no volume were taken out here
            continue
        holes += 1
        hull = _hull_volume(corners)
        doubt += hull
        com_doubt += hull * float(np.linalg.norm(corners - com, axis=1).max())
    used = v0[np.unique(f0)]
    before_bounds = np.array([used.min(axis=0), used.max(axis=0)])
    return Repair(
        faces_removed=removed,
        faces_added=added,
        holes=holes,
        turned=turned,
        volume_mm3=volume * 1e9,
        volume_doubt_mm3=doubt * 1e9,
        com_doubt_mm=com_doubt / volume * 1e3,
        bounds_change_mm=float(np.abs(after.bounds - before_bounds).max()) * 1e3,
        tool=tool if added else "",
    )


def _changed_regions(
    v0: np.ndarray, f0: np.ndarray, after: trimesh.Trimesh
) -> tuple[int, int, list[tuple[np.ndarray, bool]]]:
    """(faces removed, faces added, regions): the triangles in one surface and not the
    other, by their corners' coordinates (exact; as multisets, so that copies of a
    triangle taken out count and one kept does not), grouped into regions that share a
    corner; each region as its corners (K, 3) m and whether it holds an added one."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    v1, f1 = np.asarray(after.vertices, np.float64), np.asarray(after.faces, np.int64)
    corners, ids = np.unique(np.vstack([v0, v1]), axis=0, return_inverse=True)
    ids = ids.ravel()
    tris = np.vstack([np.sort(ids[: len(v0)][f0], axis=1), np.sort(ids[len(v0) :][f1], axis=1)])
    kinds, group = np.unique(tris, axis=0, return_inverse=True)
    group = group.ravel()
    before = np.bincount(group[: len(f0)], minlength=len(kinds))
    now = np.bincount(group[len(f0) :], minlength=len(kinds))
    removed, added = np.maximum(before - now, 0), np.maximum(now - before, 0)
    changed = np.flatnonzero(removed + added)
    if not len(changed):
        return 0, 0, []
    tri = kinds[changed]  # (C, 3) corner ids
    edges = np.vstack([tri[:, [0, 1]], tri[:, [1, 2]]])
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (len(corners),) * 2)
    _, label = connected_components(graph, directed=False)
    regions = []
    for region in np.unique(label[tri[:, 0]]):
        mine = label[tri[:, 0]] == region
        regions.append((corners[np.unique(tri[mine])], bool(added[changed[mine]].any())))
    return int(removed.sum()), int(added.sum()), regions


def _hull_volume(points: np.ndarray) -> float:
    """Volume of the points' convex hull, m^3 (0 for fewer than 4 or coplanar ones)."""
    from scipy.spatial import ConvexHull, QhullError

    if len(points) < 4:
        return 0.0
    try:
        return float(ConvexHull(points).volume)
    except (QhullError, ValueError):
        return 0.0


# ------------------------------------------------------------------------- shells


def shells(mesh: trimesh.Trimesh, path: Path) -> tuple[list, list]:
    """(bodies, voids) of a closed solid: its shells wound outward and inward. Refused:
    shells whose surfaces cross (the solid they bound is not defined), an inward shell
    in no body (a body turned inside out, not a void), a body inside another with no
    void between (its volume counted twice). A shell is inside another when its corners
    (up to SHELL_SAMPLES of them) are."""
    parts = mesh.split(only_watertight=False)
    if len(parts) <= 1:
        return [mesh], []
    outward = [s if s.volume > 0 else _inverted(s) for s in parts]
    rng = np.random.default_rng(0)
    depth = np.zeros(len(parts), int)  # how many shells hold each
    for i, part in enumerate(parts):
        n = len(part.vertices)
        sample = part.vertices[rng.choice(n, min(n, SHELL_SAMPLES), replace=False)]
        for j, other in enumerate(outward):
            lo, hi = other.bounds
            if i == j or not ((sample >= lo) & (sample <= hi)).all(axis=1).any():
                continue
            hit = other.contains(sample)
            if hit.any() and not hit.all():
                raise ConfigError(
                    f"mesh {str(path)!r}: two of its closed surfaces cross each other "
                    f"({_mm3(part)} and {_mm3(other)}): the solid they bound is not "
                    "defined; join them in CAD (a boolean union or difference)"
                )
            depth[i] += int(hit.all())
    largest = max(outward, key=lambda s: s.volume)
    for part, d in zip(parts, depth, strict=True):
        if part.volume <= 0 and d % 2 == 0:
            # which of the two is inside out the file cannot say: both are named
            raise ConfigError(
                f"mesh {str(path)!r}: a closed surface ({_mm3(part)}) faces the other way "
                f"from the body of {_mm3(largest)}, as a void's would, but lies in no body: "
                "one of them is turned inside out (its triangles face inward); turn its "
                "triangles (MeshLab's 'invert faces orientation') or remove it"
            )
        if part.volume > 0 and d % 2 == 1:
            raise ConfigError(
                f"mesh {str(path)!r}: a body ({_mm3(part)}) lies inside another with no void "
                "between them, so its volume would count twice; remove it, or join them "
                "in CAD (a boolean union)"
            )
    return [s for s in parts if s.volume > 0], [s for s in parts if s.volume <= 0]


def _mm3(shell: trimesh.Trimesh) -> str:
    return f"{abs(shell.volume) * 1e9:.6g} mm^3"


def _inverted(shell: trimesh.Trimesh) -> trimesh.Trimesh:
    out = shell.copy()
    out.invert()
    return out
