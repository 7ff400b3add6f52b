"""Feasibility of grasps given as poses, on the part's mesh and the gripper's geoms.

Details: docs/formats.md ("Grasps": the checks).
"""

from __future__ import annotations

import copy
import dataclasses

import mujoco
import numpy as np

from mjx_pick.core import grasps as gm
from mjx_pick.core.grasps import GraspBatch
from mjx_pick.core.scene import Scene

# why a grasp is rejected, in checking order ("feasible" first: the codes' order)
REASONS = ("feasible", "off_object", "too_wide", "collision", "table")
FEASIBLE, OFF_OBJECT, TOO_WIDE, COLLISION, TABLE = range(len(REASONS))
# each in a user's words (messages, the GUI, validation's counts)
REASON_WORDS = {
    "feasible": "feasible",
    "off_object": "nothing lies between the pads",
    "too_wide": "the part is wider than the stroke where the pads meet it",
    "collision": "the open gripper touches the part",
    "table": "the gripper touches the table (open, or closed on the part)",
}
# rays cast along the closing axis from each pad's face: a RAYS x RAYS grid over it
RAYS = 7
# a penetration deeper than this counts as touching: the scene's contact margin of the
# pads, and MuJoCo's distance of two meshes resting on each other, are a fraction of it
TOUCH_M = 1e-4


class GraspChecker:
    """The checks a grasp given as a pose must pass before it is simulated, for one
    scene (its object's mesh, its gripper's geoms and the table).

    Rejected only for what the real gripper cannot do: nothing between the pads (rays
    along the closing axis over the pads' faces meet no part), the part wider than the
    stroke between them, the fully open gripper touching the part, the gripper touching
    the table (fully open, or closed onto the part). The paper's speed rule then picks
    where the fingers start -- each ``safety_zone_mm`` from the part, the widest
    opening if the gripper would touch the part there -- instead of rejecting.
    """

    def __init__(self, scene: Scene, safety_zone_mm: float = 5.0):
        self.scene, self.safety_zone_mm = scene, float(safety_zone_mm)
        g = scene.gripper
        self.stroke_mm = float(g.stroke_mm)
        self.pad_width_mm, self.pad_height_mm = float(g.finger_width_mm), float(g.pad_height_mm)
        m = scene.model
        # a model of our own: the tilt of each grasp is written into its fields
        self.model = copy.deepcopy(m)
        self.data = mujoco.MjData(self.model)
        self.gripper_geoms = gripper_geoms(scene)
        # the part as the pads meet it: its convex pieces (a mesh geom of the whole part
        # would collide as its convex hull, closing every concave gap)
        names = [m.geom(i).name for i in range(m.ngeom)]
        self.part_geoms = np.array([i for i, nm in enumerate(names) if nm.startswith("piece")])
        self.table_geom = m.geom("table").id
        self.part_and_table = np.append(self.part_geoms, self.table_geom)

    def __call__(self, poses_oe: np.ndarray) -> dict[str, np.ndarray]:
        """Check grasp frames (N, 4, 4) in the object frame (E's axes, origin at the
        grasp centre, metres).

        Returns reason (N,) int (REASONS), opening_mm, gap_left_mm, gap_right_mm (the
        start: NaN where rejected) and coverage (N,): the share of the pads' face whose
        rays meet the part between them.
        """
        d, reason, left, right, coverage, reach = self._between_pads(poses_oe)
        reason[(reason == FEASIBLE) & (reach > 0.5 * self.stroke_mm)] = TOO_WIDE
        opening = np.minimum(2.0 * reach + 2.0 * self.safety_zone_mm, self.stroke_mm)
        for i in np.flatnonzero(reason == FEASIBLE):
            reason[i], opening[i] = self._clear(d, i, left[i], right[i], opening[i])
        ok = reason == FEASIBLE
        opening = np.where(ok, opening, np.nan)
        return {
            "reason": reason,
            "opening_mm": opening,
            "gap_left_mm": np.where(ok, 0.5 * opening + left, np.nan),
            "gap_right_mm": np.where(ok, 0.5 * opening - right, np.nan),
            "coverage": coverage,
        }

    def at_opening(self, poses_oe: np.ndarray, opening_mm) -> dict[str, np.ndarray]:
        """Check grasp frames (N, 4, 4) with the fingers at given start openings (N,) mm
        -- a plan made for another pose, as robustness draws them: no speed rule; the
        part reaching past a finger's start, or a finger touching the part, is
        ``collision`` (the finger lands on it).

        Returns reason (N,), gap_left_mm, gap_right_mm, coverage (N,) as ``__call__``.
        """
        d, reason, left, right, coverage, reach = self._between_pads(poses_oe)
        opening = np.broadcast_to(np.asarray(opening_mm, float), reason.shape)
        reason[(reason == FEASIBLE) & (reach > 0.5 * opening)] = COLLISION
        for i in np.flatnonzero(reason == FEASIBLE):
            one = {k: v[i : i + 1] for k, v in d.items() if k != "upward"}
            self._place(one, opening[i], right[i] - left[i])
            if self._touching([self.table_geom]):
                reason[i] = TABLE
            elif self._touching(self.part_geoms):
                reason[i] = COLLISION
        return {
            "reason": reason,
            "gap_left_mm": 0.5 * opening + left,
            "gap_right_mm": 0.5 * opening - right,
            "coverage": coverage,
        }

    def batch(self, pick_id, poses_oe: np.ndarray, mode: str) -> GraspBatch:
        """The feasible grasps of poses_oe (N, 4, 4) as a GraspBatch, with the counts of
        the rejected ones (by REASONS name)."""
        return feasible_batch(pick_id, poses_oe, self(poses_oe), mode)

    # ----------------------------------------------------------------- the part's extent
    def _between_pads(self, poses_oe):
        """What both checks start from: (decompose's dict, reason (N,) -- ``table`` for a
        grasp approaching from below, ``off_object`` for nothing between the pads, else
        feasible so far --, left, right, coverage (``_extent_mm``), reach (N,) mm: the
        part's farthest extent from the grasp centre)."""
        poses_oe = np.asarray(poses_oe, float)
        reason = np.full(len(poses_oe), FEASIBLE, np.int64)
        d = gm.decompose(poses_oe)
        reason[d["upward"]] = TABLE
        left, right, coverage = self._extent_mm(poses_oe)
        reason[(reason == FEASIBLE) & np.isnan(left)] = OFF_OBJECT
        return d, reason, left, right, coverage, np.maximum(-left, right)

    def _extent_mm(self, poses_oe: np.ndarray):
        """Where the pads meet the part along the closing axis, mm from the grasp centre:
        (left (N,), right (N,), coverage (N,)); left = min over the left pad's rays of
        their first hit, right = max of the right pad's (NaN: none between the pads;
        -inf, inf: the part reaches past a fully open pad)."""
        n = len(poses_oe)
        half = 0.5 * self.stroke_mm * 1e-3
        start = half + 1e-3  # just outside the fully open pads
        u = (np.arange(RAYS) + 0.5) / RAYS - 0.5
        gy, gz = np.meshgrid(u * self.pad_width_mm * 1e-3, u * self.pad_height_mm * 1e-3)
        face = np.stack([np.zeros(gy.size), gy.ravel(), gz.ravel()], 1)  # E coordinates
        rot, centre = poses_oe[:, :3, :3], poses_oe[:, :3, 3]
        x_axis = rot[:, :, 0]
        on_face = centre[:, None, :] + np.einsum("nij,kj->nki", rot, face)  # (N, K, 3)
        k = len(face)
        mesh = self.scene.object.mesh
        out = []
        buried = np.zeros(n, bool)  # a fully open pad's face lies inside the part
        for sign in (1.0, -1.0):  # from the left pad towards +x, then from the right
            origins = (on_face - sign * start * x_axis[:, None, :]).reshape(-1, 3)
            dirs = np.repeat(sign * x_axis, k, axis=0)
            hit = np.full(n * k, np.inf)
            leaving = np.zeros(n * k, bool)
            if len(origins):
                loc, ray, tri = mesh.ray.intersects_location(origins, dirs, multiple_hits=False)
                t = np.einsum("ij,ij->i", loc - origins[ray], dirs[ray])
                hit[ray] = t
                # a first hit on a face turned along the ray leaves the part: it started inside
                leaving[ray] = np.einsum("ij,ij->i", mesh.face_normals[tri], dirs[ray]) > 0
            buried |= leaving.reshape(n, k).any(axis=1)
            # each ray's first hit as a coordinate along x, kept when between the pads
            s = sign * (hit - start)
            inside = np.isfinite(hit) & (np.abs(s) <= half) & ~leaving
            out.append(np.where(inside, s, np.nan).reshape(n, k))
        s_left, s_right = out
        met = np.isfinite(s_left)
        coverage = met.mean(axis=1)
        with np.errstate(all="ignore"):
            left = np.where(met.any(1), np.nanmin(np.where(met, s_left, np.inf), 1), np.nan)
            right_met = np.isfinite(s_right)
            right = np.where(
                right_met.any(1), np.nanmax(np.where(right_met, s_right, -np.inf), 1), np.nan
            )
        left = np.where(np.isfinite(right), left, np.nan)
        # the part reaches past a fully open pad: wider than the stroke there
        left, right = np.where(buried, -np.inf, left), np.where(buried, np.inf, right)
        return 1e3 * left, 1e3 * right, coverage

    # ----------------------------------------------------------------------- clearance
    def _clear(self, d: dict, i: int, left: float, right: float, opening: float):
        """(reason, start opening) of grasp i: the gripper fully open must touch neither
        the part nor the table; closed to the part it must not touch the table; at the
        speed rule's opening it must not touch the part (else it starts fully open)."""
        one = {k: v[i : i + 1] for k, v in d.items() if k != "upward"}
        gap = right - left

        def touches(open_mm: float, geoms) -> bool:
            self._place(one, open_mm, gap)
            return self._touching(geoms)

        self._place(one, self.stroke_mm, gap)  # fully open: neither table nor part
        if self._touching([self.table_geom]):
            return TABLE, opening
        if self._touching(self.part_geoms):
            return COLLISION, opening
        if touches(gap, [self.table_geom]):
            return TABLE, opening
        if opening < self.stroke_mm and touches(opening, self.part_and_table):
            return FEASIBLE, self.stroke_mm
        return FEASIBLE, opening

    def _place(self, one: dict, opening_mm: float, gap_mm: float) -> None:
        """Put the model's gripper and part where grasp `one` starts, the pads opening_mm
        apart, and run its kinematics."""
        batch = GraspBatch(
            pick_id=np.zeros(1, np.int64),
            x_mm=one["x_mm"],
            y_mm=one["y_mm"],
            yaw_deg=one["yaw_deg"],
            opening_mm=np.array([opening_mm]),
            coverage=np.array([np.nan]),
            gap_left_mm=np.array([0.5 * (opening_mm - gap_mm)]),
            gap_right_mm=np.array([0.5 * (opening_mm - gap_mm)]),
            rejected={},
            n_candidates=1,
            tilt_quat=one["tilt_quat"],
            height_mm=one["height_mm"],
        )
        start = self.scene.placement(batch)
        for name, values in start.model.items():
            getattr(self.model, name)[:] = values[0]
        self.data.qpos[:] = start.qpos[0]
        mujoco.mj_kinematics(self.model, self.data)

    def _touching(self, others) -> bool:
        """Whether a gripper geom lies within TOUCH_M of penetrating one of others."""
        m, d = self.model, self.data
        for a in self.gripper_geoms:
            for b in others:
                # bounding spheres first: most pairs are far apart (the table's is a plane)
                far = np.linalg.norm(d.geom_xpos[a] - d.geom_xpos[b])
                if m.geom_type[b] != mujoco.mjtGeom.mjGEOM_PLANE and (
                    far > m.geom_rbound[a] + m.geom_rbound[b]
                ):
                    continue
                if mujoco.mj_geomDistance(m, d, int(a), int(b), 0.01, None) < -TOUCH_M:
                    return True
        return False


def feasible_batch(pick_id, poses_oe: np.ndarray, res: dict, mode: str) -> GraspBatch:
    """The feasible grasps of poses_oe (N, 4, 4) by the checks' result res
    (``GraspChecker.__call__``) as a GraspBatch, the rejected counted by REASONS name."""
    ok = res["reason"] == FEASIBLE
    counts = np.bincount(res["reason"], minlength=len(REASONS))
    if ok.any():
        batch = gm.from_poses(
            np.asarray(poses_oe)[ok],
            np.asarray(pick_id)[ok],
            res["opening_mm"][ok],
            res["gap_left_mm"][ok],
            res["gap_right_mm"][ok],
            res["coverage"][ok],
            mode=mode,
        )
    else:
        batch = gm.from_poses(np.zeros((0, 4, 4)), np.zeros(0, np.int64), mode=mode)
    rejected = {REASONS[i]: int(counts[i]) for i in range(1, len(REASONS))}
    return dataclasses.replace(batch, rejected=rejected, n_candidates=len(ok))


def gripper_geoms(scene: Scene) -> np.ndarray:
    """The gripper's solid geoms, whose clearance the checks test: a parametric jaw's
    every geom (body, links, pads); an MJCF or URDF gripper's collision geoms (its pads
    and links, named when attached: ``mjcf_gripper.link_geoms``), not its visual meshes
    (each would collide as its convex hull)."""
    from mjx_pick.core import mjcf_gripper

    m = scene.model
    grip = scene.index.gripper_body
    in_gripper = [b for b in range(m.nbody) if _descends(m, b, grip)]
    ids = np.flatnonzero(np.isin(m.geom_bodyid, in_gripper))
    spec = scene.gripper.mjcf
    if spec is None:
        return ids
    p = mjcf_gripper.PREFIX
    wanted = {p + g for g in (*mjcf_gripper.link_geoms(spec), *spec.pad_left_geoms)}
    wanted |= {p + g for g in spec.pad_right_geoms}
    return np.array([i for i in ids if m.geom(int(i)).name in wanted])


def _descends(m: mujoco.MjModel, body: int, root: int) -> bool:
    """Whether body is root or below it in the kinematic tree."""
    while body > 0:
        if body == root:
            return True
        body = m.body_parentid[body]
    return body == root
