"""Antipodal grasp candidates on a part's mesh, as ACRONYM and GraspDataGen draw them.

Details: docs/formats.md ("Grasps": candidates on meshes).
"""

from __future__ import annotations

import dataclasses
import logging
import time
import warnings
from collections.abc import Callable

import numpy as np
import trimesh

from mjx_pick.core.config import ConfigError, check_fields, check_range, setting
from mjx_pick.core.grasp_checks import REASON_WORDS, GraspChecker
from mjx_pick.core.grasps import GraspBatch, concat
from mjx_pick.core.scene import Scene

log = logging.getLogger(__name__)
# surface points drawn per block: same seed, same stream
SURFACE_BLOCK = 1024


@dataclasses.dataclass(frozen=True)
class AntipodalConfig:
    """How antipodal candidates are drawn (defaults in the spirit of ACRONYM's sampler)."""

    cone_deg: float = setting(
        15.0,
        "deg",
        "largest angle between the closing line and either surface normal (an antipodal pair)",
        lo=0,
        hi=60,
    )
    max_tilt_deg: float = setting(
        60.0,
        "deg",
        "largest angle of the approach from straight down (grasps from above the table)",
        lo=0,
        hi=90,
    )
    approaches: int = setting(
        8, "per pair", "approach directions tried about each pair's closing line", lo=1, hi=64
    )
    min_width_mm: float = setting(
        1.0, "mm", "narrowest part between the pads considered", lo=0, hi=1000
    )
    table_clearance_mm: float = setting(
        2.0,
        "mm",
        "the pads' lowest corner at least this far above the table (the grasp centre moves "
        "back along the approach, the contacts staying on the pads)",
        lo=0,
        hi=100,
    )
    max_candidates: int = setting(
        200_000, "candidates", "the search gives up after checking this many", lo=1, hi=1e8
    )

    def __post_init__(self):
        check_fields(self, "antipodal")


def antipodal_poses(
    mesh: trimesh.Trimesh,
    pad_mm: tuple[float, float, float],
    config: AntipodalConfig,
    rng: np.random.Generator,
) -> np.ndarray:
    """Grasp frames (M, 4, 4) in the object frame (E's axes, origin at the grasp centre;
    the table at z = 0) from SURFACE_BLOCK surface points on mesh.

    Each point, the opposite surface along its inward normal, kept when both normals
    lie within cone_deg of the line and the part between them is narrower than the
    stroke; then ``approaches`` approach directions about the line, those within
    max_tilt_deg of straight down; then the grasp centre drawn back along the approach
    from the contacts' midpoint, at least as far as keeps the pads' lowest corner
    table_clearance_mm above the table, at most as far as keeps the contacts on the pads
    (within 90 % of half the pad's height). pad_mm: (stroke, pad width, pad height)."""
    stroke_mm, pad_w, pad_h = pad_mm
    points, faces = trimesh.sample.sample_surface(mesh, SURFACE_BLOCK, seed=rng)
    normals = mesh.face_normals[faces]
    inward = -normals
    origins = points + 1e-6 * inward  # just inside: the first hit is the far side
    loc, ray, tri = mesh.ray.intersects_location(origins, inward, multiple_hits=False)
    width = np.einsum("ij,ij->i", loc - points[ray], inward[ray])
    far_normal = mesh.face_normals[tri]
    cos_cone = np.cos(np.deg2rad(config.cone_deg))
    keep = (
        (width >= config.min_width_mm * 1e-3)
        & (width <= stroke_mm * 1e-3)
        & (np.einsum("ij,ij->i", far_normal, inward[ray]) >= cos_cone)
    )
    ray, width = ray[keep], width[keep]
    if not len(ray):
        return np.zeros((0, 4, 4))
    # the closing axis from one contact to the other, its sign drawn (the gripper is
    # symmetric: both are grasps, half a turn apart about the approach)
    sign = np.where(rng.random(len(ray)) < 0.5, 1.0, -1.0)[:, None]
    x = sign * inward[ray]
    centre = points[ray] + 0.5 * width[:, None] * inward[ray]
    # an orthonormal basis (u, v) across the closing axis
    helper = np.where(np.abs(x[:, 2:3]) < 0.9, [[0.0, 0.0, 1.0]], [[1.0, 0.0, 0.0]])
    u = np.cross(x, helper)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    v = np.cross(x, u)
    k = config.approaches
    angle = rng.uniform(0.0, 2 * np.pi, (len(ray), 1)) + 2 * np.pi * np.arange(k) / k
    z = np.cos(angle)[..., None] * u[:, None] + np.sin(angle)[..., None] * v[:, None]
    z = z.reshape(-1, 3)  # approach directions, (P * k, 3)
    xs = np.repeat(x, k, axis=0)
    cs = np.repeat(centre, k, axis=0)
    down = -z[:, 2] >= max(np.cos(np.deg2rad(config.max_tilt_deg)), 1e-6)
    z, xs, cs = z[down], xs[down], cs[down]
    ys = np.cross(z, xs)
    # the pads' corners' heights with the centre at the contacts (E: y across, z along
    # the approach), and how far back the centre must move to lift them clear
    corners = np.array([(a, b) for a in (-0.5, 0.5) for b in (-0.5, 0.5)]) * (pad_w, pad_h)
    low = cs[:, 2] + np.min(corners[:, 0] * ys[:, 2:3] + corners[:, 1] * z[:, 2:3], axis=1) * 1e-3
    need = np.maximum(0.0, (config.table_clearance_mm * 1e-3 - low) / -z[:, 2])
    most = 0.45 * pad_h * 1e-3
    fits = need <= most
    z, xs, ys, cs, need = z[fits], xs[fits], ys[fits], cs[fits], need[fits]
    back = need + rng.random(len(need)) * (most - need)
    out = np.zeros((len(z), 4, 4))
    out[:, :3, 0] = xs
    out[:, :3, 1] = ys
    out[:, :3, 2] = z
    out[:, :3, 3] = cs - back[:, None] * z
    out[:, 3, 3] = 1.0
    return out


def generate_antipodal(
    scene: Scene,
    n: int,
    seed: int = 0,
    config: AntipodalConfig | None = None,
    safety_zone_mm: float = 5.0,
    progress: Callable[[int, int, dict], None] | None = None,
) -> GraspBatch:
    """The first n feasible antipodal grasps (``GraspChecker``) of the seeded stream on
    the scene's part, for its gripper; pick_id: each candidate's index in the stream.
    progress(drawn, found, rejected) after each block (it may raise to stop)."""
    check_range("grasps", "n", n, 1, 1e9)
    config = config or AntipodalConfig()
    checker = GraspChecker(scene, safety_zone_mm)
    rng = np.random.default_rng(seed)
    mesh = scene.object.mesh
    g = scene.gripper
    pad_mm = (float(g.stroke_mm), float(g.finger_width_mm), float(g.pad_height_mm))
    batches: list[GraspBatch] = []
    found = drawn = 0
    rejected: dict[str, int] = {}
    noted = time.monotonic()
    idle = 0
    while found < n and drawn < config.max_candidates:
        poses = antipodal_poses(mesh, pad_mm, config, rng)
        idle = idle + 1 if not len(poses) else 0
        if idle >= 8:  # no antipodal pair in 8 blocks of surface points: none will come
            break
        ids = np.arange(drawn, drawn + len(poses))
        block = checker.batch(ids, poses, mode="antipodal")
        batches.append(block)
        drawn += len(poses)
        found += len(block)
        for reason, count in block.rejected.items():
            rejected[reason] = rejected.get(reason, 0) + count
        if progress is not None:
            progress(drawn, found, rejected)
        if time.monotonic() - noted > 2.0:
            log.info(
                "antipodal grasps: %d of %d found after %d candidates", min(found, n), n, drawn
            )
            noted = time.monotonic()
    if not batches or found == 0:
        raise ConfigError(
            f"no feasible antipodal grasp on {scene.object.name!r} for {scene.gripper.name} "
            f"after {drawn:,} candidates: {rejected_words(rejected)}"
        )
    grasps = concat(batches)
    if len(grasps) < n:
        warnings.warn(
            f"only {len(grasps)} of {n} antipodal grasps are feasible after {drawn:,} "
            f"candidates (rejected: {rejected_words(rejected)})",
            stacklevel=2,
        )
        return grasps
    return dataclasses.replace(grasps.take(slice(0, n)), rejected=rejected, n_candidates=drawn)


def rejected_words(rejected: dict) -> str:
    """Rejection counts in words, most first."""
    shown = sorted(((int(v), k) for k, v in rejected.items() if v), reverse=True)
    text = "; ".join(f"{v:,}: {REASON_WORDS.get(k, k)}" for v, k in shown)
    return text or "no antipodal pair within the stroke and the friction cone"
