"""Grasps: the gripper's pose in the object's frame, batched; pick-points are the vertical ones.

Frames and the decomposition: docs/formats.md ("Grasps").
"""

from __future__ import annotations

import dataclasses

import numpy as np

# E (the exchange frame: approach +z, closing along x) is G (z up, the gripper approaching
# along -z) turned half a turn about x: R_E = R_G . FLIP
FLIP = np.diag([1.0, -1.0, -1.0])
# an approach closer than this to straight up (from under the table) has no heading:
# the decomposition refuses it
_UPWARD_COS = -1.0 + 1e-9


@dataclasses.dataclass(frozen=True)
class GraspBatch:
    """Grasps, one entry per grasp (arrays (N,) unless said).

    A grasp is the gripper's pose in the object frame O (origin at the centre of mass
    on the table, z up), held as the parts the scene places it by: the object's planar
    pose under the grasp centre in the gripper's heading frame (x_mm, y_mm, yaw_deg: a
    pick-point), the approach's tilt from vertical (tilt_quat (N, 4), w x y z: a
    rotation of the gripper about a horizontal axis of that frame) and the grasp
    centre's height above the table (height_mm). A pick-point is the grasp whose tilt
    and height are None: vertical, at the procedure's grasp height.
    :func:`poses` and :func:`from_poses` convert to and from 4x4 transforms.

    pick_id: the grasp's id (a pick-point's: its index in its generator's stream).
    opening_mm: starting distance between the pads.
    gap_left_mm / gap_right_mm: each pad's start distance from the object.
    coverage: the object's share of the region between the pads (NaN: not measured).
    rejected: candidates dropped per reason; n_candidates: how many were checked.
    """

    pick_id: np.ndarray
    x_mm: np.ndarray
    y_mm: np.ndarray
    yaw_deg: np.ndarray
    opening_mm: np.ndarray
    coverage: np.ndarray
    gap_left_mm: np.ndarray
    gap_right_mm: np.ndarray
    rejected: dict
    n_candidates: int
    mode: str = "normal"
    tilt_quat: np.ndarray | None = None  # (N, 4); None: every grasp vertical
    height_mm: np.ndarray | None = None  # None: the procedure's grasp height

    def __len__(self) -> int:
        return len(self.pick_id)

    def take(self, index) -> GraspBatch:
        """A sub-batch (index: slice, int array or bool mask)."""
        arrays = {
            f.name: getattr(self, f.name)[index]
            for f in dataclasses.fields(self)
            if isinstance(getattr(self, f.name), np.ndarray)
        }
        return dataclasses.replace(self, **arrays)

    @property
    def grasp_gap_mm(self) -> np.ndarray:
        """(N,) mm: the gap the pads close to, the object's width between them."""
        return self.opening_mm - self.gap_left_mm - self.gap_right_mm

    @property
    def is_pick_points(self) -> bool:
        """Whether these are pick-points: vertical, at the procedure's grasp height."""
        return self.tilt_quat is None and self.height_mm is None

    def columns(self) -> dict:
        """Per-grasp columns for a results table."""
        return {
            "pick_id": self.pick_id,
            "x_mm": self.x_mm,
            "y_mm": self.y_mm,
            "yaw_deg": self.yaw_deg,
            "opening_mm": self.opening_mm,
            "coverage": self.coverage,
        }

    def pose_columns(self, default_height_mm: float) -> dict:
        """The columns a results table adds for grasps that are not pick-points (none for
        pick-points): the grasp centre's height (mm), the approach's tilt from vertical
        (deg) and ``grasp_pose``, the grasp frame in O as 16 numbers, row-major, metres
        (:func:`poses`)."""
        if self.is_pick_points:
            return {}
        t = poses(self, default_height_mm)
        return {
            "height_mm": heights_mm(self, default_height_mm),
            "tilt_deg": tilt_deg(self),
            "grasp_pose": list(t.reshape(len(self), 16)),
        }


def concat(batches: list[GraspBatch]) -> GraspBatch:
    """Join batches (rejection counts add up). Pick-points join pick-points; grasps
    with a tilt or height join others that have them."""
    first = batches[0]
    kinds = {(b.tilt_quat is None, b.height_mm is None) for b in batches}
    if len(kinds) > 1:
        raise ValueError("cannot join pick-points and grasps given as poses in one batch")
    arrays = {
        f.name: np.concatenate([getattr(b, f.name) for b in batches])
        for f in dataclasses.fields(first)
        if isinstance(getattr(first, f.name), np.ndarray)
    }
    rejected = {}
    for b in batches:
        for r, count in b.rejected.items():
            rejected[r] = rejected.get(r, 0) + int(count)
    return dataclasses.replace(
        first, **arrays, rejected=rejected, n_candidates=sum(b.n_candidates for b in batches)
    )


# ------------------------------------------------------------------------- rotations
def quat_to_mat(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3) rotation matrices."""
    q = np.asarray(q, float)
    w, x, y, z = (q[..., i] for i in range(4))
    return np.stack(
        [
            np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)], -1),
            np.stack([2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)], -1),
            np.stack([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)], -1),
        ],
        -2,
    )


def rz(angle_rad) -> np.ndarray:
    """(..., 3, 3) rotations about z by angle_rad (...)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack(
        [np.stack([c, -s, z], -1), np.stack([s, c, z], -1), np.stack([z, z, o], -1)], -2
    )


def swing_quat(up: np.ndarray) -> np.ndarray:
    """(N, 4) the shortest rotations taking e_z to the unit vectors up (N, 3): each about
    a horizontal axis (w, x, y, 0); exactly the identity where up is e_z."""
    up = np.asarray(up, float)
    c = np.clip(up[:, 2], -1.0, 1.0)
    # q = (1 + c, -up_y, up_x, 0) normalised: half the angle between e_z and up
    q = np.stack([1.0 + c, -up[:, 1], up[:, 0], np.zeros_like(c)], -1)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    vertical = (up[:, 0] == 0) & (up[:, 1] == 0) & (up[:, 2] > 0)
    q[vertical] = (1.0, 0.0, 0.0, 0.0)
    return q


def tilt_deg(grasps: GraspBatch) -> np.ndarray:
    """(N,) deg: each grasp's approach from vertical (0: straight down)."""
    if grasps.tilt_quat is None:
        return np.zeros(len(grasps))
    return quat_tilt_deg(grasps.tilt_quat)


def quat_tilt_deg(tilt_quat: np.ndarray) -> np.ndarray:
    """(N,) deg: the turn of tilt quaternions (N, 4) w, x, y, z (NaN where NaN, as
    :func:`decompose` gives a grasp from under the table)."""
    w = np.clip(np.abs(tilt_quat[:, 0]), 0.0, 1.0)
    return np.rad2deg(2.0 * np.arccos(w))


def heights_mm(grasps: GraspBatch, default_height_mm: float) -> np.ndarray:
    """(N,) mm: each grasp centre's height above the table (default_height_mm, the
    procedure's grasp height, where the batch gives none)."""
    if grasps.height_mm is None:
        return np.full(len(grasps), float(default_height_mm))
    return np.asarray(grasps.height_mm, float)


# ----------------------------------------------------------------------- conversions
def poses(grasps: GraspBatch, default_height_mm: float) -> np.ndarray:
    """(N, 4, 4) the grasp frames in the object frame O, metres: E's axes (approach +z,
    closing along x), origin at the grasp centre (the pads' centre at the grasp).

    With the heading frame H at the grasp centre (world axes), the object lies at
    (x, y, -height) turned by yaw and the gripper is turned by the tilt S:
    R_OG = Rz(-yaw) S, p_OG = -Rz(-yaw) (x, y, -height); R_OE = R_OG FLIP.
    """
    n = len(grasps)
    yaw = np.deg2rad(np.asarray(grasps.yaw_deg, float))
    back = rz(-yaw)
    tilt = np.broadcast_to(np.eye(3), (n, 3, 3))
    if grasps.tilt_quat is not None:
        tilt = quat_to_mat(grasps.tilt_quat)
    h = heights_mm(grasps, default_height_mm) * 1e-3
    obj = np.stack([grasps.x_mm * 1e-3, grasps.y_mm * 1e-3, -h], -1)
    out = np.zeros((n, 4, 4))
    out[:, :3, :3] = back @ tilt @ FLIP
    out[:, :3, 3] = -np.einsum("nij,nj->ni", back, obj)
    out[:, 3, 3] = 1.0
    return out


def decompose(poses_oe: np.ndarray) -> dict[str, np.ndarray]:
    """The planar pose, tilt and height of grasp frames (N, 4, 4) in O (E's axes,
    origin at the grasp centre, metres): the inverse of :func:`poses`.

    Returns x_mm, y_mm, yaw_deg (N,), tilt_quat (N, 4), height_mm (N,) and upward (N,)
    bool: an approach from under the table (within 1e-9 of straight up), which has no
    heading; its other values are NaN.
    """
    t = np.asarray(poses_oe, float)
    r_og = t[:, :3, :3] @ FLIP
    up = r_og[:, :, 2]  # G's z (the gripper's up, against the approach) in O
    upward = up[:, 2] <= _UPWARD_COS
    swing_o = swing_quat(np.where(upward[:, None], (0.0, 0.0, 1.0), up))
    # R_OG = S_O Rz(-yaw): the twist left after the swing is a turn about z
    twist = np.swapaxes(quat_to_mat(swing_o), 1, 2) @ r_og
    yaw = -np.arctan2(twist[:, 1, 0], twist[:, 0, 0])
    # the same swing seen in the heading frame: R_OG = Rz(-yaw) S_H, S_H = Rz(yaw) S_O Rz(-yaw)
    axis = np.einsum("nij,nj->ni", rz(yaw), swing_o[:, 1:])
    tilt = np.concatenate([swing_o[:, :1], axis], 1)
    tilt[np.all(swing_o == (1.0, 0.0, 0.0, 0.0), axis=1)] = (1.0, 0.0, 0.0, 0.0)
    p = np.einsum("nij,nj->ni", rz(yaw), t[:, :3, 3])  # -(x, y, -height)
    out = {
        "x_mm": -p[:, 0] * 1e3,
        "y_mm": -p[:, 1] * 1e3,
        "yaw_deg": np.rad2deg(yaw),
        "tilt_quat": tilt,
        "height_mm": p[:, 2] * 1e3,
        "upward": upward,
    }
    for name in ("x_mm", "y_mm", "yaw_deg", "height_mm"):
        out[name] = np.where(upward, np.nan, out[name])
    out["tilt_quat"] = np.where(upward[:, None], np.nan, out["tilt_quat"])
    return out


def from_poses(
    poses_oe: np.ndarray,
    pick_id=None,
    opening_mm=None,
    gap_left_mm=None,
    gap_right_mm=None,
    coverage=None,
    mode: str = "poses",
) -> GraspBatch:
    """A GraspBatch of grasp frames (N, 4, 4) in O (:func:`decompose`; none upward).

    opening_mm, gap_*_mm: the start opening and each pad's distance from the part
    (``grasp_feasibility`` measures them); NaN until then."""
    d = decompose(poses_oe)
    if np.any(d["upward"]):
        raise ValueError("a grasp approaches from under the table: it has no pose here")
    n = len(d["x_mm"])
    nan = np.full(n, np.nan)

    def arr(v):
        return nan.copy() if v is None else np.asarray(v, float).reshape(n)

    return GraspBatch(
        pick_id=np.arange(n, dtype=np.int64) if pick_id is None else np.asarray(pick_id, np.int64),
        x_mm=d["x_mm"],
        y_mm=d["y_mm"],
        yaw_deg=d["yaw_deg"],
        opening_mm=arr(opening_mm),
        coverage=arr(coverage),
        gap_left_mm=arr(gap_left_mm),
        gap_right_mm=arr(gap_right_mm),
        rejected={},
        n_candidates=n,
        mode=mode,
        tilt_quat=d["tilt_quat"],
        height_mm=d["height_mm"],
    )


# a rotation further than this from orthonormal (max |R^T R - I|) is not a rotation
# rounded for a file: refused rather than projected (grasp poses and a mesh's pose alike)
ORTHONORMAL_TOL = 1e-3


def nearest_rotation(r: np.ndarray) -> np.ndarray:
    """(..., 3, 3) the nearest rotations (SVD) of near-orthonormal matrices: a writer's
    rounding removed."""
    u, _, vt = np.linalg.svd(r)
    return u @ vt


def pose_numbers(text: str | None, where: str) -> list[float]:
    """The 16 numbers of a 4x4 pose written as text (row-major, separated by spaces), or
    a ConfigError naming where (a file's line and column) and the text."""
    from mjx_pick.core.config import ConfigError

    try:
        values = [float(v) for v in (text or "").split()]
    except ValueError:
        values = []
    if len(values) != 16:
        raise ConfigError(
            f"{where}: {text!r} is not 16 numbers separated by spaces (a 4x4 pose, "
            "row-major, metres)"
        )
    return values


def rigid_poses(values, where: str, rows=None) -> np.ndarray:
    """(N, 4, 4) rigid transforms from values (N, 16) or (N, 4, 4): each finite, its
    last row 0 0 0 1, its rotation proper and orthonormal within ORTHONORMAL_TOL
    (re-orthonormalised: files round their rotations), else a ConfigError naming
    `where` and each bad row (rows: their names, default their indices)."""
    from mjx_pick.core.config import ConfigError

    t = np.asarray(values, float).reshape(-1, 4, 4).copy()
    names = [str(r) for r in (range(len(t)) if rows is None else rows)]
    bad: list[str] = []
    finite = np.all(np.isfinite(t), axis=(1, 2))
    bottom = np.all(np.abs(t[:, 3] - (0.0, 0.0, 0.0, 1.0)) < 1e-9, axis=1)
    r = np.where(finite[:, None, None], t[:, :3, :3], np.eye(3))
    error = np.abs(np.swapaxes(r, 1, 2) @ r - np.eye(3)).max(axis=(1, 2))
    proper = np.linalg.det(r) > 0
    for i in range(len(t)):
        if not finite[i]:
            bad.append(f"{names[i]}: not finite")
        elif not bottom[i]:
            bad.append(f"{names[i]}: its last row is {t[i, 3].tolist()}, not 0 0 0 1")
        elif error[i] > ORTHONORMAL_TOL or not proper[i]:
            what = "a reflection" if not proper[i] else f"{error[i]:.2g} from orthonormal"
            bad.append(f"{names[i]}: its rotation is {what} (allowed {ORTHONORMAL_TOL:g})")
    if bad:
        more = f" (and {len(bad) - 5} more)" if len(bad) > 5 else ""
        raise ConfigError(
            f"{where}: {len(bad)} pose(s) are not rigid transforms: {'; '.join(bad[:5])}{more}"
        )
    t[:, :3, :3] = nearest_rotation(t[:, :3, :3])
    return t
