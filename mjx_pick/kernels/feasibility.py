"""Geometric feasibility of pick-points (the paper's three checks), batched in numpy.

Details: docs/engine.md (kernels/feasibility.py).
"""

from __future__ import annotations

import concurrent.futures
import functools
import math
import os
from typing import NamedTuple

import numpy as np

FEASIBLE, OFF_OBJECT, TOO_WIDE, CLEARANCE, COVERAGE, PAD_PATH = range(6)
# pad_path: a linkage's near pad rides over the part (mjx_pick.core.pickpoints; not checked
# here, where only the gripper's footprint is seen)
REASONS = ("feasible", "off_object", "too_wide", "clearance", "coverage", "pad_path")
# candidates checked at once: bounds the (candidates x columns) temporaries
BLOCK = 4096
# threads that check blocks side by side (numpy releases the GIL in the block's array
# operations): every core this process may use, up to this many
MAX_THREADS = 32


class GripperBand(NamedTuple):
    """Gripper geometry and check thresholds, mm (floats)."""

    stroke_mm: float
    finger_width_mm: float
    finger_depth_mm: float
    safety_zone_mm: float
    min_coverage: float


class SilhouetteStack(NamedTuple):
    """Row-cumulated rotated silhouettes, each yaw bin cropped to the rows and columns
    its silhouette occupies (a long part fills a fraction of its square grid).

    cum: (C,) uint16, the bins' blocks one after the other. Bin k (the silhouette
      rotated by yaw k * pi / K) has crops[k] = (base, row0, rows, col0, cols): its block
      of (rows + 1, cols) cells, row-major from cum[base], holds at [i, j] the object
      pixels in grid rows row0 .. row0 + i - 1 of grid column col0 + j (at most the
      grid's side, which the raster's cell limit keeps far below 2**16).
    crops: (K, 5) int64, as above.
    size: the side of every bin's square grid, cells.
    res_mm: pixel size, mm.
    x0_mm: lower-left corner of every grid (x and y), mm.
    """

    cum: np.ndarray
    crops: np.ndarray
    size: int
    res_mm: float
    x0_mm: float


def build_stack(rasterize_window, polygon, res_mm: float, radius_mm: float) -> SilhouetteStack:
    """Rasterise the silhouette for yaw bins over [0, pi) (:func:`yaw_bins` of them).

    Yaw and yaw + pi give the same checks with (x, y) negated (the gripper is symmetric),
    so half a turn suffices.
    """
    bits, crops, size, x0 = packed_bins(rasterize_window, polygon, res_mm, radius_mm)
    return stack_from_bits(bits, crops, size, res_mm, x0)


def yaw_bins(res_mm: float, radius_mm: float) -> int:
    """Yaw bins over [0, pi): pi * radius / K <= res_mm, i.e. at most half a pixel of
    arc at the rim for the nearest bin."""
    return max(8, int(math.ceil(math.pi * radius_mm / res_mm)))


def packed_bins(rasterize_window, polygon, res_mm: float, radius_mm: float):
    """The silhouette rotated by yaw k * pi / K for each of the K yaw bins, rasterised
    by ``rasterize_window`` (``mjx_pick.core.objects.rasterize_window``: the grid where
    the polygon lies), cropped to the rows and columns it occupies and packed a bit per
    pixel.

    Returns:
      bits (B,) uint8: each bin's crop, row by row, ``np.packbits`` along the row, the
      bins one after the other; crops (K, 4) int64: each bin's row0, rows, col0, cols in
      its grid; the grids' side (cells); x0, the grids' lower-left corner (mm; the same
      for x and y and every bin).
    """
    n_bins = yaw_bins(res_mm, radius_mm)
    parts, crops = [], np.zeros((n_bins, 4), np.int64)
    x0 = size = None
    for k in range(n_bins):
        window, (x0, _), (w_row, w_col), size = rasterize_window(
            polygon, res_mm, k * math.pi / n_bins, radius_mm=radius_mm
        )
        rows, cols = np.flatnonzero(window.any(axis=1)), np.flatnonzero(window.any(axis=0))
        if len(rows):
            r0, r1, c0, c1 = rows[0], rows[-1] + 1, cols[0], cols[-1] + 1
            crops[k] = (w_row + r0, r1 - r0, w_col + c0, c1 - c0)
            parts.append(np.packbits(window[r0:r1, c0:c1].astype(bool), axis=1).ravel())
    bits = np.concatenate(parts) if parts else np.zeros(0, np.uint8)
    return bits, crops, int(size), float(x0)


def stack_from_bits(
    bits: np.ndarray, crops: np.ndarray, size: int, res_mm: float, x0_mm: float
) -> SilhouetteStack:
    """The row-cumulated stack of :func:`packed_bins`' bits and crops."""
    if size >= 2**16:
        raise ValueError(f"a raster of {size} rows does not fit the uint16 stack")
    crops = np.asarray(crops, np.int64)
    rows, cols = crops[:, 1], crops[:, 3]
    cells = (rows + 1) * cols
    base = np.concatenate([[0], np.cumsum(cells)[:-1]])
    cum = np.empty(int(cells.sum()), np.uint16)
    offset = 0  # in bits' bytes
    for k in range(len(crops)):
        r, c = int(rows[k]), int(cols[k])
        n_bytes = r * (-(-c // 8))
        mask = np.unpackbits(bits[offset : offset + n_bytes].reshape(r, -1), axis=1, count=c)
        offset += n_bytes
        block = cum[base[k] : base[k] + cells[k]].reshape(r + 1, c)
        block[0] = 0
        np.cumsum(mask, axis=0, dtype=np.uint16, out=block[1:])
    table = np.column_stack([base, crops]).astype(np.int64)
    return SilhouetteStack(cum, table, int(size), float(res_mm), float(x0_mm))


def _columns(band: GripperBand, res_mm: float) -> np.ndarray:
    """Gripper-frame x of the profile columns' centres, mm: one fully-open outer face
    to the other, symmetric about 0."""
    reach = 0.5 * band.stroke_mm + band.finger_depth_mm
    n_half = int(math.ceil(reach / res_mm))
    return (np.arange(-n_half, n_half) + 0.5) * res_mm


def _span(prefix: np.ndarray, start: np.ndarray, stop: np.ndarray) -> np.ndarray:
    """(N,) sums of columns [start, stop) of each row, from row-wise prefix sums
    (N, C + 1); an empty or reversed span sums to 0."""
    stop = np.maximum(start, stop)
    take = np.take_along_axis
    return take(prefix, stop[:, None], 1)[:, 0] - take(prefix, start[:, None], 1)[:, 0]


def _check_block(stack: SilhouetteStack, band: GripperBand, x, y, yaw, opening_mm):
    """Checks for (N,) float32 candidates; see :func:`check_candidates`.

    Float32 throughout, operation for operation as the per-candidate definition: the
    column profile is gathered, and the finger footprints and the region between them,
    contiguous runs of the (ascending) columns, are summed from prefix sums.
    """
    f32 = np.float32
    n_bins, n_rows1 = len(stack.crops), stack.size + 1
    res, g0 = stack.res_mm, stack.x0_mm
    # fold yaw into [0, pi): (x, y, yaw + pi) is (-x, -y, yaw) for a symmetric gripper
    turns = yaw / np.pi
    k_float = (turns - np.floor(turns / 2.0) * 2.0) * n_bins  # in [0, 2K)
    k = np.round(k_float).astype(np.int32) % (2 * n_bins)
    flip = k >= n_bins
    k = np.where(flip, k - n_bins, k)
    sign = np.where(flip, f32(-1.0), f32(1.0))
    x, y = sign * x, sign * y
    # band rows (object grid, gripper-aligned): centres in [-w/2 - y, w/2 - y]
    half_w = 0.5 * band.finger_width_mm
    i_lo = np.ceil((-half_w - y - g0) / res - 0.5).astype(np.int32)
    i_hi = np.floor((half_w - y - g0) / res - 0.5).astype(np.int32) + 1
    i_lo = np.clip(i_lo, 0, n_rows1 - 1)
    i_hi = np.clip(i_hi, 0, n_rows1 - 1)
    px = np.asarray(_columns(band, res), dtype=f32)
    j = np.floor((px - x[:, None] - g0) / res).astype(np.int32)
    # the band's rows and columns in bin k's crop: rows above and below it hold nothing
    # (clipped to its ends), columns beside it nothing (counted 0)
    base, row0, rows, col0, cols = stack.crops[k].T
    j = j - col0[:, None]
    valid = (j >= 0) & (j < cols[:, None])
    at_hi = base + np.clip(i_hi - row0, 0, rows) * cols
    at_lo = base + np.clip(i_lo - row0, 0, rows) * cols
    hi = np.where(valid, at_hi[:, None] + j, 0)
    lo = np.where(valid, at_lo[:, None] + j, 0)
    counts = np.where(valid, stack.cum[hi].astype(np.int32) - stack.cum[lo], 0)
    occupied = counts > 0

    # the columns between the open fingers, a contiguous run
    half_stroke = f32(0.5 * band.stroke_mm)
    s0 = int(np.searchsorted(px, -half_stroke, "left"))  # |px| <= half the stroke
    s1 = int(np.searchsorted(px, half_stroke, "right"))
    inner = occupied[:, s0:s1]
    any_inner = inner.any(axis=1)
    # outer edges of the outermost occupied columns between the open fingers
    last = s1 - 1 - inner[:, ::-1].argmax(axis=1)
    first = s0 + inner.argmax(axis=1)
    x_right = np.where(any_inner, (px + 0.5 * res)[last], f32(-np.inf))
    x_left = np.where(any_inner, (px - 0.5 * res)[first], f32(np.inf))
    fixed = np.isfinite(opening_mm)
    half_open = np.where(
        fixed, 0.5 * opening_mm, np.maximum(x_right, -x_left) + band.safety_zone_mm
    )
    opening = 2.0 * half_open
    too_wide = opening > band.stroke_mm + 1e-6
    landed = fixed & (np.maximum(x_right, -x_left) >= half_open)
    # finger footprints: px in [h, h + depth] and [-h - depth, -h]; between: |px| < h
    depth = band.finger_depth_mm
    n = len(x)
    occ = np.zeros((n, px.size + 1), np.int32)
    np.cumsum(occupied, axis=1, out=occ[:, 1:])
    cnt = np.zeros((n, px.size + 1), np.int32)
    np.cumsum(counts, axis=1, out=cnt[:, 1:])

    def col(v, side):  # the first column with px > v ("right") or px >= v ("left")
        return np.searchsorted(px, v, side).astype(np.intp)

    under_right = _span(occ, col(half_open, "left"), col(half_open + depth, "right"))
    under_left = _span(occ, col(-half_open - depth, "left"), col(-half_open, "right"))
    blocked = (under_right > 0) | (under_left > 0) | landed
    area = _span(cnt, col(-half_open, "right"), col(half_open, "left")).astype(f32) * res * res
    coverage = area / np.maximum(opening * band.finger_width_mm, 1e-9)
    reason = np.select(
        [~any_inner, too_wide, blocked, coverage < band.min_coverage],
        [OFF_OBJECT, TOO_WIDE, CLEARANCE, COVERAGE],
        FEASIBLE,
    )
    nan = f32(np.nan)
    opening = np.where(any_inner, opening, nan)
    gap_right = np.where(any_inner, half_open - x_right, nan)
    gap_left = np.where(any_inner, half_open + x_left, nan)
    # report gaps in the unflipped frame: a flip swaps the fingers
    gap_left, gap_right = np.where(flip, gap_right, gap_left), np.where(flip, gap_left, gap_right)
    return (
        reason.astype(np.int32),
        opening,
        np.where(any_inner, coverage, f32(0.0)),
        gap_left,
        gap_right,
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
        With a fixed opening, an object reaching to or past a finger's inner face fails
        clearance: the finger would land on it (a plan made for another pose).

    Returns:
      reason (N,) int32 in REASONS order, opening_mm (N,), coverage (N,), and the gaps
      between each finger's start and the object, gap_left_mm / gap_right_mm (N,), all
      float32.
    """
    x, y, yaw, opening = candidates(x_mm, y_mm, yaw_rad, opening_mm)

    def check(s: int):
        b = slice(s, s + BLOCK)
        # NaN openings and gaps of candidates off the object are expected, not warned
        # of (np.errstate holds for the thread it is set in)
        with np.errstate(invalid="ignore"):
            return _check_block(stack, band, x[b], y[b], yaw[b], opening[b])

    starts = range(0, max(len(x), 1), BLOCK)
    if len(starts) == 1:
        parts = [check(0)]
    else:  # blocks are independent: the same results in any order, kept in order
        parts = list(_pool().map(check, starts))
    return tuple(np.concatenate(p) for p in zip(*parts, strict=True))


def candidates(x_mm, y_mm, yaw_rad, opening_mm=None):
    """(N,) float32 x, y, yaw and fixed openings (NaN: choose) of check_candidates'
    arguments: y, yaw and opening broadcast to x's shape, None as every opening NaN."""
    x = np.atleast_1d(np.asarray(x_mm, np.float32))
    y = np.broadcast_to(np.asarray(y_mm, np.float32), x.shape)
    yaw = np.broadcast_to(np.asarray(yaw_rad, np.float32), x.shape)
    if opening_mm is None:
        opening = np.full(x.shape, np.nan, np.float32)
    else:
        opening = np.broadcast_to(np.asarray(opening_mm, np.float32), x.shape)
    return x, y, yaw, opening


def threads() -> int:
    """Threads that check candidate blocks side by side: the cores this process may use."""
    try:
        cores = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        cores = os.cpu_count() or 1
    return max(1, min(cores, MAX_THREADS))


@functools.cache
def _pool() -> concurrent.futures.ThreadPoolExecutor:
    return concurrent.futures.ThreadPoolExecutor(threads(), thread_name_prefix="feasibility")


# a forked child (Ray's workers, the GUI's) has none of its parent's threads: it makes
# a pool of its own (no fork where there is no register_at_fork)
if hasattr(os, "register_at_fork"):
    os.register_at_fork(after_in_child=_pool.cache_clear)


def reference_check(polygon, band: GripperBand, x_mm, y_mm, yaw_rad, res_mm=0.1, opening_mm=None):
    """Plain per-candidate reference: exact polygon, fine point sampling, no yaw bins.

    opening_mm: a fixed starting opening (see check_candidates), or None to choose it.
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
