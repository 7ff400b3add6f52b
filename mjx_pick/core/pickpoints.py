"""Pick-point generation (Normal, Grid, Optimization modes) with the paper's checks.

A pick-point is the object's planar pose under the gripper: x, y offset (mm) and yaw
(deg) of the object frame relative to the gripper centre. Candidates are drawn, checked
in one vectorised call (``mjx_pick.kernels.feasibility``), and the feasible ones get the
starting finger opening, so that each simulation starts with the fingers just clear of
the object (the paper's trick to cut closing time).
"""

from __future__ import annotations

import dataclasses
import functools
import logging
import math
import time
import warnings
from collections.abc import Callable

import numpy as np
import shapely
import shapely.affinity

from mjx_pick.core import cache
from mjx_pick.core import grasps as gm
from mjx_pick.core.config import (
    ConfigError,
    PlausibilityWarning,
    check_fields,
    check_range,
    setting,
)
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.gripper import GripperSpec
from mjx_pick.core.objects import ObjectModel, rasterize_window
from mjx_pick.core.procedure import GraspConfig, pad_band_mm
from mjx_pick.kernels import feasibility as fk

# what a slow step is doing, said as it starts (the CLI shows it on stderr)
log = logging.getLogger(__name__)
REASONS = fk.REASONS
# each feasibility outcome in a user's words (messages, the GUI, the CLI's counts)
REASON_WORDS = {
    "feasible": "feasible",
    "off_object": "the gripper misses the object",
    # the fingers open symmetrically about the gripper's centre: an off-centre part
    # narrower than the stroke is rejected so too, so never say "wider than the stroke"
    "too_wide": "the open fingers cannot reach around the part at that offset (it "
    "reaches farther than half the stroke, less a safety zone, from the gripper's centre)",
    "clearance": "a finger lands on the object",
    "coverage": "the object fills too little of the region between the pads",
    "pad_path": "the linkage's near pad rides over the part while closing",
}


RARE_FEASIBLE = 1e-3  # a feasible share of candidates below this: edge cases only
# the reasons that mean the part barely fits between the pads (its width, not a setting)
_FIT_REASONS = ("too_wide", "clearance")


def concat(batches: list[GraspBatch]) -> GraspBatch:
    """Pick-point batches joined (``grasps.concat``), every check's reason counted (0
    where none rejected): a pick-point search's summary names each."""
    joined = gm.concat(batches)
    rejected = dict(joined.rejected)
    for r in fk.REASONS[1:]:
        rejected.setdefault(r, 0)
    return dataclasses.replace(joined, rejected=rejected)


def warn_rare(obj, gripper, feasible: int, drawn: int, rejected: dict, config) -> None:
    """Warn when feasible pick-points are a tiny share of the candidates drawn: every
    rate rests on those few poses. The warning says why the others were rejected (each
    reason with its count and what to change, :func:`why_rejected`) -- a minimum
    coverage few poses meet is said as such, never as a part wider than the stroke.

    rejected: {reason: candidates rejected for it}; config: the PickConfig they were
    checked with."""
    if not (drawn and 0 < feasible < RARE_FEASIBLE * drawn):
        return
    counts = {k: int(v) for k, v in (rejected or {}).items() if v}
    top = max(counts, key=counts.get) if counts else "too_wide"
    edge = (
        "the part barely fits between the pads (a corner, a narrow end), and every rate "
        "rests on those edge cases; check their pictures"
        if top in _FIT_REASONS
        else "every rate rests on those few poses"
    )
    warnings.warn(
        f"{obj.name!r} with {gripper.name}: only {feasible} of {drawn:,} candidate poses "
        f"are feasible ({100 * feasible / drawn:.2g} %): {edge}. Rejected: "
        f"{why_rejected(counts, gripper, config)}",
        PlausibilityWarning,
        stacklevel=3,
    )


def why_rejected(rejected: dict, gripper, config) -> str:
    """Why candidates were rejected, in the user's words: each reason that rejected a
    tenth of them or more, the most common first, with its count and what to change.

    rejected: {reason: count}; gripper: the GripperSpec; config: the PickConfig used."""
    default = PickConfig()
    raised = (
        f"; the minimum coverage {config.min_coverage:g} is above the default "
        f"{default.min_coverage:g}: lower it, and more poses fit"
        if config.min_coverage > default.min_coverage
        else ""
    )
    advice = {
        "off_object": "the offset ranges miss the object: narrow the x and y offset ranges",
        "too_wide": f"a gripper with a larger stroke, now {gripper.stroke_mm:g} mm, or a "
        f"smaller safety zone, now {config.safety_zone_mm:g} mm, opens around more of them"
        f"{raised}",
        "clearance": "use a larger stroke, or a smaller safety zone",
        "coverage": f"lower the minimum coverage, now {config.min_coverage:g}; default "
        f"{default.min_coverage:g}",
        "pad_path": "a parallel-jaw gripper or centred poses may take it",
    }
    counts = {k: int(v) for k, v in (rejected or {}).items() if v}
    total = sum(counts.values())
    shown = [k for k in sorted(counts, key=counts.get, reverse=True) if counts[k] >= 0.1 * total]
    return (
        "; ".join(f"{counts[k]:,} because {REASON_WORDS[k]} ({advice[k]})" for k in shown)
        or advice["off_object"]
    )


def rejected_text(rejected: dict) -> str:
    """A batch's rejection counts in words, most first: '120 the gripper misses ...'."""
    shown = sorted(((int(v), k) for k, v in (rejected or {}).items() if v), reverse=True)
    return "; ".join(f"{v:,}: {REASON_WORDS.get(k, k)}" for v, k in shown) or "none"


CANDIDATE_BLOCK = 4096  # candidates are drawn in fixed blocks: same seed, same stream
# the most blocks a search checks in one Warp launch (a million candidates): the groups
# double up to it, as on the host up to two blocks per thread
DEVICE_GROUP = 256
SEARCH_NOTE_S = 2.0  # a long search for feasible pick-points says how far it is this often


def search_note(drawn: int, most: int, found: int, wanted: int, rejected: dict) -> str:
    """How far a search for feasible pick-points is, in words (the CLI's log line, the
    GUI's progress): candidates checked of the most it draws, feasible of those wanted,
    and why the others were rejected."""
    return (
        f"checked {drawn:,} of at most {most:,} candidate poses: {found:,} of {wanted:,} "
        f"feasible so far (rejected: {rejected_text(rejected)})"
    )


# cells of the feasibility raster (yaw bins x rows x columns, ~5 bytes each while it is
# built: the 0/1 masks, the uint16 stack and its copy on the device): more is refused
# before any is allocated
MAX_RASTER_CELLS = 200_000_000


@dataclasses.dataclass(frozen=True)
class PickConfig:
    """Pick-point generation settings. Defaults: the paper's (Fig. 10)."""

    safety_zone_mm: float = setting(
        5.0, "mm", "clearance kept between a descending finger and the object", lo=0, hi=100
    )
    min_coverage: float = setting(
        0.35,
        "-",
        "least fraction of the region between the fingertips the object fills",
        lo=0,
        hi=1,
    )
    # offsets are uniform in +-range; None: half the object's length (the paper's rule)
    x_range_mm: float | None = setting(
        None,
        "mm",
        "pick-point x offsets are drawn in +-this (none: half the object's length)",
        lo=0,
        hi=1000,
    )
    y_range_mm: float | None = setting(
        None,
        "mm",
        "pick-point y offsets are drawn in +-this (none: half the object's length)",
        lo=0,
        hi=1000,
    )
    yaw_min_deg: float = setting(0.0, "deg", "smallest yaw drawn", lo=-360, hi=360)
    yaw_max_deg: float = setting(
        360.0, "deg", "largest yaw drawn", lo="yaw_min_deg", hi="yaw_min_deg + 360"
    )
    resolution_mm: float = setting(
        0.5, "mm", "silhouette raster for the feasibility checks", lo=0.05, hi=2
    )
    max_candidates: int = setting(
        1_000_000, "candidates", "Normal mode gives up after drawing this many", lo=1, hi=1e9
    )
    # a linkage gripper (MJCF) only: reject poses whose near pad rides over the part
    # (FeasibilityChecker); off, such poses are simulated (and fail)
    pad_path_check: bool = True

    def __post_init__(self):
        check_fields(self, "picks")


class FeasibilityChecker:
    """The paper's three checks for one (object, gripper, settings), batched.

    The checks see the object's outline above the fingertips at the grasp
    (``ObjectModel.band_outline``; the procedure's grasp-height rule places them): for
    a prism its silhouette, for a mesh the shadow of its part above that height --
    what a descending finger can hit and what the pads can meet. A foot below the
    fingertips (an L-part standing on its edge) is no longer taken for a grip.

    An MJCF linkage's pads descend while they close (``mjx_pick.core.mjcf_gripper``); the
    scene starts each pick raised by the height compensation for the final grasp gap,
    so the pads grip at the grasp height. But with the part off-centre the near pad
    reaches it first, at a wider opening, where it rides higher by the drop between
    that opening and the grasp gap; if that lifts its tip above the part's top, it
    passes over the part and lands on it (such poses fail in simulation). A fourth
    check rejects those poses
    as "pad_path" (the part's full height is taken as its top: optimistic for a mesh
    lower under the near pad).

    device: a Warp device name ('cuda:0'): the checks run there, one Warp kernel launch
    a call (``kernels.feasibility_warp``: the same results as numpy's, bit for bit);
    None: numpy on the host's threads (``kernels.feasibility``, the reference).
    """

    def __init__(
        self,
        obj: ObjectModel,
        gripper: GripperSpec,
        config: PickConfig | None = None,
        grasp: GraspConfig | None = None,
        device: str | None = None,
    ):
        config = config or PickConfig()
        if config.safety_zone_mm >= 0.5 * gripper.stroke_mm:
            raise ConfigError(
                f"picks.safety_zone_mm = {config.safety_zone_mm:g} is out of range: allowed "
                f"< half the stroke of {gripper.name} ({0.5 * gripper.stroke_mm:g} mm)"
            )
        self.object, self.gripper, self.config = obj, gripper, config
        self.device = device
        self.band = fk.GripperBand(
            stroke_mm=float(gripper.stroke_mm),
            finger_width_mm=float(gripper.finger_width_mm),
            finger_depth_mm=float(gripper.finger_depth_mm),
            safety_zone_mm=float(config.safety_zone_mm),
            min_coverage=float(config.min_coverage),
        )
        lo, hi = pad_band_mm(obj, gripper, grasp or GraspConfig())
        self.silhouette = obj.band_outline(lo, max(hi, obj.height_mm))
        if self.silhouette.is_empty:
            raise ConfigError(
                f"the pads of {gripper.name} span {lo:g}-{hi:g} mm above the table and miss "
                f"{obj.name!r} ({obj.height_mm:g} mm high): lower pick_height_mm"
            )
        self.stack = _stack(obj.name, self.silhouette, config.resolution_mm)
        self.kinematics = None
        if gripper.mjcf is not None and config.pad_path_check:
            from mjx_pick.core import mjcf_gripper

            self.kinematics = mjcf_gripper.characterise(gripper.mjcf)
            self.room_mm = obj.height_mm - lo  # the part's top above the fingertips

    def __call__(self, x_mm, y_mm, yaw_deg, opening_mm=None) -> dict[str, np.ndarray]:
        """Check (N,) candidates; returns reason, opening_mm, coverage, gap_*_mm arrays.

        opening_mm: (N,) fixed starting openings (the fingers of a plan made for another
        pose; an object reaching a finger fails clearance), or None to choose them.
        """
        yaw_rad = np.deg2rad(np.asarray(yaw_deg, float))
        if self.device is None:
            checked = fk.check_candidates(self.stack, self.band, x_mm, y_mm, yaw_rad, opening_mm)
        else:
            from mjx_pick.kernels import feasibility_warp

            checked = feasibility_warp.check_candidates(
                self.stack, self.band, x_mm, y_mm, yaw_rad, opening_mm, device=self.device
            )
        reason, opening, coverage, gap_l, gap_r = checked
        reason = np.asarray(reason)
        if self.kinematics is not None:
            rides = self.near_pad_rise_mm(opening, gap_l, gap_r) >= self.room_mm
            reason = np.where((reason == fk.FEASIBLE) & rides, fk.PAD_PATH, reason)
        return {
            "reason": reason,
            "opening_mm": np.asarray(opening, float),
            "coverage": np.asarray(coverage, float),
            "gap_left_mm": np.asarray(gap_l, float),
            "gap_right_mm": np.asarray(gap_r, float),
        }

    def near_pad_rise_mm(self, opening_mm, gap_left_mm, gap_right_mm) -> np.ndarray:
        """(N,) how much higher than at the grasp the near pad is when it reaches the
        part (an MJCF linkage; mm): the pads' drop between the first-contact opening
        and the grasp gap."""
        o, gl, gr = (np.asarray(a, float) * 1e-3 for a in (opening_mm, gap_left_mm, gap_right_mm))
        first, final = o - 2.0 * np.minimum(gl, gr), o - gl - gr
        kin = self.kinematics
        return 1e3 * (kin.pad_centre_drop_m(final) - kin.pad_centre_drop_m(first))

    def ranges(self) -> tuple[float, float]:
        """The x and y offset ranges in mm (defaults: half the object's length)."""
        return offset_ranges(self.object, self.config)

    def batch(self, pick_id, x_mm, y_mm, yaw_deg, mode: str) -> GraspBatch:
        """Check candidates and keep the feasible ones as a GraspBatch."""
        return feasible_batch(pick_id, x_mm, y_mm, yaw_deg, self(x_mm, y_mm, yaw_deg), mode)


def offset_ranges(obj: ObjectModel, config: PickConfig) -> tuple[float, float]:
    """The x and y offset ranges in mm (defaults: half the object's length)."""
    half = 0.5 * obj.length_mm
    xr = config.x_range_mm if config.x_range_mm is not None else half
    yr = config.y_range_mm if config.y_range_mm is not None else half
    return xr, yr


def feasible_batch(pick_id, x_mm, y_mm, yaw_deg, res: dict, mode: str) -> GraspBatch:
    """The feasible candidates of a FeasibilityChecker result `res`, with the counts of
    the rejected ones."""
    ok = res["reason"] == fk.FEASIBLE
    counts = np.bincount(res["reason"], minlength=len(REASONS))
    return GraspBatch(
        pick_id=np.asarray(pick_id, np.int64)[ok],
        x_mm=np.asarray(x_mm, float)[ok],
        y_mm=np.asarray(y_mm, float)[ok],
        yaw_deg=np.asarray(yaw_deg, float)[ok],
        opening_mm=res["opening_mm"][ok],
        coverage=res["coverage"][ok],
        gap_left_mm=res["gap_left_mm"][ok],
        gap_right_mm=res["gap_right_mm"][ok],
        rejected={REASONS[i]: int(counts[i]) for i in range(1, len(REASONS))},
        n_candidates=len(ok),
        mode=mode,
    )


def raster_cells(radius_mm: float, res_mm: float) -> int:
    """Cells of the feasibility raster of a silhouette of this radius (``fk.build_stack``)."""
    n_bins = max(8, math.ceil(math.pi * radius_mm / res_mm))
    side = 2 * (math.ceil(radius_mm / res_mm) + 2)
    return n_bins * side * side


def check_raster(obj: ObjectModel, config: PickConfig | None = None) -> None:
    """Refuse, before anything is allocated, an object whose feasibility raster would
    exceed MAX_RASTER_CELLS even at the coarsest allowed resolution (it grows as
    (size/resolution)^3); a finer resolution than fits is coarsened when built."""
    config = config or PickConfig()
    radius = max(math.hypot(x, y) for x, y in obj.polygon.exterior.coords)
    raster_resolution(obj.name, radius, config.resolution_mm)


# yaws over half a turn at which check_stroke measures the outline (the gripper is
# symmetric: yaw and yaw + 180 deg grip the same section)
STROKE_YAWS = 180
# band positions every 1/STROKE_BAND_STEPS of the finger width
STROKE_BAND_STEPS = 16
# below this fraction of the configured yaws with a section that may fit, a warning
# says that most candidates will be dropped as too wide
STROKE_FEW_YAWS = 0.25


@dataclasses.dataclass(frozen=True)
class StrokeFit:
    """How the outline between the pads fits the stroke (``stroke_fit``).

    yaw_deg: (K,) the yaws measured, over [0, 180); opening_mm: (K,) at each, a lower
    bound of the narrowest opening (safety zones left out) that the feasibility checks
    could accept within half a yaw step (inf where none); narrowest_mm: their minimum;
    fits: the fraction of the configured yaws where that opening plus the two safety
    zones may fit the stroke."""

    yaw_deg: np.ndarray
    opening_mm: np.ndarray
    narrowest_mm: float
    fits: float


def stroke_fit(
    obj: ObjectModel,
    gripper: GripperSpec,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
) -> StrokeFit:
    """Bound, from the outline the pads meet (the FeasibilityChecker's) alone, the
    narrowest opening any pick-point could need: no raster (cheap beside building one).

    A feasible pick-point's band (finger-wide, across the closing direction) cuts the
    outline into pieces; those between the pads lie there whole (a piece reaching under
    a finger fails clearance), span at most the opening less the safety zones, and fill
    min_coverage of the pads' region. Here, at each of STROKE_YAWS yaws, bands are
    sampled every STROKE_BAND_STEPS-th of the finger width and narrowed so that every
    band in between, at any yaw within half a step, contains one (the outline moves at
    most its radius times half a step); what a band loses that way is at most its lost
    width times the opening, which the coverage test here forgives. Runs of neighbouring
    pieces (those overlapping along the closing direction merged: they go together)
    that pass it give the bound, centred on the run as far as the drawn offsets reach,
    less the yaw's movement and a raster cell (the checks' own rounding). So a part whose
    bound plus the safety zones exceeds the stroke has no feasible pick-point.
    """
    config = config or PickConfig()
    lo, hi = pad_band_mm(obj, gripper, grasp or GraspConfig())
    outline = obj.band_outline(lo, max(hi, obj.height_mm))
    yaws = np.arange(STROKE_YAWS) * (180.0 / STROKE_YAWS)
    if outline.is_empty:  # nothing between the pads (FeasibilityChecker refuses it)
        return StrokeFit(yaws, np.full(STROKE_YAWS, np.inf), math.inf, 0.0)
    xr, yr = offset_ranges(obj, config)
    # a pure function of the outline and five numbers: kept on disk across runs
    # (mjx_pick.core.cache), as the feasibility raster is
    key = {
        "outline_sha256": cache.digest(outline.wkb),
        "finger_width_mm": float(gripper.finger_width_mm),
        "min_coverage": float(config.min_coverage),
        "x_range_mm": float(xr),
        "y_range_mm": float(yr),
        "resolution_mm": float(config.resolution_mm),
        "yaws": STROKE_YAWS,
        "band_steps": STROKE_BAND_STEPS,
    }
    args = (outline, key["finger_width_mm"], key["min_coverage"], xr, yr, config.resolution_mm)
    openings = cache.memo("stroke_fit", key, lambda: {"openings": _openings(*args)})["openings"]
    lo_yaw, hi_yaw = config.yaw_min_deg, config.yaw_max_deg
    wanted = np.mod(yaws - lo_yaw, 360.0) <= hi_yaw - lo_yaw  # in the configured range
    wanted |= np.mod(yaws + 180.0 - lo_yaw, 360.0) <= hi_yaw - lo_yaw
    room = gripper.stroke_mm - 2.0 * config.safety_zone_mm
    fits = float(np.mean(openings[wanted] <= room)) if wanted.any() else 0.0
    return StrokeFit(yaws, openings, float(openings.min()), fits)


def _openings(outline, w: float, c_min: float, xr: float, yr: float, res_mm: float) -> np.ndarray:
    """stroke_fit's (STROKE_YAWS,) bounds on the narrowest opening, mm (inf: none), for
    an outline, finger width w (mm), min_coverage c_min, offset ranges +-xr, +-yr (mm)
    and the raster's cell (mm)."""
    # a tenth of a millimetre moves no edge further than the raster's rounding and keeps
    # a mesh's outline (thousands of vertices) cheap to cut; taken off the bound below
    simplify_mm = 0.1
    outline = shapely.simplify(outline, simplify_mm, preserve_topology=True)
    radius = float(np.hypot(*shapely.get_coordinates(outline).T).max())
    step = w / STROKE_BAND_STEPS
    slack = radius * math.sin(0.5 * math.pi / STROKE_YAWS) + simplify_mm  # half a yaw step
    width = w - step - 2.0 * slack  # the band every band in reach contains
    fill = c_min * w - step - 2.0 * slack  # least area per mm of opening in that band
    slop = 2.0 * slack + res_mm
    yaws = np.arange(STROKE_YAWS) * (180.0 / STROKE_YAWS)
    openings = np.full(STROKE_YAWS, np.inf)
    for k, yaw in enumerate(yaws):
        if width <= 0.0:  # too coarse to bound anything: never a refusal
            openings[k] = 0.0
            continue
        rotated = shapely.affinity.rotate(outline, yaw, origin=(0.0, 0.0))
        x0, y0, x1, y1 = rotated.bounds
        # band centres in reach (the gripper centre's y is a drawn offset, +-yr)
        c0, c1 = max(y0 - 0.5 * w, -yr - slack), min(y1 + 0.5 * w, yr + slack)
        if c1 < c0:
            continue
        edges = np.linspace(c0, c1, max(2, math.ceil((c1 - c0) / step) + 1))
        centres = 0.5 * (edges[:-1] + edges[1:])
        bands = shapely.box(x0 - 1.0, centres - 0.5 * width, x1 + 1.0, centres + 0.5 * width)
        cut = shapely.intersection(rotated, bands)
        parts, band_of = shapely.get_parts(cut, return_index=True)
        areas = shapely.area(parts)
        solid = areas > 0.0  # a band's edge along an outline's edge cuts off bare lines
        parts, band_of, areas = parts[solid], band_of[solid], areas[solid]
        bounds = shapely.bounds(parts)
        for b in np.unique(band_of):
            sel = band_of == b
            run = _narrowest_run(bounds[sel], areas[sel], fill, xr + slack)
            openings[k] = min(openings[k], max(run - slop, 0.0))
    return openings


def _whole_width_fits(obj, gripper, config, grasp) -> bool:
    """Whether the whole outline the pads meet, centred between them (within the drawn
    x offsets), fits the stroke less the safety zones at STROKE_FEW_YAWS of the
    configured yaws or more: check_stroke then says nothing (a part whose whole width
    fits but whose sections are too sparse for min_coverage is left to the sampler)."""
    lo, hi = pad_band_mm(obj, gripper, grasp or GraspConfig())
    outline = obj.band_outline(lo, max(hi, obj.height_mm))
    if outline.is_empty:  # the pads miss the part: FeasibilityChecker's error names it
        return True
    xy = shapely.get_coordinates(outline.convex_hull)
    yaws = np.deg2rad(np.arange(STROKE_YAWS) * (180.0 / STROKE_YAWS))
    x = xy[:, 0][None, :] * np.cos(yaws)[:, None] - xy[:, 1][None, :] * np.sin(yaws)[:, None]
    left, right = x.min(axis=1), x.max(axis=1)
    xr, _ = offset_ranges(obj, config)
    centre = np.clip(0.5 * (left + right), -xr, xr)
    opening = 2.0 * np.maximum(right - centre, centre - left) + config.resolution_mm
    room = gripper.stroke_mm - 2.0 * config.safety_zone_mm
    lo_yaw, hi_yaw = config.yaw_min_deg, config.yaw_max_deg
    deg = np.rad2deg(yaws)
    wanted = np.mod(deg - lo_yaw, 360.0) <= hi_yaw - lo_yaw
    wanted |= np.mod(deg + 180.0 - lo_yaw, 360.0) <= hi_yaw - lo_yaw
    return bool(wanted.any()) and float(np.mean(opening[wanted] <= room)) >= STROKE_FEW_YAWS


def _narrowest_run(bounds, areas, fill: float, xr: float) -> float:
    """The narrowest opening over runs of neighbouring pieces of one band (bounds:
    (P, 4) xmin, ymin, xmax, ymax; areas: (P,)) holding at least fill mm^2 per mm of
    it; inf if none. The pads centre on a run, or as near as the drawn x offsets (+-xr)
    reach: off-centre, the opening spans the run's far side twice."""
    order = np.argsort(bounds[:, 0])
    clusters: list[list[float]] = []  # [xmin, xmax, area] of pieces overlapping in x
    for i in order:
        a, b = bounds[i, 0], bounds[i, 2]
        if clusters and a <= clusters[-1][1]:
            clusters[-1][1] = max(clusters[-1][1], b)
            clusters[-1][2] += areas[i]
        else:
            clusters.append([a, b, areas[i]])
    best = math.inf
    for i in range(len(clusters)):
        area = 0.0
        for j in range(i, len(clusters)):
            a, b = clusters[i][0], clusters[j][1]
            if b - a >= best:
                break
            area += clusters[j][2]
            centre = min(max(0.5 * (a + b), -xr), xr)
            opening = 2.0 * max(b - centre, centre - a)
            if opening < best and area >= fill * opening:
                best = opening
    return best


def stroke_refusal(
    obj: ObjectModel,
    gripper: GripperSpec,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
) -> str | None:
    """Why :func:`check_stroke` refuses gripper for obj (no pick-point can fit), or None
    where one may: the quick check a study runs on each of its grippers before any
    candidate is drawn (its may-fit-at-few-yaws warning is left to a single run)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        try:
            check_stroke(obj, gripper, config, grasp)
        except ConfigError as err:
            return str(err)
    return None


def check_stroke(
    obj: ObjectModel,
    gripper: GripperSpec,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
) -> StrokeFit | None:
    """Before any raster, scene or folder: refuse a part that no pick-point can fit
    (``stroke_fit``: the narrowest opening it could need, plus the safety zones, is
    wider than the stroke; the sampler would draw max_candidates and find none); warn,
    with the numbers, when it may fit at few of the configured yaws. Returns the fit,
    or None when the whole part fits between the pads at enough yaws to say nothing
    (most parts: a projection of its hull, without stroke_fit's band cuts)."""
    config = config or PickConfig()
    if _whole_width_fits(obj, gripper, config, grasp):
        return None
    fit = stroke_fit(obj, gripper, config, grasp)
    stroke, zone = gripper.stroke_mm, config.safety_zone_mm
    where = f"{obj.name!r} with {gripper.name} (stroke {stroke:g} mm)"
    if fit.narrowest_mm > stroke:
        raise ConfigError(
            f"{where}: the part is at least {fit.narrowest_mm:.1f} mm wide between the pads "
            f"at every pose (a finger-wide section that fills min_coverage = "
            f"{config.min_coverage:g} of the pads' region), wider than the stroke, so no "
            "pick-point can be feasible: use a gripper with a larger stroke, or check the "
            "object's scale"
        )
    if fit.narrowest_mm + 2.0 * zone > stroke:
        raise ConfigError(
            f"{where}: the part is at least {fit.narrowest_mm:.1f} mm wide between the pads "
            f"at every pose; with the {zone:g} mm safety zone on each side the fingers need "
            f"{fit.narrowest_mm + 2.0 * zone:.1f} mm, more than the stroke, so no pick-point "
            f"can be feasible: lower --safety-zone-mm (picks.safety_zone_mm) below "
            f"{0.5 * (stroke - fit.narrowest_mm):.1f}, or use a gripper with a larger stroke"
        )
    if fit.fits < STROKE_FEW_YAWS:
        warnings.warn(
            f"{where}: the part may fit between the pads (at least {fit.narrowest_mm:.1f} mm "
            f"plus {zone:g} mm safety zones) at only {100 * fit.fits:.0f} % of the yaws in "
            "picks' range: most candidates will be too wide, and the feasible pick-points "
            "cluster at those yaws",
            PlausibilityWarning,
            stacklevel=2,
        )
    return fit


def raster_resolution(name: str, radius_mm: float, res_mm: float) -> float:
    """The raster's cell size, mm: res_mm, or the finest coarser one whose raster holds
    at most MAX_RASTER_CELLS (a PlausibilityWarning says so); a ConfigError when even the
    coarsest allowed resolution does not fit."""
    cells = raster_cells(radius_mm, res_mm)
    if cells <= MAX_RASTER_CELLS:
        return res_mm
    fits = math.ceil(res_mm * (cells / MAX_RASTER_CELLS) ** (1 / 3) * 102) / 100
    coarsest = PickConfig.__dataclass_fields__["resolution_mm"].metadata["range"][1]
    if fits > coarsest:
        raise ConfigError(
            f"{name!r} is {2 * radius_mm:.0f} mm across: its feasibility raster would hold "
            f"{raster_cells(radius_mm, coarsest) / 1e6:.0f} million cells even at "
            f"picks.resolution_mm = {coarsest:g} (allowed {MAX_RASTER_CELLS / 1e6:.0f} "
            "million): check the object's scale"
        )
    warnings.warn(
        f"{name!r} is {2 * radius_mm:.0f} mm across: the feasibility raster uses "
        f"{fits:g} mm cells instead of picks.resolution_mm = {res_mm:g} to stay within "
        f"{MAX_RASTER_CELLS / 1e6:.0f} million cells (~{MAX_RASTER_CELLS * 5 / 2**30:.1f} GiB)",
        PlausibilityWarning,
        # one place for the check before any work and the raster's build: Python's
        # default filter then says it once per process, not once per caller
        stacklevel=1,
    )
    return fits


@functools.lru_cache(maxsize=8)
def _stack_cached(key, polygon, res_mm: float):
    radius = float(np.hypot(*shapely.get_coordinates(polygon).T).max())  # one piece or several
    res_mm = raster_resolution(key[0], radius, res_mm)
    # the rasterised yaw bins are a pure function of the silhouette: kept on disk across
    # runs (mjx_pick.core.cache), a bit per pixel of each bin's crop
    entry = {
        "silhouette_sha256": cache.digest(polygon.wkb),
        "res_mm": float(res_mm),
        "radius_mm": float(radius),
        "yaw_bins": fk.yaw_bins(res_mm, radius),
        "layout": "bins cropped, rows of packed columns",
    }

    def compute() -> dict:
        log.info(
            "%s: rasterising the silhouette for the feasibility checks (%d yaw bins) ...",
            key[0],
            fk.yaw_bins(res_mm, radius),
        )
        bits, crops, size, x0 = fk.packed_bins(rasterize_window, polygon, res_mm, radius)
        return {"bits": bits, "crops": crops, "size": np.array(size), "x0_mm": np.array(x0)}

    arrays = cache.memo("silhouettes", entry, compute)
    return fk.stack_from_bits(
        arrays["bits"], arrays["crops"], int(arrays["size"]), res_mm, float(arrays["x0_mm"])
    )


def _stack(name: str, silhouette, res_mm: float) -> fk.SilhouetteStack:
    return _stack_cached((name, silhouette.wkb), silhouette, float(res_mm))


def draw_block(rng: np.random.Generator, xr: float, yr: float, config: PickConfig, n: int):
    """n uniform candidate poses: x in +-xr, y in +-yr (mm), yaw in the config's range."""
    x = rng.uniform(-xr, xr, n)
    y = rng.uniform(-yr, yr, n)
    yaw = rng.uniform(config.yaw_min_deg, config.yaw_max_deg, n)
    if config.yaw_max_deg - config.yaw_min_deg >= 360.0:
        yaw = np.mod(yaw, 360.0)
    return x, y, yaw


def candidate_blocks(checker: FeasibilityChecker, seed: int):
    """An endless, seeded stream of candidate blocks: (pick_id, x_mm, y_mm, yaw_deg),
    CANDIDATE_BLOCK each. The poses depend on the object and settings only, so every
    gripper sees the same stream for the same seed."""
    rng = np.random.default_rng(seed)
    xr, yr = checker.ranges()
    start = 0
    while True:
        x, y, yaw = draw_block(rng, xr, yr, checker.config, CANDIDATE_BLOCK)
        yield np.arange(start, start + CANDIDATE_BLOCK), x, y, yaw
        start += CANDIDATE_BLOCK


def candidate_stream(checker: FeasibilityChecker, seed: int):
    """Feasible GraspBatches from the seeded stream of candidate blocks, one a block.

    Blocks are checked in groups that double up to two per thread
    (``fk.threads()``), side by side, or up to DEVICE_GROUP in one launch on the
    checker's Warp device; a group's blocks are drawn in order, so the batches and
    their counts are those of checking one block at a time. A search that ends inside a
    group has checked the group's later blocks for nothing (at most half its checks:
    the groups double from one block).
    """
    blocks = candidate_blocks(checker, seed)
    group, most = 1, DEVICE_GROUP if checker.device is not None else 2 * fk.threads()
    while True:
        drawn = [next(blocks) for _ in range(group)]
        ids, x, y, yaw = (np.concatenate(a) for a in zip(*drawn, strict=True))
        checked = checker(x, y, yaw)
        for b in range(group):
            s = slice(b * CANDIDATE_BLOCK, (b + 1) * CANDIDATE_BLOCK)
            res = {k: v[s] for k, v in checked.items()}
            yield feasible_batch(ids[s], x[s], y[s], yaw[s], res, mode="normal")
        group = min(2 * group, most)


def generate_normal(
    obj: ObjectModel,
    gripper: GripperSpec,
    n: int,
    seed: int = 0,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
    progress: Callable[[int, int, dict], None] | None = None,
    device: str | None = None,
) -> GraspBatch:
    """Normal mode: the first n feasible pick-points of the seeded candidate stream.

    A search that finds few feasible poses draws up to ``max_candidates``: it logs how
    far it is every SEARCH_NOTE_S (:func:`search_note`), and calls progress(drawn,
    found, rejected) -- candidates checked, feasible found, {reason: count} -- after
    each block, which may raise to stop it (the GUI's Stop button). device: where the
    checks run (:class:`FeasibilityChecker`; the same picks anywhere).
    """
    check_range("picks", "n", n, 1, 1e9)
    checker = FeasibilityChecker(obj, gripper, config, grasp, device)
    most = checker.config.max_candidates
    batches, found, drawn = [], 0, 0
    rejected: dict[str, int] = {}
    noted = time.monotonic()
    for block in candidate_stream(checker, seed):
        batches.append(block)
        found += len(block)
        drawn += block.n_candidates
        for reason, count in block.rejected.items():
            rejected[reason] = rejected.get(reason, 0) + int(count)
        if progress is not None:
            progress(drawn, found, rejected)
        if found >= n or drawn >= most:
            break
        if time.monotonic() - noted > SEARCH_NOTE_S:
            log.info("%s", search_note(drawn, most, found, n, rejected))
            noted = time.monotonic()
    picks = concat(batches)
    if len(picks) == 0:
        raise ConfigError(_empty_message(obj, gripper, checker.config, picks))
    warn_rare(obj, gripper, len(picks), picks.n_candidates, picks.rejected, checker.config)
    if len(picks) < n:
        warnings.warn(
            f"only {len(picks)} of {n} pick-points are feasible after {picks.n_candidates} "
            f"candidates (rejected: {rejected_text(picks.rejected)})",
            stacklevel=2,
        )
        return picks
    # keep exactly n; n_candidates and the rejection counts cover every candidate that
    # was checked (whole blocks)
    return picks.take(slice(0, n))


def generate_grid(
    obj: ObjectModel,
    gripper: GripperSpec,
    x_step_mm: float,
    y_step_mm: float,
    yaw_step_deg: float,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
) -> GraspBatch:
    """Grid mode: every feasible pick of a systematic x, y, yaw grid (ranges as Normal)."""
    check_range("grid", "x_step_mm", x_step_mm, 0, lo_open=True)
    check_range("grid", "y_step_mm", y_step_mm, 0, lo_open=True)
    check_range("grid", "yaw_step_deg", yaw_step_deg, 0, 360, lo_open=True)
    checker = FeasibilityChecker(obj, gripper, config, grasp)
    xr, yr = checker.ranges()
    xs = np.arange(-xr, xr + 1e-9, x_step_mm)
    ys = np.arange(-yr, yr + 1e-9, y_step_mm)
    cfg = checker.config
    yaws = np.arange(cfg.yaw_min_deg, cfg.yaw_max_deg - 1e-9, yaw_step_deg)
    if len(xs) * len(ys) * len(yaws) > 50_000_000:
        raise ConfigError(
            f"grid has {len(xs) * len(ys) * len(yaws)} points (> 50 million): use larger steps"
        )
    gx, gy, gyaw = (a.ravel() for a in np.meshgrid(xs, ys, yaws, indexing="ij"))
    parts = []
    for start in range(0, len(gx), 262_144):
        sl = slice(start, start + 262_144)
        parts.append(checker.batch(np.arange(len(gx))[sl], gx[sl], gy[sl], gyaw[sl], "grid"))
    picks = concat(parts)
    if len(picks) == 0:
        raise ConfigError(_empty_message(obj, gripper, cfg, picks))
    return picks


@dataclasses.dataclass(frozen=True)
class OptimizationResult:
    """Optimization mode: every evaluated pick-point, its score, and whether K were found."""

    picks: GraspBatch
    scores: np.ndarray
    reached: bool
    k: int
    min_score: float

    @property
    def best(self) -> GraspBatch:
        """The evaluated pick-points at or above the score threshold, best first."""
        order = np.argsort(-self.scores, kind="stable")
        order = order[self.scores[order] >= self.min_score]
        return self.picks.take(order)


def optimize(
    obj: ObjectModel,
    gripper: GripperSpec,
    score_fn: Callable[[GraspBatch], np.ndarray],
    k: int,
    min_score: float,
    max_n: int,
    batch_size: int = 256,
    seed: int = 0,
    config: PickConfig | None = None,
    grasp: GraspConfig | None = None,
    device: str | None = None,
) -> OptimizationResult:
    """Optimization mode: evaluate feasible batches until k reach min_score or max_n are spent.

    Args:
      score_fn: scores (N,) for a GraspBatch -- the simulator in practice.
      k: pick-points wanted at or above min_score.
      max_n: most pick-points to evaluate.
      batch_size: pick-points per call of score_fn (a fixed shape: no recompiles).
      device: where the checks run (:class:`FeasibilityChecker`; the same picks anywhere).
    """
    check_range("optimize", "k", k, 1)
    check_range("optimize", "max_n", max_n, 1)
    check_range("optimize", "batch_size", batch_size, 1)
    checker = FeasibilityChecker(obj, gripper, config, grasp, device)
    pending: list[GraspBatch] = []
    evaluated, scores, good = [], [], 0
    stream = candidate_stream(checker, seed)
    drawn = 0
    while good < k and sum(len(b) for b in evaluated) < max_n:
        while sum(len(b) for b in pending) < batch_size and drawn < checker.config.max_candidates:
            block = next(stream)
            drawn += block.n_candidates
            pending.append(block)
        queue = concat(pending)
        if len(queue) == 0:
            raise ConfigError(_empty_message(obj, gripper, checker.config, queue))
        room = max_n - sum(len(b) for b in evaluated)
        take = min(batch_size, len(queue), room)
        batch = queue.take(slice(0, take))
        rest = queue.take(slice(take, None))
        pending = [dataclasses.replace(rest, rejected={}, n_candidates=0)] if len(rest) else []
        s = np.asarray(score_fn(batch), float)
        if s.shape != (len(batch),):
            raise ValueError(f"score_fn returned shape {s.shape}, expected ({len(batch)},)")
        evaluated.append(batch)
        scores.append(s)
        good += int(np.sum(s >= min_score))
        if take == 0:
            break
    picks = concat(evaluated)
    picks = dataclasses.replace(picks, mode="optimization", n_candidates=drawn)
    return OptimizationResult(picks, np.concatenate(scores), good >= k, k, min_score)


def _empty_message(obj, gripper, config, picks: GraspBatch) -> str:
    """Why no candidate was feasible, in the user's words (:func:`why_none`)."""
    return (
        f"no feasible pick-point for {obj.name} with {gripper.name} after "
        f"{picks.n_candidates:,} candidates: {why_none(picks.rejected, gripper, config)}"
    )


def why_none(rejected: dict, gripper, config) -> str:
    """Why none of the candidates was feasible: first the check that rejected every
    candidate that passed the others -- the last in REASONS order that rejected any (a
    candidate is rejected by the first check it fails), the one that decided, however
    few it saw -- then the others by count (:func:`why_rejected`). A minimum coverage
    no pose meets is said as such even when most candidates were too wide anyway."""
    counts = {k: int(v) for k, v in (rejected or {}).items() if v}
    order = [r for r in REASONS[1:] if counts.get(r)]
    if len(order) < 2:
        return why_rejected(counts, gripper, config)
    last = order[-1]
    rest = {k: v for k, v in counts.items() if k != last}
    return (
        "those that passed the other checks were all rejected: "
        f"{why_rejected({last: counts[last]}, gripper, config)}; before that, "
        f"{why_rejected(rest, gripper, config)}"
    )
