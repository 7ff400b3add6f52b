"""The feasibility checks of :mod:`mjx_pick.kernels.feasibility` as one Warp kernel.

Details: docs/engine.md (kernels/feasibility_warp.py).
"""

from __future__ import annotations

import collections
import threading

import numpy as np
import warp as wp

from mjx_pick.kernels import feasibility as fk
from mjx_pick.kernels import warp_runtime

# no gradients of these checks: no adjoint code to generate and compile; no fused
# multiply-adds (CUDA's default): each float32 operation rounds once, as numpy's do
wp.set_module_options({"enable_backward": False, "fuse_fp": False})

FEASIBLE = wp.constant(fk.FEASIBLE)
OFF_OBJECT = wp.constant(fk.OFF_OBJECT)
TOO_WIDE = wp.constant(fk.TOO_WIDE)
CLEARANCE = wp.constant(fk.CLEARANCE)
COVERAGE = wp.constant(fk.COVERAGE)
INT32_MIN = wp.constant(wp.int32(-(2**31)))
# silhouette stacks kept on each device (the arrays behind a checker's stack, by
# identity): a search checks group after group against one stack
KEEP_STACKS = 4


@wp.struct
class Frame:
    """The stack's grid and the band's thresholds as float32 scalars, each the float32
    that ``_check_block``'s numpy arithmetic turns its Python float into."""

    n_bins: int  # yaw bins K over [0, pi)
    n_rows1: int  # the grid's side + 1: rows of a bin's cumulated block, uncropped
    s0: int  # the columns between the open fingers: [s0, s1)
    s1: int
    bins: float  # K
    pi: float
    res: float  # pixel, mm
    x0: float  # the grid's lower-left corner, mm
    half_w: float  # half the finger width, mm
    neg_half_w: float
    half_res: float  # half a pixel, mm
    safety: float  # safety zone, mm
    depth: float  # finger depth, mm
    stroke_tol: float  # the widest opening that fits the stroke, mm
    finger_width: float  # mm
    tiny: float  # the smallest area a coverage is divided by, mm^2
    min_coverage: float
    nan: float  # numpy's float32 NaN, bit for bit


@wp.func
def as_int32(v: wp.float32) -> wp.int32:
    """numpy's float32 -> int32 cast on x86 (cvttss2si): truncated, and INT32_MIN for NaN
    and values outside int32, so non-finite or absurd poses land where numpy's do."""
    if v >= wp.float32(-2147483648.0) and v < wp.float32(2147483648.0):
        return wp.int32(v)
    return INT32_MIN


@wp.func
def search(px: wp.array(dtype=wp.float32), v: wp.float32, right: wp.bool) -> wp.int32:
    """numpy.searchsorted(px, v, side) of ascending px: the first column with px > v
    (right) or px >= v (left); NaN sorts after every number, as numpy sorts it."""
    n = px.shape[0]
    if wp.isnan(v):
        return n
    lo = wp.int32(0)
    hi = n
    while lo < hi:
        mid = (lo + hi) // 2
        below = px[mid] < v
        if right:
            below = px[mid] <= v
        if below:
            lo = mid + 1
        else:
            hi = mid
    return lo


@wp.func
def count(
    cum: wp.array(dtype=wp.uint16),
    px: wp.array(dtype=wp.float32),
    c: wp.int32,
    xs: wp.float32,
    at_lo: wp.int32,
    at_hi: wp.int32,
    col0: wp.int32,
    cols: wp.int32,
    p: Frame,
) -> wp.int32:
    """Object pixels in the band's rows of profile column c: the crop's cumulated rows
    at_hi and at_lo subtracted (0 for a grid column beside the crop)."""
    j = as_int32(wp.floor((px[c] - xs - p.x0) / p.res))
    # compared before col0 is subtracted: j may be INT32_MIN (numpy subtracts in int64)
    if j < col0 or j >= col0 + cols:
        return 0
    j = j - col0
    return wp.int32(cum[at_hi + j]) - wp.int32(cum[at_lo + j])


@wp.func
def floor_mod(k: wp.int32, m: wp.int32) -> wp.int32:
    """k mod m with the sign of m (numpy's %; C's truncates)."""
    r = k % m
    if r < 0:
        r = r + m
    return r


@wp.kernel
def check_kernel(
    cum: wp.array(dtype=wp.uint16),
    crops: wp.array2d(dtype=wp.int32),
    px: wp.array(dtype=wp.float32),
    x: wp.array(dtype=wp.float32),
    y: wp.array(dtype=wp.float32),
    yaw: wp.array(dtype=wp.float32),
    opening_in: wp.array(dtype=wp.float32),
    p: Frame,
    reason: wp.array(dtype=wp.int32),
    opening_out: wp.array(dtype=wp.float32),
    coverage_out: wp.array(dtype=wp.float32),
    gap_left: wp.array(dtype=wp.float32),
    gap_right: wp.array(dtype=wp.float32),
):
    """One candidate per thread: ``fk._check_block`` for one row, operation for
    operation in float32 (each step below names the numpy line it mirrors)."""
    t = wp.tid()
    two = wp.float32(2.0)
    # fold yaw into [0, pi): (x, y, yaw + pi) is (-x, -y, yaw) for a symmetric gripper
    turns = yaw[t] / p.pi
    k_float = (turns - wp.floor(turns / two) * two) * p.bins
    k = floor_mod(as_int32(wp.rint(k_float)), 2 * p.n_bins)
    flip = k >= p.n_bins
    sign = wp.float32(1.0)
    if flip:
        k = k - p.n_bins
        sign = wp.float32(-1.0)
    xs = sign * x[t]
    ys = sign * y[t]
    # band rows (object grid, gripper-aligned): centres in [-w/2 - y, w/2 - y]
    half = wp.float32(0.5)
    i_lo = as_int32(wp.ceil((p.neg_half_w - ys - p.x0) / p.res - half))
    i_hi = as_int32(wp.floor((p.half_w - ys - p.x0) / p.res - half)) + 1
    i_lo = wp.clamp(i_lo, 0, p.n_rows1 - 1)
    i_hi = wp.clamp(i_hi, 0, p.n_rows1 - 1)
    base = crops[k, 0]
    row0 = crops[k, 1]
    rows = crops[k, 2]
    col0 = crops[k, 3]
    cols = crops[k, 4]
    at_hi = base + wp.clamp(i_hi - row0, 0, rows) * cols
    at_lo = base + wp.clamp(i_lo - row0, 0, rows) * cols

    # the outermost occupied columns between the open fingers
    first = wp.int32(-1)
    last = wp.int32(-1)
    for c in range(p.s0, p.s1):
        if count(cum, px, c, xs, at_lo, at_hi, col0, cols, p) > 0:
            if first < 0:
                first = c
            last = c
    if first < 0:  # ~any_inner
        reason[t] = OFF_OBJECT
        opening_out[t] = p.nan
        coverage_out[t] = wp.float32(0.0)
        gap_left[t] = p.nan
        gap_right[t] = p.nan
        return
    x_right = px[last] + p.half_res
    x_left = px[first] - p.half_res
    fixed = wp.isfinite(opening_in[t])
    extent = wp.max(x_right, -x_left)
    half_open = extent + p.safety
    if fixed:
        half_open = half * opening_in[t]
    opening = two * half_open
    too_wide = opening > p.stroke_tol
    blocked = fixed and extent >= half_open  # landed

    # finger footprints: px in [h, h + depth] and [-h - depth, -h]; between: |px| < h
    r0 = search(px, half_open, False)
    r1 = wp.max(r0, search(px, half_open + p.depth, True))
    l0 = search(px, -half_open - p.depth, False)
    l1 = wp.max(l0, search(px, -half_open, True))
    m0 = search(px, -half_open, True)
    m1 = wp.max(m0, search(px, half_open, False))
    for c in range(r0, r1):
        if count(cum, px, c, xs, at_lo, at_hi, col0, cols, p) > 0:
            blocked = True
    for c in range(l0, l1):
        if count(cum, px, c, xs, at_lo, at_hi, col0, cols, p) > 0:
            blocked = True
    cells = wp.int32(0)
    for c in range(m0, m1):
        cells = cells + count(cum, px, c, xs, at_lo, at_hi, col0, cols, p)
    area = wp.float32(cells) * p.res * p.res
    coverage = area / wp.max(opening * p.finger_width, p.tiny)

    # the first check failed decides (np.select's order)
    r = FEASIBLE
    if coverage < p.min_coverage:
        r = COVERAGE
    if blocked:
        r = CLEARANCE
    if too_wide:
        r = TOO_WIDE
    reason[t] = r
    opening_out[t] = opening
    coverage_out[t] = coverage
    # report gaps in the unflipped frame: a flip swaps the fingers
    right = half_open - x_right
    left = half_open + x_left
    if flip:
        gap_left[t] = right
        gap_right[t] = left
    else:
        gap_left[t] = left
        gap_right[t] = right


def frame(stack: fk.SilhouetteStack, band: fk.GripperBand) -> tuple[Frame, np.ndarray]:
    """The kernel's scalars for stack and band, and the (C,) float32 profile columns'
    centres (mm), as ``fk._check_block`` makes them: each Python float it combines with
    a float32 array becomes that float32 (numpy's promotion of a Python scalar)."""
    f32 = np.float32
    res = stack.res_mm
    px = np.asarray(fk._columns(band, res), dtype=f32)
    half_stroke = f32(0.5 * band.stroke_mm)
    p = Frame()
    p.n_bins = len(stack.crops)
    p.n_rows1 = stack.size + 1
    p.s0 = int(np.searchsorted(px, -half_stroke, "left"))
    p.s1 = int(np.searchsorted(px, half_stroke, "right"))
    values = {
        "bins": len(stack.crops),
        "pi": np.pi,
        "res": res,
        "x0": stack.x0_mm,
        "half_w": 0.5 * band.finger_width_mm,
        "neg_half_w": -(0.5 * band.finger_width_mm),
        "half_res": 0.5 * res,
        "safety": band.safety_zone_mm,
        "depth": band.finger_depth_mm,
        "stroke_tol": band.stroke_mm + 1e-6,
        "finger_width": band.finger_width_mm,
        "tiny": 1e-9,
        "min_coverage": band.min_coverage,
        "nan": np.nan,
    }
    for name, v in values.items():
        setattr(p, name, float(f32(float(v))))
    return p, px


_stacks: collections.OrderedDict = collections.OrderedDict()
_stacks_lock = threading.Lock()


def _on_device(stack: fk.SilhouetteStack, device) -> tuple:
    """stack's cumulated cells and crop table on device, copied once: kept by the
    identity of its arrays, which the entry holds (so no other array takes their id
    while it is kept); a stack's arrays are never written after ``fk.stack_from_bits``."""
    key = (str(device), id(stack.cum), id(stack.crops))
    with _stacks_lock:
        hit = _stacks.get(key)
        if hit is not None:
            _stacks.move_to_end(key)
            return hit[2], hit[3]
    if len(stack.cum) >= 2**31:
        raise ValueError(f"a stack of {len(stack.cum)} cells does not fit int32 indices")
    cum = wp.array(np.ascontiguousarray(stack.cum), dtype=wp.uint16, device=device)
    crops = wp.array(np.asarray(stack.crops, np.int32), dtype=wp.int32, device=device)
    with _stacks_lock:
        _stacks[key] = (stack.cum, stack.crops, cum, crops)
        while len(_stacks) > KEEP_STACKS:
            _stacks.popitem(last=False)
    return cum, crops


def prepare(device="cuda:0") -> None:
    """Build (or load from Warp's kernel cache) this module's kernel for device, now:
    a first use on a machine compiles it (seconds), later processes load it."""
    warp_runtime.warp()
    wp.load_module(check_kernel.module, device=device)


def check_candidates(
    stack: fk.SilhouetteStack,
    band: fk.GripperBand,
    x_mm,
    y_mm,
    yaw_rad,
    opening_mm=None,
    device="cuda:0",
):
    """``fk.check_candidates`` on a Warp device: the candidates copied in, one thread
    each in one launch (:func:`launch`), the results copied out. The same results as
    numpy's, bit for bit (docs/engine.md says how that is tested).

    Args:
      stack, band: as fk.check_candidates (band's fields Python floats, as declared).
      x_mm, y_mm, yaw_rad: (N,) pick-point poses, as fk.check_candidates.
      opening_mm: (N,) fixed starting openings (NaN: choose), or None to choose all.
      device: a Warp device ('cuda:0'; 'cpu' runs the same kernel on the host, one
        thread).

    Returns:
      reason (N,) int32 in fk.REASONS order, opening_mm, coverage, gap_left_mm and
      gap_right_mm (N,) float32.
    """
    warp_runtime.warp()
    device = wp.get_device(device)
    poses = fk.candidates(x_mm, y_mm, yaw_rad, opening_mm)
    poses = [wp.array(np.ascontiguousarray(a), dtype=wp.float32, device=device) for a in poses]
    return tuple(out.numpy() for out in launch(stack, band, *poses))


def launch(stack: fk.SilhouetteStack, band: fk.GripperBand, x, y, yaw, opening) -> tuple:
    """The checks of (N,) candidates already on a Warp device, launched there (not waited
    for): x, y (mm), yaw (rad) and fixed openings (mm, NaN: choose) as float32 Warp arrays
    of one device. Returns the five result arrays of :func:`check_candidates` on it."""
    device, n = x.device, x.shape[0]
    outs = [wp.empty(n, dtype=wp.int32, device=device)]
    outs += [wp.empty(n, dtype=wp.float32, device=device) for _ in range(4)]
    if n:
        p, px = frame(stack, band)
        cum, crops = _on_device(stack, device)
        px = wp.array(px, dtype=wp.float32, device=device)
        inputs = [cum, crops, px, x, y, yaw, opening, p]
        wp.launch(check_kernel, dim=n, inputs=inputs, outputs=outs, device=device)
    return tuple(outs)
