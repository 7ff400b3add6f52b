"""Batched geometric feasibility of pick-points (the paper's three checks), in JAX.

Everything here is pure and jit-able; the candidate axis is added with ``vmap`` at the
single entry point :func:`check_candidates`.

Method. For a pick-point (x, y, yaw) only the *band* under the fingers matters: the strip
|y_g| <= finger_width / 2 of the gripper frame, from one fully-open finger's outer face
to the other's. The object's silhouette is pre-rasterised once per yaw bin (rotated about
its origin, axes aligned with the gripper's) and cumulated along rows, so the amount of
object in the band at any gripper-frame column is one subtraction of two gathered rows.
From that column profile:

* off the object: no object between the fully open fingers;
* distance ("too wide"): each finger starts ``safety_zone`` outside the outermost object
  column between the open fingers; the (symmetric) opening this needs must fit the stroke;
* clearance: both finger footprints (depth x width) at that opening are free of object;
* coverage: object area between the fingertips over the area between them (opening x
  finger width) is at least ``min_coverage``.

A plain reference (:func:`reference_check`) samples the exact polygon point by point
for one candidate; tests pin the kernel to it. The raster costs at most half a pixel of
position and half a yaw bin of angle (bins are chosen so that this is also at most half
a pixel at the object's rim).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

FEASIBLE, OFF_OBJECT, TOO_WIDE, CLEARANCE, COVERAGE, PAD_PATH = range(6)
# pad_path: a linkage's near pad rides over the part (mjx_pick.core.pickpoints; not checked
# in these kernels, which see the gripper's footprint only)
REASONS = ("feasible", "off_object", "too_wide", "clearance", "coverage", "pad_path")


class GripperBand(NamedTuple):
    """Gripper geometry and check thresholds, mm (floats: hashable, static under jit)."""

    stroke_mm: float
    finger_width_mm: float
    finger_depth_mm: float
    safety_zone_mm: float
    min_coverage: float


class SilhouetteStack(NamedTuple):
    """Row-cumulated rotated silhouettes.

    cum_rows: (K, H + 1, W) uint16; cum_rows[k, i, j] = object pixels in rows < i of
      column j of the silhouette rotated by yaw k * pi / K (at most H, which the raster's
      cell limit keeps far below 2**16).
    res_mm: pixel size, mm (a Python float: static).
    x0_mm: lower-left corner of every grid (x and y), mm (static).
    """

    cum_rows: jax.Array
    res_mm: float
    x0_mm: float


def build_stack(rasterize, polygon, res_mm: float, radius_mm: float) -> SilhouetteStack:
    """Rasterise the silhouette for yaw bins over [0, pi) (:func:`yaw_bins` of them).

    Yaw and yaw + pi give the same checks with (x, y) negated (the gripper is symmetric),
    so half a turn suffices.
    """
    masks, x0 = rasterize_bins(rasterize, polygon, res_mm, radius_mm)
    return stack_from_masks(masks, res_mm, x0)


def yaw_bins(res_mm: float, radius_mm: float) -> int:
    """Yaw bins over [0, pi): pi * radius / K <= res_mm, i.e. at most half a pixel of
    arc at the rim for the nearest bin."""
    return max(8, int(math.ceil(math.pi * radius_mm / res_mm)))


def rasterize_bins(rasterize, polygon, res_mm: float, radius_mm: float):
    """(K, H, W) uint8 masks of the silhouette rotated by yaw k * pi / K, and the grids'
    lower-left corner x0 (mm; the same for x and y and every bin)."""
    n_bins = yaw_bins(res_mm, radius_mm)
    masks = []
    x0 = None
    for k in range(n_bins):
        mask, (gx0, _) = rasterize(polygon, res_mm, k * math.pi / n_bins, radius_mm=radius_mm)
        masks.append(mask)
        x0 = gx0
    return np.stack(masks).astype(np.uint8), float(x0)


def stack_from_masks(masks: np.ndarray, res_mm: float, x0_mm: float) -> SilhouetteStack:
    """The row-cumulated stack of (K, H, W) 0/1 masks (:func:`rasterize_bins`)."""
    masks = np.asarray(masks)
    n_bins, n_rows, n_cols = masks.shape
    if n_rows >= 2**16:
        raise ValueError(f"a raster of {n_rows} rows does not fit the uint16 stack")
    cum = np.empty((n_bins, n_rows + 1, n_cols), np.uint16)
    cum[:, 0] = 0
    # one row at a time: each add runs over K rows of W contiguous cells, where numpy's
    # cumsum along the middle axis steps through memory a row at a time (slow on a large
    # stack); uint16 halves the memory the stack and its copy move
    for i in range(n_rows):
        np.add(cum[:, i], masks[:, i], out=cum[:, i + 1], casting="unsafe")
    return SilhouetteStack(jnp.asarray(cum), float(res_mm), float(x0_mm))


def _columns(band: GripperBand, res_mm: float) -> np.ndarray:
    """Gripper-frame x of the profile columns' centres, mm: one fully-open outer face
    to the other, symmetric about 0."""
    reach = 0.5 * band.stroke_mm + band.finger_depth_mm
    n_half = int(math.ceil(reach / res_mm))
    return (np.arange(-n_half, n_half) + 0.5) * res_mm


def _check_one(stack: SilhouetteStack, band: GripperBand, x_mm, y_mm, yaw_rad, opening_mm):
    """Checks for one candidate. Returns (reason, opening_mm, coverage, gap_l, gap_r).

    opening_mm: NaN to choose the opening (``safety_zone`` outside the object); else the
    fingers are at this opening (a plan made for another pose), and an object reaching
    to or past a finger's inner face fails clearance: the finger would land on it.
    """
    cum = stack.cum_rows
    n_bins, n_rows1, n_cols = cum.shape
    res, g0 = stack.res_mm, stack.x0_mm
    # fold yaw into [0, pi): (x, y, yaw + pi) is (-x, -y, yaw) for a symmetric gripper
    turns = yaw_rad / jnp.pi
    k_float = (turns - jnp.floor(turns / 2.0) * 2.0) * n_bins  # in [0, 2K)
    k = jnp.round(k_float).astype(jnp.int32) % (2 * n_bins)
    flip = k >= n_bins
    k = jnp.where(flip, k - n_bins, k)
    sign = jnp.where(flip, -1.0, 1.0)
    x, y = sign * x_mm, sign * y_mm
    # band rows (object grid, gripper-aligned): centres in [-w/2 - y, w/2 - y]
    half_w = 0.5 * band.finger_width_mm
    i_lo = jnp.ceil((-half_w - y - g0) / res - 0.5).astype(jnp.int32)
    i_hi = jnp.floor((half_w - y - g0) / res - 0.5).astype(jnp.int32) + 1
    i_lo = jnp.clip(i_lo, 0, n_rows1 - 1)
    i_hi = jnp.clip(i_hi, 0, n_rows1 - 1)
    px = jnp.asarray(_columns(band, res), dtype=jnp.float32)
    j = jnp.floor((px - x - g0) / res).astype(jnp.int32)
    valid = (j >= 0) & (j < n_cols)
    jc = jnp.clip(j, 0, n_cols - 1)
    counts = jnp.where(
        valid, cum[k, i_hi, jc].astype(jnp.int32) - cum[k, i_lo, jc].astype(jnp.int32), 0
    )
    occupied = counts > 0

    half_stroke = 0.5 * band.stroke_mm
    in_stroke = jnp.abs(px) <= half_stroke
    inner = occupied & in_stroke
    any_inner = jnp.any(inner)
    # outer edges of the outermost occupied columns between the open fingers
    x_right = jnp.max(jnp.where(inner, px + 0.5 * res, -jnp.inf))
    x_left = jnp.min(jnp.where(inner, px - 0.5 * res, jnp.inf))
    fixed = jnp.isfinite(opening_mm)
    half_open = jnp.where(
        fixed, 0.5 * opening_mm, jnp.maximum(x_right, -x_left) + band.safety_zone_mm
    )
    opening = 2.0 * half_open
    too_wide = opening > band.stroke_mm + 1e-6
    landed = fixed & (jnp.maximum(x_right, -x_left) >= half_open)
    depth = band.finger_depth_mm
    under_right = (px >= half_open) & (px <= half_open + depth)
    under_left = (px <= -half_open) & (px >= -half_open - depth)
    blocked = jnp.any(occupied & (under_right | under_left)) | landed
    between = jnp.abs(px) < half_open
    area = jnp.sum(jnp.where(between, counts, 0)) * res * res
    coverage = area / jnp.maximum(opening * band.finger_width_mm, 1e-9)
    reason = jnp.select(
        [~any_inner, too_wide, blocked, coverage < band.min_coverage],
        [OFF_OBJECT, TOO_WIDE, CLEARANCE, COVERAGE],
        FEASIBLE,
    )
    nan = jnp.float32(jnp.nan)
    opening = jnp.where(any_inner, opening, nan)
    gap_right = jnp.where(any_inner, half_open - x_right, nan)
    gap_left = jnp.where(any_inner, half_open + x_left, nan)
    # report gaps in the unflipped frame: a flip swaps the fingers
    gap_left, gap_right = (
        jnp.where(flip, gap_right, gap_left),
        jnp.where(flip, gap_left, gap_right),
    )
    return (
        reason.astype(jnp.int32),
        opening,
        jnp.where(any_inner, coverage, 0.0),
        gap_left,
        gap_right,
    )


@functools.partial(jax.jit, static_argnames=("band", "res_mm", "x0_mm"))
def _check_batch(cum_rows, x_mm, y_mm, yaw_rad, opening_mm, band, res_mm, x0_mm):
    stack = SilhouetteStack(cum_rows, res_mm, x0_mm)
    return jax.vmap(lambda a, b, c, d: _check_one(stack, band, a, b, c, d))(
        x_mm, y_mm, yaw_rad, opening_mm
    )


def check_candidates(
    stack: SilhouetteStack, band: GripperBand, x_mm, y_mm, yaw_rad, opening_mm=None
):
    """Feasibility of N candidates at once.

    Args:
      stack: from build_stack.
      band: gripper geometry and thresholds.
      x_mm, y_mm, yaw_rad: (N,) pick-point poses (object frame relative to the gripper).
      opening_mm: (N,) fixed starting openings (NaN: choose), or None to choose all.

    Returns:
      reason (N,) int32 in REASONS order, opening_mm (N,), coverage (N,), and the gaps
      between each finger's start and the object, gap_left_mm / gap_right_mm (N,).
    """
    x = jnp.asarray(x_mm, jnp.float32)
    y = jnp.asarray(y_mm, jnp.float32)
    yaw = jnp.asarray(yaw_rad, jnp.float32)
    if opening_mm is None:
        opening = jnp.full(x.shape, jnp.nan, jnp.float32)
    else:
        opening = jnp.broadcast_to(jnp.asarray(opening_mm, jnp.float32), x.shape)
    return _check_batch(stack.cum_rows, x, y, yaw, opening, band, stack.res_mm, stack.x0_mm)


def reference_check(polygon, band: GripperBand, x_mm, y_mm, yaw_rad, res_mm=0.1, opening_mm=None):
    """Plain per-candidate reference: exact polygon, fine point sampling, no yaw bins.

    opening_mm: a fixed starting opening (see _check_one), or None to choose it.
    """
    import shapely

    px = _columns(band, res_mm)
    half_w = 0.5 * band.finger_width_mm
    n_rows = int(round(band.finger_width_mm / res_mm))
    py = -half_w + (np.arange(n_rows) + 0.5) * res_mm
    gx, gy = np.meshgrid(px, py)
    # gripper-frame point p -> object frame: R(-yaw) (p - t)
    c, s = math.cos(yaw_rad), math.sin(yaw_rad)
    dx, dy = gx - x_mm, gy - y_mm
    ox, oy = c * dx + s * dy, -s * dx + c * dy
    inside = shapely.contains_xy(polygon, ox.ravel(), oy.ravel()).reshape(gx.shape)
    counts = inside.sum(axis=0)
    occupied = counts > 0
    in_stroke = np.abs(px) <= 0.5 * band.stroke_mm
    inner = occupied & in_stroke
    if not inner.any():
        return OFF_OBJECT, math.nan, 0.0
    x_right = px[inner].max() + 0.5 * res_mm
    x_left = px[inner].min() - 0.5 * res_mm
    extent = max(x_right, -x_left)
    half_open = extent + band.safety_zone_mm if opening_mm is None else 0.5 * opening_mm
    opening = 2 * half_open
    if opening > band.stroke_mm + 1e-6:
        return TOO_WIDE, opening, 0.0
    landed = opening_mm is not None and extent >= half_open
    depth = band.finger_depth_mm
    under = ((px >= half_open) & (px <= half_open + depth)) | (
        (px <= -half_open) & (px >= -half_open - depth)
    )
    area = counts[np.abs(px) < half_open].sum() * res_mm * res_mm
    coverage = area / (opening * band.finger_width_mm)
    if landed or (occupied & under).any():
        return CLEARANCE, opening, coverage
    if coverage < band.min_coverage:
        return COVERAGE, opening, coverage
    return FEASIBLE, opening, coverage
