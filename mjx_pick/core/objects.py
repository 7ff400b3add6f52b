"""Object import: a top-down image plus thickness, or a mesh, to an :class:`ObjectModel`.

Details: docs/model.md (core/objects.py).
"""

from __future__ import annotations

import dataclasses
import logging
import math
import os
import warnings
from pathlib import Path

import cv2
import numpy as np
import shapely
import shapely.affinity
import trimesh
from shapely.geometry import MultiPolygon, Polygon
from shapely.geometry.polygon import orient

from mjx_pick.core import cache, meshrepair, numbers
from mjx_pick.core.config import ConfigError, PlausibilityWarning, check_name, check_range
from mjx_pick.core.grasps import ORTHONORMAL_TOL, nearest_rotation

# what a slow preparation step is doing, said as it starts (the CLI shows it on stderr)
log = logging.getLogger(__name__)

# MJX wants convex meshes of fewer than ~32 vertices for its branchless convex-convex
# test ("sharp bits" of the MJX docs); a prism of 12 polygon corners has 24.
MAX_PIECE_CORNERS = 12
MAX_HULL_VERTICES = 32
# CoACD's search besides the concavity threshold (object_from_mesh's coacd_threshold):
# at most 32 pieces; 60 tree-search iterations, not CoACD's 150 -- the shipped parts'
# labels move no more than under another seed, in less time (benchmarks/coacd_labels.py
# measures it). Part of the prepared mesh's cache key.
COACD_SETTINGS = {
    "max_convex_hull": 32,
    "preprocess_mode": "auto",
    "mcts_max_depth": 3,
    "mcts_iterations": 60,
    "seed": 0,
}
MIN_PIECE_MM2 = 0.01  # a band outline's pieces smaller than this are arithmetic specks
# a disconnected blob is dropped with a warning only when it is this small beside the
# largest; otherwise the image holds several objects and we refuse to guess
DOMINANCE_RATIO = 0.05
# an object is 1 mm to 1 m across and at most 1 m thick: outside, the scale or the unit
# is wrong (and the feasibility raster of a larger part would not fit in memory)
SIZE_RANGE_MM = (1.0, 1000.0)
# inputs refused before they are decoded or processed (memory and time)
MAX_IMAGE_PIXELS = 100_000_000
MAX_MESH_FACES = 500_000
MAX_MESH_FILE_BYTES = 256 * 2**20
# the densities of solids: outside the first range a warning, outside the second an
# error (no solid is that light or that dense: the mass, the scale or the unit is wrong)
DENSITY_PLAUSIBLE_KG_M3 = (50.0, 25_000.0)
DENSITY_POSSIBLE_KG_M3 = (1.0, 1_000_000.0)
# a mesh's resting pose by name; or a rotation (world <- mesh file), whose R^T R may differ
# from the identity by a writer's rounding (ROTATION_ROUNDING: projected onto the nearest
# rotation) but not by more (ROTATION_REFUSED, grasp poses' too: a scale, shear or a
# wrong matrix)
POSE_NAMES = ("as_given", "stable")
ROTATION_ROUNDING = 1e-6
ROTATION_REFUSED = ORTHONORMAL_TOL


@dataclasses.dataclass(frozen=True, eq=False)
class ObjectModel:
    """A rigid object ready for scene building and for the geometric checks.

    Attributes:
      name: identifier used in file names and reports.
      polygon: top-down silhouette, mm, object frame (may have holes).
      height_mm: thickness of a prism; the largest height of a mesh.
      mass_kg: mass.
      com_m: (3,) centre of mass in the object frame, m (x = y = 0 by construction).
      inertia_kg_m2: (3, 3) inertia about the centre of mass, object-frame axes.
      mesh: watertight visual/mass mesh in the object frame, m.
      pieces: convex collision pieces, each (V, 3) vertices in the object frame, m.
      pick_height_mm: fingertip height above the table set by the user, or None for
        the grasp-height rule of the procedure (``mjx_pick.core.procedure.fingertip_height_mm``).
      material: the object's material name (recorded with results).
      source: where it came from (file path and import settings).
      outline: a prism's outline its collision pieces were cut from, mm (else None).
      mesh_to_object_m: a mesh's (4, 4) rigid transform from the file's frame, scaled
        to metres, to the object frame: the file's vertices it maps onto ``mesh``'s.
        None for a prism.
      repair: a mesh's repair figures (:meth:`meshrepair.Repair.figures`: faces taken
        out and added, volume, mass or density and their doubt, centre of mass and
        bounds change); None for a prism.
    """

    name: str
    polygon: Polygon
    height_mm: float
    mass_kg: float
    com_m: np.ndarray
    inertia_kg_m2: np.ndarray
    mesh: trimesh.Trimesh
    pieces: tuple[np.ndarray, ...]
    pick_height_mm: float | None
    material: str = "pla"
    source: str = ""
    # prisms only: the outline the pieces were cut from (mm), and the thickness (m)
    outline: Polygon | None = None
    # meshes only: (4, 4) rigid transform, object frame <- the mesh file's frame in metres
    # (after the unit's scale); maps a grasp given in the file's frame into this one
    mesh_to_object_m: np.ndarray | None = None
    # meshes only: what the import's repair changed (meshrepair.Repair.figures)
    repair: dict | None = None

    def __post_init__(self):
        check_name("object", self.name)  # the one name rule, as a gripper's

    def pad_pieces(self, finger_depth_mm: float, finger_width_mm: float) -> tuple[np.ndarray, ...]:
        """Collision pieces for the pads of a finger of this footprint (depth x width).

        A hole no finger can enter never touches a pad, so for a prism it is filled
        before partitioning: every hole vertex is reflex and costs a piece, and every
        piece costs MJX a contact pair per pad. Mass properties and the table contact
        (the convex hull) are unaffected. A hole is kept when its area could hold the
        footprint and it is wider than the finger is deep (conservative: a hole kept
        in doubt only costs speed).
        """
        if self.outline is None or not self.outline.interiors:
            return self.pieces
        kept = [
            h
            for h in self.outline.interiors
            if _finger_may_enter(Polygon(h), finger_depth_mm, finger_width_mm)
        ]
        if len(kept) == len(self.outline.interiors):
            return self.pieces
        filled = Polygon(self.outline.exterior, kept)
        height = float(self.pieces[0][:, 2].max())
        return tuple(_prism(p, height) for p in convex_partition(filled, MAX_PIECE_CORNERS))

    def band_outline(self, z_lo_mm: float, z_hi_mm: float) -> Polygon | MultiPolygon:
        """Top-down outline of the part of the object between two heights, mm.

        What fingers whose pads span z_lo..z_hi can touch or hit: a prism's silhouette
        wherever the band meets it; for a mesh, the projection of its slice (an L-part
        standing on its edge has a narrower outline in a band than its whole shadow).
        A band may cut one solid into several pieces (the prongs of a standing fork
        above its base): all are kept, since a finger can land on any of them. Empty
        when the band misses the object.
        """
        key = (round(float(z_lo_mm), 6), round(float(z_hi_mm), 6))
        cache = self.__dict__.setdefault("_band_cache", {})
        if key not in cache:
            z_lo, z_hi = max(key[0], 0.0), min(key[1], self.height_mm)
            if z_hi <= z_lo:
                cache[key] = Polygon()
            elif self.outline is not None or (z_lo <= 0.0 and z_hi >= self.height_mm):
                cache[key] = self.polygon  # a prism, or the whole height
            else:
                cache[key] = _band_outline(self._mesh_digest(), self.mesh, z_lo, z_hi)
        return cache[key]

    def _mesh_digest(self) -> str:
        """sha256 of the mesh's vertices and faces: the content key of its cached
        outlines and sections (computed once per object)."""
        if "_mesh_sha256" not in self.__dict__:
            m = self.mesh
            self.__dict__["_mesh_sha256"] = cache.digest(
                np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
            )
        return self.__dict__["_mesh_sha256"]

    def wall_height_mm(self, z_lo_mm: float, z_hi_mm: float, slices: int = 24) -> float:
        """Height of the object's side wall within a band, mm: how tall a rigid pad's
        contact patch on it can be.

        A prism's wall is vertical over its whole thickness: the band's overlap with it.
        A curved side (a lying cylinder) touches a flat pad only near its widest
        cross-section: the band is sliced, and the slices whose cross-section is within
        5 % of the widest one (by area; for a cylinder of radius R a strip of 0.62 R,
        close to the contact of a ~1 mm deep rubber pad) count as wall.
        """
        return self.wall_mm(z_lo_mm, z_hi_mm, slices)[0]

    def wall_mm(self, z_lo_mm: float, z_hi_mm: float, slices: int = 24) -> tuple[float, float]:
        """(height, centre height above the table) of the side wall within a band, mm:
        the wall as :meth:`wall_height_mm` counts it, and the mean height of its slices
        (the band's middle where there is no wall)."""
        z_lo, z_hi = max(z_lo_mm, 0.0), min(z_hi_mm, self.height_mm)
        if z_hi <= z_lo:
            return 0.0, 0.5 * (z_lo_mm + z_hi_mm)
        if self.outline is not None:
            return z_hi - z_lo, 0.5 * (z_lo + z_hi)
        zs = np.linspace(z_lo, z_hi, slices + 2)[1:-1]
        areas = cache.memo(
            "sections",
            {"mesh_sha256": self._mesh_digest(), "z_mm": zs.tolist()},
            lambda: {"area_mm2": [_section_area_mm2(self.mesh, z * 1e-3) for z in zs]},
        )["area_mm2"]
        if areas.max() <= 0:
            return 0.0, 0.5 * (z_lo + z_hi)
        wall = np.asarray(areas) >= 0.95 * areas.max()
        return float((z_hi - z_lo) * np.mean(wall)), float(np.mean(zs[wall]))

    @property
    def area_mm2(self) -> float:
        return float(self.polygon.area)

    @property
    def length_mm(self) -> float:
        """Longest side of the silhouette's axis-aligned bounding box."""
        x0, y0, x1, y1 = self.polygon.bounds
        return float(max(x1 - x0, y1 - y0))

    def summary(self) -> dict:
        """Plain-values description for config.json and reports."""
        out = {
            "name": self.name,
            "area_mm2": round(self.area_mm2, 3),
            "height_mm": self.height_mm,
            "mass_g": self.mass_kg * 1e3,
            "pick_height_mm": self.pick_height_mm,
            "bounds_mm": [round(b, 3) for b in self.polygon.bounds],
            "n_holes": len(self.polygon.interiors),
            "n_collision_pieces": len(self.pieces),
            "material": self.material,
            "source": self.source,
            # the silhouette, so that reports can draw it from config.json alone
            "outline_wkt": shapely.to_wkt(self.polygon, rounding_precision=4),
        }
        if self.mesh_to_object_m is not None:  # a grasp in the file's frame maps with it
            out["mesh_to_object_m"] = np.asarray(self.mesh_to_object_m).tolist()
        if self.repair is not None:
            out["repair"] = dict(self.repair)
        return out


# --------------------------------------------------------------------------- images


def segment_image(path: str | os.PathLike) -> np.ndarray:
    """Foreground mask of the one object in a top-down image.

    Handles dark-on-light, light-on-dark (the background is the class that owns the
    image border) and images with an alpha channel.

    Returns:
      (H, W) bool mask of the object (holes are False).
    """
    path = Path(path)
    if not path.is_file():
        raise ConfigError(f"image {str(path)!r} does not exist")
    _check_image_pixels(path)
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    if img is None or img.size == 0:
        raise ConfigError(
            f"image {str(path)!r} cannot be read: use a PNG or JPG "
            "(8- or 16-bit; gray, RGB or RGBA)"
        )
    if img.dtype != np.uint8:
        img = cv2.convertScaleAbs(img, alpha=255.0 / max(float(img.max()), 1.0))
    fg = None
    if img.ndim == 3 and img.shape[2] == 4 and img[..., 3].min() < 128 <= img[..., 3].max():
        fg = img[..., 3] >= 128  # alpha carries the silhouette
    if fg is None:
        gray = img if img.ndim == 2 else cv2.cvtColor(img[..., :3], cv2.COLOR_BGR2GRAY)
        if float(gray.max()) - float(gray.min()) < 16:
            raise ConfigError(f"image {str(path)!r}: no object found (the image has no contrast)")
        _, binary = cv2.threshold(gray, 0, 1, cv2.THRESH_BINARY + cv2.THRESH_OTSU)
        border = np.concatenate([binary[0], binary[-1], binary[:, 0], binary[:, -1]])
        background = 1 if border.mean() >= 0.5 else 0
        fg = binary != background
    # 3x3 open removes isolated noise pixels; close fills pinholes in the object
    kernel = cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (3, 3))
    fg8 = cv2.morphologyEx(fg.astype(np.uint8), cv2.MORPH_OPEN, kernel)
    fg8 = cv2.morphologyEx(fg8, cv2.MORPH_CLOSE, kernel)
    return _single_component(fg8, path)


def _check_image_pixels(path: Path) -> None:
    """Refuse an image of more than MAX_IMAGE_PIXELS from its header, before decoding."""
    size = _image_size(path)
    if size is None:  # unreadable headers are reported by the decoder
        return
    w, h = size
    if w * h > MAX_IMAGE_PIXELS:
        raise ConfigError(
            f"image {str(path)!r} is {w} x {h} pixels: allowed at most "
            f"{MAX_IMAGE_PIXELS / 1e6:g} million; scale it down (and --px-per-mm with it)"
        )


def _image_size(path: Path) -> tuple[int, int] | None:
    """(width, height) from an image file's header, or None where no reader of Pillow's
    takes it. Read as Image.open reads it, less its decompression-bomb refusal, which
    names no size (the size is what the caller refuses, in its own words)."""
    from PIL import Image

    Image.init()
    with path.open("rb") as fh:
        prefix = fh.read(16)
        for fmt in Image.ID:
            factory, accept = Image.OPEN[fmt]
            try:
                if accept is not None and accept(prefix) is not True:
                    continue  # not this format (or a format's note on why not)
                fh.seek(0)
                with factory(fh, str(path)) as im:
                    return tuple(int(v) for v in im.size)
            except Exception:  # noqa: BLE001 - a damaged header: the next reader, or None
                continue
    return None


def _check_size_mm(what: str, extents_mm, hint: str) -> None:
    """Refuse an object outside SIZE_RANGE_MM across (its largest side)."""
    lo, hi = SIZE_RANGE_MM
    size = float(max(extents_mm))
    if not lo <= size <= hi:
        dims = " x ".join(f"{e:.4g}" for e in extents_mm)
        raise ConfigError(
            f"{what} is {dims} mm: allowed {lo:g} mm to {hi / 1e3:g} m across; {hint}"
        )


def _single_component(fg8: np.ndarray, path: Path) -> np.ndarray:
    count, labels, stats, _ = cv2.connectedComponentsWithStats(fg8, connectivity=8)
    if count <= 1:
        raise ConfigError(f"image {str(path)!r}: no object found after segmentation")
    areas = stats[1:, cv2.CC_STAT_AREA]
    order = np.argsort(areas)[::-1]
    largest = int(order[0]) + 1
    if len(order) > 1:
        second = float(areas[order[1]])
        if second > DOMINANCE_RATIO * float(areas[order[0]]):
            raise ConfigError(
                f"image {str(path)!r}: {len(order)} disconnected objects found (largest areas "
                f"{int(areas[order[0]])} and {int(second)} px); crop the image to one object"
            )
        warnings.warn(
            f"image {path.name}: kept the largest object, dropped {len(order) - 1} small "
            f"blob(s) of at most {int(second)} px",
            stacklevel=3,
        )
    x, y, w, h = stats[largest, :4]
    hgt, wid = fg8.shape
    if x == 0 or y == 0 or x + w >= wid or y + h >= hgt:
        raise ConfigError(
            f"image {str(path)!r}: the object touches the image border (bbox x={x}..{x + w}, "
            f"y={y}..{y + h} in a {wid}x{hgt} image); photograph it with a margin"
        )
    return labels == largest


def mask_to_polygon(mask: np.ndarray, px_per_mm: float, simplify_mm: float) -> Polygon:
    """Outer contour and holes of a mask as a polygon in mm (y up), simplified.

    Contours run through boundary pixel *centres*; growing the polygon by half a pixel
    puts its edges on the pixel edges, so areas come out unbiased.
    """
    contours, hierarchy = cv2.findContours(
        mask.astype(np.uint8), cv2.RETR_CCOMP, cv2.CHAIN_APPROX_NONE
    )
    hierarchy = hierarchy[0]
    outer = max(
        (i for i in range(len(contours)) if hierarchy[i][3] == -1),
        key=lambda i: cv2.contourArea(contours[i]),
    )
    holes = [contours[i][:, 0, :] for i in range(len(contours)) if hierarchy[i][3] == outer]
    shell = contours[outer][:, 0, :].astype(float)

    def ring(pts: np.ndarray) -> Polygon:
        return Polygon(pts) if len(pts) >= 3 else Polygon()

    poly_px = shapely.make_valid(ring(shell))
    for hole in holes:
        # a hole contour traces the object pixels around it; shrink by half a pixel
        hole_poly = shapely.make_valid(ring(hole.astype(float)))
        if hole_poly.area > 0:
            poly_px = poly_px.difference(hole_poly)
    poly_px = poly_px.buffer(0.5, join_style="mitre", mitre_limit=2.0)
    poly = shapely.affinity.scale(poly_px, 1.0 / px_per_mm, -1.0 / px_per_mm, origin=(0, 0))
    poly = poly.simplify(simplify_mm, preserve_topology=True)
    return _largest_polygon(shapely.make_valid(poly))


def _polygons(geom) -> list[Polygon]:
    """The polygons of a geometry (a polygon, a multi-polygon or a collection)."""
    if isinstance(geom, Polygon):
        return [geom] if not geom.is_empty else []
    flat = []
    for g in getattr(geom, "geoms", []):
        if isinstance(g, Polygon | MultiPolygon):
            flat.extend(_polygons(g) if isinstance(g, MultiPolygon) else [g])
    return flat


def _largest_polygon(geom) -> Polygon:
    if isinstance(geom, Polygon):
        return orient(geom)
    flat = _polygons(geom)
    if not flat:
        raise ConfigError("the silhouette has no area after simplification")
    return orient(max(flat, key=lambda p: p.area))


def object_from_image(
    path: str | os.PathLike,
    *,
    px_per_mm: float | None,
    thickness_mm: float | None,
    mass_g: float | None = None,
    density_kg_m3: float | None = None,
    simplify_mm: float = 0.3,
    pick_height_mm: float | None = None,
    material: str = "pla",
    name: str | None = None,
) -> ObjectModel:
    """A prism of the silhouette in a top-down image.

    Args:
      path: PNG/JPG, dark-on-light, light-on-dark or with alpha.
      px_per_mm: image scale (required).
      thickness_mm: prism thickness (required).
      mass_g: mass; give this or density_kg_m3.
      density_kg_m3: density, used when mass_g is not given.
      simplify_mm: polygon simplification tolerance.
      pick_height_mm: fingertip height above the table; default: the grasp-height
        rule of the procedure (``GraspConfig.grasp_height``).
      material: material name recorded with the results.
      name: defaults to the file stem.
    """
    if not Path(path).is_file():
        raise ConfigError(f"image {str(path)!r} does not exist")
    if px_per_mm is None:
        raise ConfigError("px_per_mm is required for an image object (pixels per millimetre)")
    if thickness_mm is None:
        raise ConfigError("thickness_mm is required for an image object")
    numbers.check("px_per_mm", px_per_mm)
    numbers.check("thickness_mm", thickness_mm)
    check_range("object", "simplify_mm", simplify_mm, 0, 5)
    label = _label(name, Path(path))
    mask = segment_image(path)
    rows, cols = np.flatnonzero(mask.any(axis=1)), np.flatnonzero(mask.any(axis=0))
    px = (cols[-1] - cols[0] + 1, rows[-1] - rows[0] + 1)
    _check_size_mm(
        f"the object in image {str(path)!r} ({px[0]} x {px[1]} px at px_per_mm={px_per_mm:g})",
        [v / px_per_mm for v in px],
        "check px_per_mm (--px-per-mm), the image's pixels per millimetre",
    )
    polygon = mask_to_polygon(mask, px_per_mm, simplify_mm)
    source = f"{path} (px_per_mm={px_per_mm:g}, simplify_mm={simplify_mm:g})"
    return object_from_polygon(
        polygon,
        thickness_mm=thickness_mm,
        mass_g=mass_g,
        density_kg_m3=density_kg_m3,
        pick_height_mm=pick_height_mm,
        material=material,
        name=label,
        source=source,
    )


def object_from_polygon(
    polygon: Polygon,
    *,
    thickness_mm: float,
    mass_g: float | None = None,
    density_kg_m3: float | None = None,
    pick_height_mm: float | None = None,
    material: str = "pla",
    name: str = "object",
    source: str = "polygon",
    collision_simplify_mm: float = 0.5,
) -> ObjectModel:
    """A prism from a silhouette polygon in mm (any origin; recentred on its centroid).

    collision_simplify_mm is the outline tolerance of the collision pieces (the
    silhouette for the geometric checks keeps the polygon as given).
    """
    numbers.check("thickness_mm", thickness_mm)
    polygon = orient(shapely.make_valid(polygon)) if not polygon.is_valid else orient(polygon)
    if polygon.is_empty or polygon.area <= 0:
        raise ConfigError(f"object {name!r}: the silhouette has no area")
    x0, y0, x1, y1 = polygon.bounds
    _check_size_mm(f"object {name!r}'s silhouette", [x1 - x0, y1 - y0], "check its scale")
    c = polygon.centroid
    polygon = shapely.affinity.translate(polygon, -c.x, -c.y)
    mesh = trimesh.creation.extrude_polygon(
        shapely.affinity.scale(polygon, 1e-3, 1e-3, origin=(0, 0)), thickness_mm * 1e-3
    )
    if not mesh.is_watertight:
        raise ConfigError(f"object {name!r}: extrusion is not watertight (self-touching outline?)")
    mass_kg = _mass_kg(name, mesh.volume, mass_g, density_kg_m3)
    # collision pieces come from a coarser outline: every hole vertex is reflex and
    # costs a piece, and every piece costs MJX three contact pairs
    coarse = polygon.simplify(max(collision_simplify_mm, 0.0), preserve_topology=True)
    pieces = tuple(
        _prism(piece, thickness_mm * 1e-3) for piece in convex_partition(coarse, MAX_PIECE_CORNERS)
    )
    obj = _finish(
        name, polygon, thickness_mm, mass_kg, mesh, pieces, pick_height_mm, material, source
    )
    return dataclasses.replace(obj, outline=coarse)


def _finger_may_enter(hole: Polygon, depth_mm: float, width_mm: float) -> bool:
    if hole.area < depth_mm * width_mm:
        return False
    radius = shapely.maximum_inscribed_circle(hole, tolerance=0.05).length
    return 2.0 * radius >= depth_mm


def _label(name: str | None, path: Path) -> str:
    """An object's name: the one given, else its file's name without the suffix --
    checked by the name rule now, before the file is read or prepared."""
    if name is not None:
        check_name("object", name)
        return name
    try:
        check_name("object", path.stem)
    except ConfigError as err:
        raise ConfigError(
            f"{str(path)!r}: an object is named after its file: {err}; rename the file"
        ) from None
    return path.stem


def _mass_kg(name: str, volume_m3: float, mass_g: float | None, density: float | None) -> float:
    if mass_g is None and density is None:
        raise ConfigError(f"object {name!r}: give mass_g or density_kg_m3")
    if mass_g is not None and density is not None:
        raise ConfigError(
            f"object {name!r}: mass_g = {mass_g:g} and density_kg_m3 = {density:g} are both "
            "given: give one (--mass-g or --density-kg-m3); the other follows from the volume"
        )
    if mass_g is not None:
        check_range("object", "mass_g", mass_g, 0, lo_open=True)
        mass_kg = mass_g * 1e-3
        given = f"mass_g = {mass_g:g} in {volume_m3 * 1e9:.4g} mm^3 is a density of "
        fix = "check mass_g (--mass-g) and the size (the scale or unit)"
    else:
        check_range("object", "density_kg_m3", density, 0, lo_open=True)
        mass_kg = density * volume_m3
        given = "density_kg_m3 = "
        fix = "check density_kg_m3 (--density-kg-m3)"
    rho = mass_kg / volume_m3
    lo, hi = DENSITY_POSSIBLE_KG_M3
    if not lo <= rho <= hi:
        raise ConfigError(
            f"object {name!r}: {given}{rho:.5g} kg/m^3; no solid is (allowed {lo:g} to "
            f"{hi:g} kg/m^3): {fix}"
        )
    lo, hi = DENSITY_PLAUSIBLE_KG_M3
    if not lo <= rho <= hi:
        warnings.warn(
            f"object {name!r}: {given}{rho:.5g} kg/m^3, outside the solids' "
            f"{lo:g}-{hi:g} kg/m^3: {fix}",
            PlausibilityWarning,
            stacklevel=3,
        )
    return mass_kg


def _finish(name, polygon, height_mm, mass_kg, mesh, pieces, pick_height_mm, material, source):
    mesh = mesh.copy()
    mesh.density = mass_kg / mesh.volume
    com = np.asarray(mesh.center_mass, dtype=float)
    inertia = np.asarray(mesh.moment_inertia, dtype=float)  # about the centre of mass
    if pick_height_mm is not None:
        check_range("object", "pick_height_mm", pick_height_mm, 0, height_mm, lo_open=True)
        pick_height_mm = float(pick_height_mm)
    return ObjectModel(
        name=name,
        polygon=polygon,
        height_mm=float(height_mm),
        mass_kg=float(mass_kg),
        com_m=com,
        inertia_kg_m2=inertia,
        mesh=mesh,
        pieces=pieces,
        pick_height_mm=pick_height_mm,
        material=material,
        source=source,
    )


def _prism(corners_mm: np.ndarray, height_m: float) -> np.ndarray:
    xy = np.asarray(corners_mm, dtype=float) * 1e-3
    bottom = np.column_stack([xy, np.zeros(len(xy))])
    top = np.column_stack([xy, np.full(len(xy), height_m)])
    return np.vstack([bottom, top])


# ----------------------------------------------------------- exact convex partition


def convex_partition(polygon: Polygon, max_corners: int = MAX_PIECE_CORNERS) -> list[np.ndarray]:
    """Split a polygon (holes allowed) into convex pieces of at most max_corners corners.

    Triangulates (earcut) and greedily removes diagonals while the merged piece stays
    convex and small enough (Hertel-Mehlhorn): at most 4x the optimal piece count, and
    exact -- the union of the pieces is the polygon.

    Returns:
      list of (k, 2) counter-clockwise corner arrays, mm.
    """
    verts, faces = trimesh.creation.triangulate_polygon(polygon, engine="earcut")
    verts = np.asarray(verts, dtype=float)
    pieces: list[list[int]] = []
    for f in faces:
        a, b, c = (int(i) for i in f)
        if _cross(verts[a], verts[b], verts[c]) < 0:
            b, c = c, b
        if abs(_cross(verts[a], verts[b], verts[c])) > 1e-12:
            pieces.append([a, b, c])
    # merge across the diagonal that yields the largest convex piece first: fewer,
    # fatter pieces than a first-come order (fewer contact pairs for MJX)
    while True:
        edge_owner: dict[tuple[int, int], int] = {}
        for pi, cyc in enumerate(pieces):
            for k in range(len(cyc)):
                edge_owner[(cyc[k], cyc[(k + 1) % len(cyc)])] = pi
        best = None
        for (u, v), pi in edge_owner.items():
            pj = edge_owner.get((v, u))
            if pj is None or pj <= pi:
                continue
            cand = _drop_collinear(_merge(pieces[pi], pieces[pj], u, v), verts)
            if len(cand) <= max_corners and _is_convex(cand, verts):
                area = _area(cand, verts)
                if best is None or area > best[0]:
                    best = (area, pi, pj, cand)
        if best is None:
            break
        _, pi, pj, cand = best
        pieces = [p for k, p in enumerate(pieces) if k not in (pi, pj)] + [cand]
    return [verts[p] for p in pieces]


def _area(cyc: list[int], verts: np.ndarray) -> float:
    pts = verts[cyc]
    return 0.5 * float(
        np.dot(pts[:, 0], np.roll(pts[:, 1], -1)) - np.dot(pts[:, 1], np.roll(pts[:, 0], -1))
    )


def _cross(o, a, b) -> float:
    return float((a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0]))


def _merge(p: list[int], q: list[int], u: int, v: int) -> list[int]:
    """Join cycles p (has edge u->v) and q (has edge v->u) along that edge."""
    i = p.index(u)
    p_rot = p[i + 1 :] + p[: i + 1]  # ends with u, starts with v
    j = q.index(v)
    q_rot = q[j + 1 :] + q[: j + 1]  # ends with v, starts with u
    return p_rot[:-1] + [u] + q_rot[1:-1]


def _drop_collinear(cyc: list[int], verts: np.ndarray) -> list[int]:
    out = []
    n = len(cyc)
    for k in range(n):
        a, b, c = verts[cyc[k - 1]], verts[cyc[k]], verts[cyc[(k + 1) % n]]
        scale = max(np.linalg.norm(b - a) * np.linalg.norm(c - b), 1e-18)
        if abs(_cross(a, b, c)) / scale > 1e-9:
            out.append(cyc[k])
    return out


def _is_convex(cyc: list[int], verts: np.ndarray) -> bool:
    n = len(cyc)
    if n < 3:
        return False
    for k in range(n):
        if _cross(verts[cyc[k - 1]], verts[cyc[k]], verts[cyc[(k + 1) % n]]) < -1e-12:
            return False
    return True


# --------------------------------------------------------------------------- meshes


def object_from_mesh(
    path: str | os.PathLike,
    *,
    unit: str,
    mass_g: float | None = None,
    density_kg_m3: float | None = None,
    pose: str | np.ndarray = "as_given",
    pick_height_mm: float | None = None,
    material: str = "pla",
    name: str | None = None,
    coacd_threshold: float = 0.04,
    largest_body: bool = False,
    repair_volume_pct: float = meshrepair.VOLUME_PCT,
    repair_com_mm: float = meshrepair.COM_MM,
    repair_bounds_mm: float = meshrepair.BOUNDS_MM,
) -> ObjectModel:
    """An object from a mesh file (STL/OBJ/PLY/GLB), resting on the table.

    Args:
      path: mesh file readable by trimesh.
      unit: "m" or "mm", the unit the file's coordinates are in (required).
      mass_g / density_kg_m3: one of them.
      pose: "as_given" (keep the file's orientation, z up), "stable" (the most
        probable resting pose, trimesh.poses.compute_stable_poses), or the part's
        orientation on the table: a (3, 3) rotation or (4, 4) rigid transform, world <-
        mesh file frame (:func:`check_pose`; only its rotation is used). Either way the
        part is set on the table with its centre of mass over the origin, and
        ``mesh_to_object_m`` records the whole transform.
      pick_height_mm: fingertip height; default: the procedure's grasp-height rule.
      coacd_threshold: CoACD concavity threshold (smaller keeps finer concave detail).
      largest_body: a mesh of several disconnected bodies is refused (the outline,
        the feasibility checks and the physics must see the same solid); True keeps
        the largest body (with its inner voids) and drops the others with a warning.
      repair_volume_pct / repair_com_mm / repair_bounds_mm: how much the repair of a
        surface that is not a closed solid may change it (:class:`meshrepair.Tolerance`:
        volume in doubt, %; centre of mass, mm; bounds, mm); beyond, it is refused.
    """
    path = Path(path)
    label = _label(name, path)
    pose = check_pose(pose)
    tolerance = meshrepair.Tolerance(repair_volume_pct, repair_com_mm, repair_bounds_mm)
    _check_mesh_file(path, unit)
    if mass_g is None and density_kg_m3 is None:  # before any work
        raise ConfigError(f"object {label!r}: give mass_g or density_kg_m3")

    def check(rep: meshrepair.Repair) -> None:  # before the decomposition, and when cached
        v = rep.volume_mm3 * 1e-9
        rho = density_kg_m3 if density_kg_m3 is not None else mass_g * 1e-3 / v
        tolerance.check(path, rep, rho, density_kg_m3 is not None)

    prepared = _prepared_mesh(path, unit, pose, coacd_threshold, largest_body, check)
    rep = meshrepair.Repair.from_json(prepared["repair_json"].tobytes().decode())
    check(rep)
    dropped = prepared["dropped_note"].tobytes().decode()
    if dropped:  # bodies left out by largest_body: said on every load
        warnings.warn(dropped, stacklevel=2)
    # rebuilt from the arrays whether they were read or computed: one path, same bits
    mesh = trimesh.Trimesh(prepared["vertices"], prepared["faces"], process=False)
    height_mm = float(mesh.bounds[1, 2] * 1e3)
    mass_kg = _mass_kg(label, mesh.volume, mass_g, density_kg_m3)
    rho = mass_kg / mesh.volume
    if rep.changed:  # said on every load, cached or not: the run's log has it
        said = log.warning if rep.volume_doubt_mm3 or rep.bounds_change_mm else log.info
        said("mesh %s repaired: %s", path.name, rep.describe(rho, density_kg_m3 is not None))
    figures = rep.figures(mass_kg, rho, density_kg_m3 is not None)
    polygon = shapely.from_wkb(prepared["outline_wkb"].tobytes())
    ends = np.cumsum(prepared["piece_sizes"])[:-1]
    pieces = tuple(np.split(prepared["piece_vertices"], ends))
    shown = pose if isinstance(pose, str) else _matrix_text(pose)
    source = f"{path} (unit={unit}, pose={shown}{', largest_body' if largest_body else ''})"
    obj = _finish(
        label, polygon, height_mm, mass_kg, mesh, pieces, pick_height_mm, material, source
    )
    return dataclasses.replace(
        obj, mesh_to_object_m=prepared["mesh_to_object"].copy(), repair=figures
    )


MESH_SCALES = {"m": 1.0, "mm": 1e-3}


def check_pose(pose) -> str | np.ndarray:
    """A mesh's resting pose as :func:`object_from_mesh` takes it, checked: "as_given",
    "stable", or a rotation -- returned as a (3, 3) float64 proper rotation, projected
    onto the nearest one (SVD) where a writer's rounding left it up to ROTATION_REFUSED
    from orthonormal.

    Args:
      pose: a name, or array-like (3, 3) rotation or (4, 4) rigid transform, world <-
        mesh file frame (a 4x4's translation is not used: the part is set on the table).
    """
    if isinstance(pose, str):
        if pose in POSE_NAMES:
            return pose
        raise _pose_error(repr(pose), "not a pose's name")
    try:
        m = np.array(pose, dtype=np.float64)
    except (TypeError, ValueError):
        raise _pose_error(repr(pose), "not a matrix of numbers") from None
    shown = _matrix_text(m) if m.ndim == 2 and m.size <= 16 else repr(pose)
    if m.shape not in ((3, 3), (4, 4)):
        raise _pose_error(shown, f"its shape is {m.shape}")
    if not np.isfinite(m).all():
        raise _pose_error(shown, "it holds a NaN or an infinity")
    if m.shape == (4, 4) and np.abs(m[3] - [0.0, 0.0, 0.0, 1.0]).max() > ROTATION_ROUNDING:
        raise _pose_error(shown, f"its last row is {_matrix_text(m[3])}, not [0, 0, 0, 1]")
    r = m[:3, :3]
    det = float(np.linalg.det(r))
    if det <= 0:
        what = "a mirror image of the part" if det < 0 else "a singular matrix"
        raise _pose_error(shown, f"its rotation's determinant is {det:.6g} ({what}), not +1")
    off = float(np.abs(r.T @ r - np.eye(3)).max())
    if off > ROTATION_REFUSED:
        raise _pose_error(
            shown,
            f"its rotation is not orthonormal (R^T R is {off:.3g} from the identity; "
            f"allowed {ROTATION_REFUSED:g}: a scale or shear?)",
        )
    return nearest_rotation(r)  # rounding removed, rigid


def _pose_error(shown: str, why: str) -> ConfigError:
    return ConfigError(
        f"object.pose = {shown} is not allowed: {why}; choose 'as_given', 'stable', or the "
        "part's orientation as a 3x3 rotation or 4x4 rigid transform (world <- mesh file "
        f"frame: orthonormal within {ROTATION_REFUSED:g}, determinant +1; a 4x4's last row "
        "0 0 0 1)"
    )


def _matrix_text(m: np.ndarray) -> str:
    """A small vector or matrix on one line, its numbers to 6 significant digits."""
    m = np.asarray(m)
    if m.ndim == 1:
        return "[" + ", ".join(f"{float(v):.6g}" for v in m) + "]"
    return "[" + ", ".join(_matrix_text(row) for row in m) + "]"


def _check_mesh_file(path: Path, unit: str) -> None:
    """Refuse, before any load, a unit that is not allowed and a mesh file that is
    missing, too large or (by its header) holds too many triangles or is cut short."""
    if unit not in MESH_SCALES:
        raise ConfigError(f"object.unit = {unit!r} is not allowed: choose 'm' or 'mm'")
    if not path.is_file():
        raise ConfigError(f"mesh {str(path)!r} does not exist")
    size = path.stat().st_size
    if size > MAX_MESH_FILE_BYTES:
        raise ConfigError(
            f"mesh {str(path)!r} is a {size / 2**20:.0f} MiB file: allowed at most "
            f"{MAX_MESH_FILE_BYTES / 2**20:.0f} MiB; simplify it (fewer triangles)"
        )
    _check_mesh_header(path, size)  # a count or a cut its header shows: before any load


def _prepared_mesh(
    path: Path,
    unit: str,
    pose: str | np.ndarray,
    coacd_threshold: float,
    largest_body: bool,
    check,
) -> dict[str, np.ndarray]:
    """The mesh file's prepared geometry (:func:`_prepare_mesh`'s arrays), read from the
    on-disk cache when this file was prepared alike before, else computed and stored.
    pose: :func:`check_pose`'s; check: refuses a repair (not part of the key: the
    caller checks a cached one again)."""
    # everything that decides the prepared geometry; mass and material are applied after
    key = {
        # the arrays' layout: older entries lack mesh_to_object (1) or repair_json (2)
        "layout": 3,
        "file_sha256": cache.file_digest(path),
        "suffix": path.suffix.lower(),
        "unit": unit,
        "pose": pose if isinstance(pose, str) else pose.tolist(),
        "coacd_threshold": float(coacd_threshold),
        "max_hull_vertices": MAX_HULL_VERTICES,
        "coacd": dict(COACD_SETTINGS),
        "largest_body": bool(largest_body),
    }
    return cache.memo(
        "mesh",
        key,
        lambda: _prepare_mesh(path, unit, pose, coacd_threshold, largest_body, check),
    )


def _check_mesh_header(path: Path, size: int) -> None:
    """Refuse, from its first bytes, a mesh file that holds too many triangles or is cut
    short: a binary STL's header gives its triangle count (and so its length), a PLY's
    its face count -- found before a load that may take gigabytes and minutes."""
    suffix = path.suffix.lower()
    with path.open("rb") as fh:
        head = fh.read(4096)
    count = None
    if suffix == ".stl" and len(head) >= 84:
        n = int(np.frombuffer(head[80:84], "<u4")[0])
        binary = not head.lstrip()[:5].lower().startswith(b"solid") or size == 84 + 50 * n
        if binary and _is_text(head):
            # a binary STL's count has NUL bytes below 16.7 million triangles, and its
            # triangles' floats have more: this "count" is four letters of text
            start = head[:40].decode("utf-8", "replace").split("\n")[0].strip()
            raise ConfigError(
                f"mesh {str(path)!r} is not an STL: it holds text, and an ASCII STL begins "
                f"with 'solid' (this one begins {start!r}); export the mesh again as STL"
            )
        if binary:
            if size < 84 + 50 * n:
                raise ConfigError(
                    f"mesh {str(path)!r} is cut short: its header says {n:,} triangles "
                    f"({84 + 50 * n:,} bytes), the file has {size:,} bytes; export it again"
                )
            count = n
    elif suffix == ".ply":
        header = head.split(b"end_header", 1)[0].decode("ascii", "replace")
        for line in header.splitlines():
            parts = line.split()
            if parts[:2] == ["element", "face"] and len(parts) == 3 and parts[2].isdigit():
                count = int(parts[2])
    if count is not None and count > MAX_MESH_FACES:
        raise ConfigError(
            f"mesh {str(path)!r} has {count} triangles: allowed at most {MAX_MESH_FACES}; "
            "decimate it (e.g. MeshLab's quadric edge collapse, or trimesh's "
            "simplify_quadric_decimation) to a few ten thousand"
        )


def _is_text(head: bytes) -> bool:
    """Whether a file's first bytes are UTF-8 text (no NUL byte, no invalid sequence
    except one a 4096-byte cut may have split)."""
    if b"\0" in head:
        return False
    try:
        head.decode("utf-8")
    except UnicodeDecodeError as err:
        return err.start >= len(head) - 3  # a character cut at the end
    return True


def _prepare_mesh(
    path: Path,
    unit: str,
    pose: str | np.ndarray,
    coacd_threshold: float,
    largest_body: bool,
    check,
) -> dict:
    """A mesh file's geometry in the object frame: the cached part of object_from_mesh.

    Returns arrays: vertices (V, 3) m and faces (F, 3) of the watertight mesh, resting on
    the table with its centre of mass over the origin; mesh_to_object (4, 4), the rigid
    transform that took the file's vertices (m) there; repair_json, what the repair
    changed (:class:`meshrepair.Repair`, refused by check before the decomposition
    when beyond its tolerances); outline_wkb, the top-down outline
    (mm) as WKB bytes; piece_vertices (sum V_i, 3) m and piece_sizes (P,), the convex
    collision pieces one after the other.
    """
    try:
        log.info("reading mesh %s ...", path.name)
        mesh = trimesh.load(str(path), force="mesh", process=True)
    except Exception as err:  # noqa: BLE001 - trimesh raises many types for bad files
        # trimesh's own failures name its internals (a missing optional module for text
        # it could not decode): the user needs to know the file is not a mesh it reads
        why = "a damaged or truncated file?" if isinstance(err, ImportError) else str(err)
        raise ConfigError(f"mesh {str(path)!r} cannot be read as a mesh ({why})") from err
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ConfigError(f"mesh {str(path)!r} holds no triangles")
    if len(mesh.faces) > MAX_MESH_FACES:
        raise ConfigError(
            f"mesh {str(path)!r} has {len(mesh.faces)} triangles: allowed at most "
            f"{MAX_MESH_FACES}; decimate it (e.g. MeshLab's quadric edge collapse, or "
            "trimesh's simplify_quadric_decimation) to a few ten thousand"
        )
    mesh.apply_scale(MESH_SCALES[unit])
    mesh, rep = meshrepair.repair(mesh, path)
    check(rep)
    mesh, dropped = _one_body(mesh, path, largest_body)
    # one transform, applied once: the file's vertices map onto the model's exactly
    mesh_to_object = _resting_transform(mesh, pose)
    mesh.apply_transform(mesh_to_object)
    _check_size_mm(
        f"mesh {str(path)!r} with unit={unit!r}",
        mesh.extents * 1e3,
        "check the unit (--unit m or mm)",
    )
    log.info("%s: top-down outline of %d triangles ...", path.name, len(mesh.faces))
    polygon = _mesh_outline(mesh, 0.0, float(mesh.bounds[1, 2]))
    log.info("%s: convex decomposition for collisions (CoACD) ...", path.name)
    pieces = _coacd_pieces(mesh, coacd_threshold)
    return {
        "vertices": np.asarray(mesh.vertices, dtype=np.float64),
        "faces": np.asarray(mesh.faces, dtype=np.int64),
        "mesh_to_object": mesh_to_object,
        "outline_wkb": np.frombuffer(shapely.to_wkb(polygon), np.uint8),
        "piece_vertices": np.concatenate(pieces).astype(np.float64),
        "piece_sizes": np.array([len(p) for p in pieces], np.int64),
        "dropped_note": np.frombuffer(dropped.encode(), np.uint8),
        "repair_json": np.frombuffer(rep.to_json().encode(), np.uint8),
    }


def _resting_transform(mesh: trimesh.Trimesh, pose: str | np.ndarray) -> np.ndarray:
    """(4, 4) rigid transform, object frame <- mesh (m): the pose's turn (none, the most
    stable resting pose, or the given rotation), then the shift that sets the turned
    part on the table (z = 0) with its centre of mass over the origin."""
    turn = np.eye(4)
    if isinstance(pose, str):
        if pose == "stable":
            transforms, _ = trimesh.poses.compute_stable_poses(mesh, n_samples=1, sigma=0.0)
            turn[:3, :3] = transforms[0][:3, :3]  # its translation is replaced below
    else:
        turn[:3, :3] = pose
    turned = mesh.copy()
    turned.apply_transform(turn)
    com = turned.center_mass
    shift = np.eye(4)
    shift[:3, 3] = [-com[0], -com[1], -turned.bounds[0, 2]]
    return shift @ turn


def _one_body(mesh: trimesh.Trimesh, path: Path, largest_body: bool) -> tuple[trimesh.Trimesh, str]:
    """(the mesh, "") if it is one connected solid; else an error naming its bodies, or,
    with largest_body, (the largest body and the voids inside it, the note that says
    what was dropped) -- a note the caller warns with on every load, cached or not.

    A closed shell inside a body with inward normals is a void of it, not a body of its
    own: a hollow part is one body (``meshrepair.shells`` refuses shells that cross, a
    body turned inside out and a body inside another).
    """
    bodies, voids = meshrepair.shells(mesh, path)
    if len(bodies) <= 1:
        return mesh, ""
    bodies.sort(key=lambda s: s.volume, reverse=True)
    vols = ", ".join(f"{b.volume * 1e9:.6g}" for b in bodies[:6])
    more = " ..." if len(bodies) > 6 else ""
    if not largest_body:
        raise ConfigError(
            f"mesh {str(path)!r} holds {len(bodies)} disconnected bodies (volumes {vols}{more} "
            "mm^3); the outline, the feasibility checks and the physics need one solid: join "
            "them in CAD (a boolean union or a bridge), or keep the largest with "
            "--largest-body (largest_body=True)"
        )
    kept = bodies[0]
    inside = [v for v in voids if bool(kept.contains(v.vertices[:1])[0])]
    note = (
        f"mesh {path.name}: kept the largest of {len(bodies)} disconnected bodies "
        f"({kept.volume * 1e9:.6g} mm^3), dropped {len(bodies) - 1} of volumes "
        f"{', '.join(f'{b.volume * 1e9:.6g}' for b in bodies[1:6])}{more} mm^3"
    )
    return (trimesh.util.concatenate([kept, *inside]) if inside else kept), note


def _mesh_outline(
    mesh: trimesh.Trimesh, z_lo_m: float, z_hi_m: float, pieces: bool = False
) -> Polygon | MultiPolygon:
    """Top-down outline (mm) of the part of a watertight mesh between two heights (m).

    The shadow of a solid is the union of its triangles' shadows. That union is taken
    directly, because trimesh's projected outline came apart into dozens of slivers on
    real scanned meshes (a YCB marker kept a third of its length). The band's part is
    the mesh cut by two capped planes.

    pieces: keep every piece of the shadow (a band of one solid can cut it in several:
    the two prongs of a standing fork above its base), dropping only specks of less
    than MIN_PIECE_MM2 left by the union's arithmetic; else the largest piece (the whole
    height of one connected solid casts one shadow).
    """
    part = mesh
    lo, hi = mesh.bounds[:, 2]
    if z_lo_m > lo + 1e-9:
        part = part.slice_plane([0, 0, z_lo_m], [0, 0, 1], cap=True)
    if z_hi_m < hi - 1e-9 and part is not None and len(part.faces):
        part = part.slice_plane([0, 0, z_hi_m], [0, 0, -1], cap=True)
    if part is None or not len(part.faces):
        return Polygon()
    tri = np.asarray(part.triangles)[:, :, :2] * 1e3
    # drop triangles seen edge-on (vertical walls): their shadow has no area
    u, v = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    area = 0.5 * np.abs(u[:, 0] * v[:, 1] - u[:, 1] * v[:, 0])
    shadows = shapely.polygons(tri[area > 1e-9])
    # a hair of growth closes the cracks between neighbouring triangles' shadows
    union = shapely.make_valid(shapely.union_all(shapely.buffer(shadows, 1e-4)).buffer(-1e-4))
    if not pieces:
        return _largest_polygon(union)
    kept = [p for p in _polygons(union) if p.area >= MIN_PIECE_MM2]
    if not kept:
        return Polygon()
    return orient(kept[0]) if len(kept) == 1 else MultiPolygon([orient(p) for p in kept])


def _band_outline(mesh_sha256: str, mesh: trimesh.Trimesh, z_lo_mm: float, z_hi_mm: float):
    """_mesh_outline of a band (mm), through the on-disk cache (key: the mesh's content)."""
    arrays = cache.memo(
        "outline",
        # "pieces": every piece is kept (older entries held the largest alone)
        {"mesh_sha256": mesh_sha256, "z_lo_mm": z_lo_mm, "z_hi_mm": z_hi_mm, "pieces": "all"},
        lambda: {
            "wkb": np.frombuffer(
                shapely.to_wkb(_mesh_outline(mesh, z_lo_mm * 1e-3, z_hi_mm * 1e-3, pieces=True)),
                np.uint8,
            )
        },
    )
    return shapely.from_wkb(arrays["wkb"].tobytes())


def _section_area_mm2(mesh: trimesh.Trimesh, z_m: float) -> float:
    """Area of a mesh's horizontal cross-section at height z_m, mm^2 (0 if none)."""
    section = mesh.section(plane_origin=[0, 0, z_m], plane_normal=[0, 0, 1])
    if section is None:
        return 0.0
    planar, _ = section.to_2D()
    return float(sum(p.area for p in planar.polygons_full)) * 1e6


def _coacd_pieces(mesh: trimesh.Trimesh, threshold: float) -> tuple[np.ndarray, ...]:
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(
        coacd.Mesh(np.asarray(mesh.vertices), np.asarray(mesh.faces)),
        threshold=threshold,
        **COACD_SETTINGS,
    )
    pieces = []
    for verts, faces in parts:
        hull = trimesh.Trimesh(verts, faces).convex_hull
        v = np.asarray(hull.vertices, dtype=float)
        if len(v) > MAX_HULL_VERTICES:
            v = _reduce_hull(v, MAX_HULL_VERTICES)
        pieces.append(v)
    return tuple(pieces)


def _reduce_hull(v: np.ndarray, k: int) -> np.ndarray:
    """Keep k hull vertices spread by farthest-point sampling (a slightly smaller hull)."""
    chosen = [int(np.argmax(np.linalg.norm(v - v.mean(0), axis=1)))]
    dist = np.linalg.norm(v - v[chosen[0]], axis=1)
    while len(chosen) < k:
        nxt = int(np.argmax(dist))
        chosen.append(nxt)
        dist = np.minimum(dist, np.linalg.norm(v - v[nxt], axis=1))
    return v[chosen]


def rasterize(
    polygon: Polygon,
    mm_per_px: float,
    yaw_rad: float = 0.0,
    pad_px: int = 2,
    radius_mm: float | None = None,
):
    """Rasterize a (rotated) polygon on a grid centred on the object origin.

    radius_mm: the grid's half size before padding (default: the polygon's largest
    distance from the origin). Give it to get one grid size for every yaw: the rotated
    corners' distances differ in the last bits, and ceil() can turn that into a pixel.

    Pixel (i, j) covers x in [x0 + j*s, x0 + (j+1)*s), y in [y0 + i*s, ...) (row = +y);
    a pixel is object when its centre is inside (:func:`rasterize_window`).

    Returns:
      mask (H, W) uint8 and (x0, y0) of the grid's lower-left corner, mm.
    """
    window, corner, (row0, col0), size = rasterize_window(
        polygon, mm_per_px, yaw_rad, pad_px, radius_mm
    )
    mask = np.zeros((size, size), np.uint8)
    mask[row0 : row0 + window.shape[0], col0 : col0 + window.shape[1]] = window
    return mask, corner


def rasterize_window(
    polygon: Polygon,
    mm_per_px: float,
    yaw_rad: float = 0.0,
    pad_px: int = 2,
    radius_mm: float | None = None,
):
    """:func:`rasterize`'s grid, computed and returned only where the rotated polygon's
    bounding box lies (the rest of the grid is empty).

    Scan lines: along each row's centre line, the crossings of the outline's edges
    (every ring, holes too) toggle inside/outside -- the even-odd rule, which is shapely's
    ``contains_xy`` on every centre, at a fraction of its cost; a centre on the outline
    is outside, as shapely has it.

    Returns:
      window (h, w) uint8: the grid's rows row0 .. row0 + h - 1 and columns col0 ..
      col0 + w - 1; (x0, y0), the whole grid's lower-left corner, mm; (row0, col0); the
      whole grid's side, cells.
    """
    rot = shapely.affinity.rotate(polygon, yaw_rad, origin=(0, 0), use_radians=True)
    if radius_mm is None:  # one piece or several
        radius_mm = float(np.hypot(*shapely.get_coordinates(rot).T).max())
    half = int(math.ceil(radius_mm / mm_per_px)) + pad_px
    x0 = y0 = -half * mm_per_px
    n = 2 * half
    centres = x0 + (np.arange(n) + 0.5) * mm_per_px
    edges = _outline_edges(rot)
    if edges is None:
        return np.zeros((0, 0), np.uint8), (x0, y0), (0, 0), n
    a, b = edges
    # the window: the centres within the outline's bounds
    (xmin, ymin), (xmax, ymax) = np.minimum(a, b).min(axis=0), np.maximum(a, b).max(axis=0)
    r0, r1 = np.searchsorted(centres, ymin, "left"), np.searchsorted(centres, ymax, "right")
    c0, c1 = np.searchsorted(centres, xmin, "left"), np.searchsorted(centres, xmax, "right")
    mask = _scan_window(a, b, centres, (r0, r1), (c0, c1))
    return mask, (x0, y0), (int(r0), int(c0)), n


def _outline_edges(polygon) -> tuple[np.ndarray, np.ndarray] | None:
    """Every edge of the outline's rings (holes too) as (a, b): (E, 2) start and end
    points, mm; None when the outline has no points."""
    rings = [r for p in shapely.get_parts(polygon) for r in (p.exterior, *p.interiors)]
    ends = [shapely.get_coordinates(r) for r in rings]
    if not ends or not len(np.concatenate(ends)):
        return None
    a = np.concatenate([e[:-1] for e in ends])  # each edge from a to b
    b = np.concatenate([e[1:] for e in ends])
    return a, b


def _scan_window(a, b, centres, rows, cols) -> np.ndarray:
    """The window's mask by the even-odd rule on each row's centre line: (h, w) uint8,
    1 where a cell's centre lies inside the edges a -> b ((E, 2), mm). centres: the
    grid's cell centres along x and y, mm; rows, cols: the window's (first, end) cells."""
    (r0, r1), (c0, c1) = rows, cols
    h, w = int(r1 - r0), int(c1 - c0)
    # rows whose centre line an edge crosses: min(ya, yb) <= yc < max(ya, yb), so that a
    # vertex on a centre line counts once and a horizontal edge not at all
    first = np.searchsorted(centres, np.minimum(a[:, 1], b[:, 1]), "left")
    rows_of = np.searchsorted(centres, np.maximum(a[:, 1], b[:, 1]), "left") - first
    edge = np.repeat(np.arange(len(a)), rows_of)
    row = np.arange(len(edge)) + np.repeat(first - (np.cumsum(rows_of) - rows_of), rows_of)
    (xa, ya), (xb, yb) = a[edge].T, b[edge].T
    x = xa + (centres[row] - ya) * (xb - xa) / (yb - ya)
    # a crossing toggles every pixel whose centre lies right of it (window columns from
    # its first, col - c0 in [0, w])
    col = np.searchsorted(centres, x, "right")
    at = (row - r0) * (w + 1) + (col - c0)
    toggles = np.bincount(at, minlength=h * (w + 1)).astype(np.uint8)
    mask = np.cumsum(toggles.reshape(h, w + 1)[:, :w], axis=1, dtype=np.uint8)
    mask &= 1  # the parity of the crossings to the left (a uint8 sum wraps: parity kept)
    # a centre on the outline is outside (as shapely says): on a crossing, or on a
    # horizontal edge lying on its row's centre line (axis-aligned edges at yaw 0 and
    # 90 degrees meet centres exactly)
    on = col - 1
    hit = (on >= c0) & (centres[np.maximum(on, 0)] == x)
    mask[row[hit] - r0, on[hit] - c0] = 0
    flat = (a[:, 1] == b[:, 1]) & np.isin(a[:, 1], centres)
    for (xa, y), (xb, _) in zip(a[flat], b[flat], strict=True):
        lo = np.searchsorted(centres, min(xa, xb), "left") - c0
        hi = np.searchsorted(centres, max(xa, xb), "right") - c0
        mask[np.searchsorted(centres, y) - r0, lo:hi] = 0
    return mask


# --------------------------------------------------------------------------- assets

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")
MESH_SUFFIXES = (".stl", ".obj", ".ply", ".glb", ".gltf", ".off")


def asset_manifest() -> dict:
    """The shipped objects' manifest (assets/objects/manifest.toml)."""
    import tomllib
    from importlib import resources

    text = (resources.files("mjx_pick.assets") / "objects" / "manifest.toml").read_text()
    return tomllib.loads(text)


def asset_names() -> list[str]:
    """Names of the shipped test objects."""
    return sorted(asset_manifest())


def load_asset(name: str, **overrides) -> ObjectModel:
    """A shipped object by name, with its manifest's scale, thickness, mass and material."""
    from importlib import resources

    manifest = asset_manifest()
    if name not in manifest:
        raise ConfigError(
            f"unknown object asset {name!r}: choose one of {', '.join(sorted(manifest))}"
        )
    entry = manifest[name]
    kwargs = {
        "px_per_mm": entry["px_per_mm"],
        "thickness_mm": entry["thickness_mm"],
        "mass_g": entry["mass_g"],
        "material": entry["material"],
        "name": name,
    }
    kwargs.update({k: v for k, v in overrides.items() if v is not None})
    with resources.as_file(resources.files("mjx_pick.assets") / "objects" / entry["image"]) as p:
        return object_from_image(p, **kwargs)


def load_object(
    source: str | os.PathLike,
    *,
    px_per_mm: float | None = None,
    thickness_mm: float | None = None,
    mass_g: float | None = None,
    density_kg_m3: float | None = None,
    unit: str | None = None,
    pose: str | np.ndarray = "as_given",
    pick_height_mm: float | None = None,
    simplify_mm: float | None = None,
    material: str | None = None,
    largest_body: bool = False,
    repair_volume_pct: float | None = None,
    repair_com_mm: float | None = None,
    repair_bounds_mm: float | None = None,
) -> ObjectModel:
    """An object from a shipped asset name, an image file or a mesh file (CLI entry).
    Every number is checked by its rule (``core.numbers``) and an option the source
    does not use is refused, never dropped. pose and repair_*: a mesh's
    (:func:`object_from_mesh`; None: the default tolerance)."""
    text = str(source)
    suffix = Path(text).suffix.lower()
    kind = "an image" if suffix in IMAGE_SUFFIXES else "a mesh" if suffix in MESH_SUFFIXES else ""
    options = {
        "px_per_mm": px_per_mm,
        "thickness_mm": thickness_mm,
        "mass_g": mass_g,
        "density_kg_m3": density_kg_m3,
        "pick_height_mm": pick_height_mm,
        "simplify_mm": simplify_mm,
        "unit": unit,
        "pose": pose,
        "largest_body": largest_body,
        "repair_volume_pct": repair_volume_pct,
        "repair_com_mm": repair_com_mm,
        "repair_bounds_mm": repair_bounds_mm,
    }
    _check_object_options(text, kind, options)
    return _load_checked_object(text, suffix, options, material)


def _load_checked_object(
    text: str, suffix: str, options: dict, material: str | None
) -> ObjectModel:
    """:func:`load_object` once its options are checked: the image, mesh or shipped asset
    that text names (suffix: its lower-case suffix), options its keywords by name."""
    o = options
    common = {"pick_height_mm": o["pick_height_mm"]}
    if material is not None:
        common["material"] = material
    if suffix in IMAGE_SUFFIXES:
        extra = {} if o["simplify_mm"] is None else {"simplify_mm": o["simplify_mm"]}
        return object_from_image(
            text,
            px_per_mm=o["px_per_mm"],
            thickness_mm=o["thickness_mm"],
            mass_g=o["mass_g"],
            density_kg_m3=o["density_kg_m3"],
            **extra,
            **common,
        )
    if suffix in MESH_SUFFIXES:
        if o["unit"] is None:
            raise ConfigError(f"mesh {text!r}: give its unit ('m' or 'mm', --unit)")
        tolerance = {k: o[k] for k in _REPAIR_NUMBERS if o[k] is not None}
        return object_from_mesh(
            text,
            unit=o["unit"],
            mass_g=o["mass_g"],
            density_kg_m3=o["density_kg_m3"],
            pose=o["pose"],
            largest_body=o["largest_body"],
            **tolerance,
            **common,
        )
    if suffix == "" and text in asset_names():
        return load_asset(
            text,
            px_per_mm=o["px_per_mm"],
            thickness_mm=o["thickness_mm"],
            mass_g=o["mass_g"],
            simplify_mm=o["simplify_mm"],
            **common,
        )
    raise ConfigError(
        f"object {text!r} is neither a shipped asset ({', '.join(asset_names())}), an image "
        f"({', '.join(IMAGE_SUFFIXES)}) nor a mesh ({', '.join(MESH_SUFFIXES)})"
    )


# a mesh's repair tolerances (load_object's names: object_from_mesh's keywords)
_REPAIR_NUMBERS = ("repair_volume_pct", "repair_com_mm", "repair_bounds_mm")
# load_object's numbers, each checked by its rule (``core.numbers``)
_OBJECT_NUMBERS = (
    "px_per_mm",
    "thickness_mm",
    "mass_g",
    "density_kg_m3",
    "pick_height_mm",
    "simplify_mm",
    *_REPAIR_NUMBERS,
)


def _check_object_options(text: str, kind: str, options: dict) -> None:
    """Refuse, in this order, a number its rule refuses, a mass given with a density,
    and an option the source does not use (kind: "an image", "a mesh", or "" for a
    shipped asset). options: :func:`load_object`'s keywords by name."""
    for name in _OBJECT_NUMBERS:
        numbers.check_optional(name, options[name])
    # checked here, projected once where it is used (object_from_mesh): the projection
    # onto a rotation is not idempotent to the bit, and the cache key holds its bits
    check_pose(options["pose"])
    mass_g, density_kg_m3 = options["mass_g"], options["density_kg_m3"]
    if mass_g is not None and density_kg_m3 is not None:
        raise ConfigError(
            f"object {text!r}: mass_g = {mass_g:g} and density_kg_m3 = {density_kg_m3:g} are "
            "both given: give one (--mass-g or --density-kg-m3); the other follows from the "
            "volume"
        )
    unused = _unused_options(kind, options)
    extra = [k for k, v in unused.items() if v is not None]
    if extra:
        what = kind or "a shipped asset"
        raise ConfigError(
            f"object {text!r} is {what}: {', '.join(extra)} does not apply to it (leave "
            + ", ".join("--" + k.replace("_", "-") for k in extra)
            + " out)"
        )


def _unused_options(kind: str, options: dict) -> dict:
    """The options a source of this kind does not use, by name (None: not given)."""
    largest_body = options["largest_body"] or None
    repair = {k: options[k] for k in _REPAIR_NUMBERS}
    unused = {
        "an image": {"unit": options["unit"], "largest_body": largest_body, **repair},
        "a mesh": {
            "px_per_mm": options["px_per_mm"],
            "thickness_mm": options["thickness_mm"],
            "simplify_mm": options["simplify_mm"],
        },
        "": {
            "density_kg_m3": options["density_kg_m3"],
            "unit": options["unit"],
            "largest_body": largest_body,
            **repair,
        },
    }[kind]
    pose = options["pose"]
    if not (isinstance(pose, str) and pose == "as_given") and kind != "a mesh":
        unused["pose"] = "given"
    return unused


def check_same_object(theirs: dict, obj: ObjectModel, where: str) -> None:
    """Refuse an object that is not the one ``theirs`` (an ``ObjectModel.summary``
    recorded with a run or a plan) was made for: name, mass, height and silhouette must
    match (numbers to a relative 1e-6); fields ``theirs`` lacks are not compared.

    where: what holds ``theirs``, for the message (e.g. "--results runs/do")."""
    mine = obj.summary()
    differ = []
    for k in ("name", "mass_g", "height_mm", "outline_wkt"):
        a, b = theirs.get(k), mine.get(k)
        if a is None:
            continue
        same = math.isclose(a, b, rel_tol=1e-6) if isinstance(a, int | float) else a == b
        if not same:
            differ.append(k)
    if differ:
        raise ConfigError(
            f"{where} is of object {theirs.get('name')!r}, not this run's {mine['name']!r} "
            f"({theirs.get('mass_g', 0):g} g against {mine['mass_g']:g} g): they differ in "
            f"{', '.join(differ)}; give the object (and --mass-g ...) it was made with"
        )
