"""What a grasp can hold by Coulomb's law, at the contact points the engine makes.

Details: docs/model.md (core/holding.py).
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
from scipy import sparse
from scipy.optimize import linprog

from mjx_pick.core.config import ConfigError
from mjx_pick.core.scene import Scene, parallel_jaw_pad_side


@dataclasses.dataclass(frozen=True)
class PadContacts:
    """Contact points of the two pads on a part, in the grip frame.

    The grip frame: x along the closing direction (the grip axis), z up, origin on the
    grip axis midway between the pads at the pads' centre height.
    """

    points_m: np.ndarray  # (K, 3) contact positions, m
    pad: np.ndarray  # (K,) 0: left pad, 1: right pad


def pad_contacts(scene: Scene, squeeze_m: float = 2e-5) -> PadContacts:
    """The contact points the engine makes when both pads close on a centred part.

    The part sits as built (centred under the gripper, no yaw); each finger of the
    parallel jaw is moved in until it touches, then ``squeeze_m`` further, and the
    collider's pad-part contacts are read. The default squeeze is a few times the depth
    of a pad contact under load, and short of the rim behind the pad box
    (``physics.PAD_RIM_RECESS_MM``), which a flat face does not reach.

    Raises:
      ConfigError: an MJCF gripper (its fingers swing on a linkage; not supported
        here), or a pad that meets nothing over its whole stroke.
    """
    if scene.kinematics is not None:
        raise ConfigError(
            f"holding.pad_contacts: gripper {scene.gripper.name!r} is an MJCF gripper; "
            "only the parametric parallel jaw is supported"
        )
    m, ix = scene.model, scene.index
    d = mujoco.MjData(m)
    sides = {g: parallel_jaw_pad_side(m.geom(g).name) for g in range(m.ngeom)}
    pads = {g: side for g, side in sides.items() if side is not None}
    qadr = (ix.finger_left_qpos, ix.finger_right_qpos)

    def touching(side: int, travel: float) -> bool:
        d.qpos[:] = m.qpos0
        d.qpos[qadr[side]] = travel
        mujoco.mj_forward(m, d)
        return any(pads.get(int(g)) == side for c in d.contact[: d.ncon] for g in c.geom)

    travel = []
    for side in (0, 1):
        lo, hi = 0.0, scene.index.stroke_m / 2
        if not touching(side, hi):
            raise ConfigError(f"holding.pad_contacts: pad {side} closes without touching the part")
        for _ in range(40):  # bisection to well below a micrometre
            mid = 0.5 * (lo + hi)
            lo, hi = (lo, mid) if touching(side, mid) else (mid, hi)
        travel.append(hi + squeeze_m)
    d.qpos[:] = m.qpos0
    d.qpos[qadr[0]], d.qpos[qadr[1]] = travel
    mujoco.mj_forward(m, d)
    # the grip frame's origin: between the pads as built (not their collision boxes)
    built = (
        "_visual" if mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "pad_left_visual") >= 0 else ""
    )
    left = d.geom_xpos[m.geom(f"pad_left{built}").id]
    right = d.geom_xpos[m.geom(f"pad_right{built}").id]
    origin = 0.5 * (left + right)
    points, pad = [], []
    for c in d.contact[: d.ncon]:
        side = {pads.get(int(c.geom[0])), pads.get(int(c.geom[1]))} - {None}
        if side:
            points.append(np.asarray(c.pos) - origin)
            pad.append(side.pop())
    return PadContacts(np.asarray(points), np.asarray(pad, int))


def uniform_patch_points(width_m: float, height_m: float, n: int = 15) -> PadContacts:
    """A rubber pad's reference: an n x n grid over a width x height patch on each pad
    (uniform pressure), in the grip frame of :class:`PadContacts`."""
    u = (np.arange(n) + 0.5) / n - 0.5
    y, z = (a.ravel() for a in np.meshgrid(u * width_m, u * height_m))
    pts = [np.stack([np.full_like(y, s), y, z], axis=1) for s in (-1.0, 1.0)]
    return PadContacts(np.concatenate(pts), np.repeat([0, 1], n * n))


def _cone_rows(cone: str, mu: float, mu_t: float) -> np.ndarray:
    """Rows a with a . (f_1, f_2, tau) <= N bounding one point's friction: the pyramid's
    eight faces of the L1 budget, or an outer polyhedron of the elliptic cone (600
    directions: within 0.3 % of the round cone). Without torsion (mu_t 0) tau's column
    is 0; the caller pins tau to 0."""
    if cone == "pyramidal":
        directions = np.array(np.meshgrid([-1, 1], [-1, 1], [-1, 1])).reshape(3, -1).T
    else:
        k = np.arange(600) + 0.5  # Fibonacci sphere
        polar, azim = np.arccos(1 - 2 * k / 600), np.pi * (1 + 5**0.5) * k
        directions = np.stack(
            [np.sin(polar) * np.cos(azim), np.sin(polar) * np.sin(azim), np.cos(polar)], 1
        )
    return directions / np.array([mu, mu, mu_t if mu_t > 0 else np.inf])


def hold_limit_m(
    contacts: PadContacts,
    grip_force_n: float,
    weight_n: float,
    mu: float,
    mu_t: float,
    cone: str = "pyramidal",
) -> float:
    """The largest lever, m, at which the contacts hold a part.

    Args:
      contacts: the points of both pads (:func:`pad_contacts`).
      grip_force_n: each pad's normal force F, N, shared equally by its points.
      weight_n: the load along -z the pads carry, m (g + a), N.
      mu, mu_t: Coulomb (-) and torsional (m) friction of every point.
      cone: "pyramidal" or "elliptic", as the solver's.

    Returns:
      d*: the part's centre of mass may lie up to d* from the grip axis, along the pad
      plane's horizontal (y), before no friction within the cones balances its weight
      and the torque m (g + a) d about the grip axis. 0 when even a centred part slips
      (2 mu F < weight).
    """
    pts, pad = contacts.points_m, contacts.pad
    n_pts = len(pts)
    share = np.array([grip_force_n / np.count_nonzero(pad == p) for p in pad])
    rows = _cone_rows(cone, mu, mu_t)
    # variables: (f_y, f_z, tau) per point, then the lever d; maximise d
    nv = 3 * n_pts + 1
    # point i's cone rows on its own three variables: block diagonal, built sparse (a
    # rubber pad's 450 points x 600 elliptic rows are 2.9 GB dense; HiGHS takes the
    # nonzeros either way)
    k = len(rows)
    cols = 3 * np.arange(n_pts)[:, None, None] + np.arange(3)
    a_ub = sparse.csc_array(
        (
            np.broadcast_to(rows, (n_pts, k, 3)).ravel(),
            (np.arange(n_pts * k).repeat(3), np.broadcast_to(cols, (n_pts, k, 3)).ravel()),
        ),
        shape=(k * n_pts, nv),
    )
    a_ub.eliminate_zeros()  # as a dense matrix's conversion drops them
    b_ub = np.repeat(share, len(rows))
    # the normal of pad 0 points +x into the part, pad 1's -x: its torsion about +x flips
    spin = np.where(pad == 0, 1.0, -1.0)
    a_eq = np.zeros((3, nv))
    a_eq[0, 0 : 3 * n_pts : 3] = 1.0  # sum f_y = 0
    a_eq[1, 1 : 3 * n_pts : 3] = 1.0  # sum f_z = weight
    # torque about the grip axis (x): y f_z - z f_y + torsion = weight * d
    a_eq[2, 0 : 3 * n_pts : 3] = -pts[:, 2]
    a_eq[2, 1 : 3 * n_pts : 3] = pts[:, 1]
    a_eq[2, 2 : 3 * n_pts : 3] = spin
    a_eq[2, -1] = -weight_n
    c = np.zeros(nv)
    c[-1] = -1.0
    # without torsional friction a point's torque about its normal is zero
    tau = (None, None) if mu_t > 0 else (0.0, 0.0)
    bounds = [(None, None), (None, None), tau] * n_pts + [(0, None)]
    res = linprog(c, a_ub, b_ub, a_eq, [0.0, weight_n, 0.0], bounds=bounds, method="highs")
    return float(res.x[-1]) if res.status == 0 else 0.0
