"""Standalone repro: MJX-JAX lets two box pads chatter on a block that MuJoCo C holds.

Question
--------
Does MJX's JAX physics (``mujoco.mjx``, ``impl="jax"``) hold a block squeezed by two flat
box pads at low pad friction the way MuJoCo C does, on the same MjModel?

Scene: a 300 g block (50 x 30 x 20 mm, a box geom or a box-shaped 8-vertex mesh) on a plane,
squeezed along x by two 8 x 22 x 38 mm box pads on slide joints driven by position servos
(kp 1e4 N/m). The pad targets close at 50 mm/s to F/kp past first touch (touch at
t ~ 0.12 s, full force at t ~ 0.17 s), hold, and a third servo lifts the gripper 30 mm
(smoothstep over 0.2 s from t = 0.35 s); the run ends at t = 0.8 s. Pyramidal cone,
Newton, implicitfast, dt 1 ms, condim 4 on the pad pairs. At mu 0.1 and the default
23.03 N per pad the hold has a ~7 % margin (static need m g / (2 mu) = 14.7 N; with the
lift's peak 4.5 m/s^2 it is 21.5 N).

The same MjModel is stepped by ``mujoco.mj_step`` and by ``jax.jit(mjx.step)`` (scan of 5
steps per 5 ms control tick); per tick each pad's normal force is summed over its active
contacts from ``efc_force`` (C: MjData; MJX: the device data's contact list, read directly
because ``mj_contactForce`` on ``mjx.get_data`` output returned occasional garbage, up to
~1000 N on one pad, varying from run to run: get_data drops efc rows with an all-zero
Jacobian and remaps ``efc_address``). Contacts per pad count the active contacts.

Measured (2026-11-23, 2-core CPU, mujoco 4.0.0, mujoco-mjx 3.17.0, jax 0.10.2, float32
MJX unless noted). Squeeze window t in (0.13, 0.35) s = 43 ticks; "ticks < 1 N": ticks in
it where one pad pushes < 1 N; "contacts/pad": min-max over it; lift: block z at t = 0.8 s
(target 30 mm, C sags to 29.47); tilt: max over the run.

    engine   block  mu   ticks<1N  contacts/pad  lift mm  tilt deg
    C        mesh   0.1   0/43     4-4           29.47      0.00
    MJX      mesh   0.1   7/43     0-4           22.42      2.87
    C        box    0.1   0/43     4-4           29.47      0.00
    MJX      box    0.1   8/43     0-4            0.17    131.30   (dropped)
    MJX x64  mesh   0.1  39/43     0-4           16.38    163.65
    MJX x64  box    0.1   0/43     4-4           29.27      0.00   (holds)
    C        mesh   0.5   0/43     4-4           29.83      0.00
    MJX      mesh   0.5   1/43     0-4           28.82      0.15
    C        box    0.5   0/43     4-4           29.83      0.00
    MJX      box    0.5   4/43     0-4           29.84      0.03

Perturbed mesh block at mu 0.1 (C holds both, 29.38 / 29.47 mm, tilt 0.00): MJX with
``--px 1e-6`` 9/43 ticks < 1 N and the state went NaN during the lift (lift and tilt print
nan); with ``--pyaw 1e-3`` 3/43, dropped (lift 0.26 mm, tilt 44.25 deg). At mu 0.5 MJX
holds but still loses a pad's contacts on some squeeze ticks. The outcome at mu 0.1 is
chaotic (x64 box holds, x64 mesh is worse than float32): the contact dropout is what is
systematic. Wall time per MJX run on this CPU: 17-23 s (jit included).

Causes, both in ``mujoco/mjx/_src/collision_convex.py``
---------------------------------------------------------
1. ``_sat_gaussmap`` (used by ``convex_convex``, i.e. the mesh block) returns a single
   edge-edge contact whenever the best edge axis is within 1e-6 m of the shallowest face
   point (``best_edge_dist > dist.max() - 1e-6``). On a flat face-face contact the edge axis
   ties the face axis, so the pad gets 1 contact instead of 4 on some steps (e.g. both
   pads at t = 0.125 s with the defaults, ``--print 0.12:0.15``) and the block is
   squeezed through one point.
2. ``_create_contact_manifold`` keeps a clipped incident point only if
   ``_point_in_front_of_plane`` says it penetrates the reference face by > 1e-6 m. With
   this soft pad solref/solimp the steady penetration is set by the pyramidal cone's
   regulariser and scales roughly with mu^2: MuJoCo C, 23 N squeeze at t = 0.3 s, gives
   0.0093 um at mu 0.1 and 0.29 um at mu 0.5 (mesh and box alike), both under the 1e-6 m
   cut. The clipped points are dropped, the pad loses its contacts, moves in, regains
   them deeper and is pushed back (our reading of the traces): the chatter.
   (Read from the source: the box block goes through ``box_box`` / ``_box_box_impl``,
   which keeps the face axis unless the edge axis is off it by > ~8 deg, so cause 1 is
   specific to the mesh block; cause 2 applies to both.)

The two-line change tried (as a monkeypatch, not included here): in ``_sat_gaussmap``
``best_edge_dist > dist.max() + 1e-6`` (edge contact only if shallower than every face
point by > 1e-6 m), and in ``_point_in_front_of_plane`` ``> 0.0`` instead of ``> 1e-6``.
With both changes and JAX x64, MJX matched C exactly in the colleague's runs (same
outcomes on the perturbed picks); in float32 2 of 3 perturbed picks held.

Run (repo root, venv active; C takes < 0.1 s, MJX on CPU ~20 s per run on 2 cores):

    python benchmarks/probes/mjx_contact_repro.py              # mesh block, mu 0.1, C and MJX
    python benchmarks/probes/mjx_contact_repro.py --obj box
    python benchmarks/probes/mjx_contact_repro.py --mu 0.5            # contrast: MJX holds
    python benchmarks/probes/mjx_contact_repro.py --x64               # MJX in float64
    python benchmarks/probes/mjx_contact_repro.py --px 1e-6 --pyaw 1e-3   # perturbed block pose
    python benchmarks/probes/mjx_contact_repro.py --print 0.12:0.16   # per-tick trace

Meant as the repro attached to the upstream (google-deepmind/mujoco) bug report: it imports
only numpy, mujoco and mujoco.mjx.
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np

CONTROL_TICK_S = 0.005  # control period: ctrl is set once per tick (s)
TIMESTEP_S = 0.001  # physics step (s)
SERVO_KP = 1e4  # pad position-servo stiffness (N/m)
TOUCH_Q_M = 0.0175  # pad slide-joint position at first touch of the 50 mm wide block (m)
LIFT_START_S = 0.35  # lift begins (s)
LIFT_DURATION_S = 0.2  # smoothstep lift duration (s)
LIFT_HEIGHT_M = 0.03  # lift height (m)
SQUEEZE_WINDOW_S = (0.13, LIFT_START_S)  # window for the squeeze statistics (s)
DURATION_S = 0.8  # simulated time (s)

MESH_BLOCK = (
    '<mesh name="block" vertex="-0.025 -0.015 0  0.025 -0.015 0  0.025 0.015 0  '
    "-0.025 0.015 0  -0.025 -0.015 0.02  0.025 -0.015 0.02  0.025 0.015 0.02  "
    '-0.025 0.015 0.02"/>'
)


def build_xml(mu: float, obj: str, cone: str) -> str:
    """MJCF of the scene.

    Args:
      mu: sliding friction of the two pad-block contact pairs (-).
      obj: "box" (box geom block) or "mesh" (box-shaped convex mesh block).
      cone: friction cone, "pyramidal" or "elliptic".
    """
    if obj == "box":
        block_geom = '<geom name="block" type="box" size="0.025 0.015 0.01" pos="0 0 0.01"/>'
    else:
        block_geom = '<geom name="block" type="mesh" mesh="block"/>'
    pad_pair = (
        f'condim="4" friction="{mu} {mu} 0.00076751 0.0001 0.0001" '
        'solref="-250000 -1000" solimp="0.99 0.99 0.001 0.5 2"'
    )
    return f"""<mujoco>
  <option timestep="{TIMESTEP_S}" cone="{cone}" impratio="1" iterations="10"
          ls_iterations="8" tolerance="1e-8" integrator="implicitfast" solver="Newton"/>
  <default><geom contype="0" conaffinity="0"/></default>
  <asset>{MESH_BLOCK}</asset>
  <worldbody>
    <geom name="table" type="plane" size="0.5 0.5 0.01"/>
    <body name="object">
      <freejoint/>
      <inertial pos="0 0 0.01" mass="0.3" diaginertia="3.25e-05 7.25e-05 8.5e-05"/>
      {block_geom}
    </body>
    <body name="gripper" pos="0 0 0.021" gravcomp="1">
      <joint name="lift" type="slide" axis="0 0 1"/>
      <inertial pos="0 0 0.079" mass="0.925" diaginertia="1e-3 1e-3 1e-3"/>
      <body name="finger_left" pos="-0.0465 0 0" gravcomp="1">
        <joint name="fl" type="slide" axis="1 0 0" range="0 0.0425"/>
        <geom name="pad_left" type="box" size="0.004 0.011 0.019" mass="0.04"/>
      </body>
      <body name="finger_right" pos="0.0465 0 0" gravcomp="1">
        <joint name="fr" type="slide" axis="-1 0 0" range="0 0.0425"/>
        <geom name="pad_right" type="box" size="0.004 0.011 0.019" mass="0.04"/>
      </body>
    </body>
  </worldbody>
  <contact>
    <pair geom1="pad_left" geom2="block" {pad_pair}/>
    <pair geom1="pad_right" geom2="block" {pad_pair}/>
    <pair geom1="table" geom2="block" condim="3" friction="0.2 0.2 0.005 0.0001 0.0001"
          solref="-250000 -1000" solimp="0.9 0.95 0.001 0.5 2"/>
  </contact>
  <actuator>
    <position name="fl" joint="fl" kp="{SERVO_KP}" kv="20" forcerange="-235 235"/>
    <position name="fr" joint="fr" kp="{SERVO_KP}" kv="20" forcerange="-235 235"/>
    <position name="lift" joint="lift" kp="20000" kv="400" forcerange="-500 500"/>
  </actuator>
</mujoco>"""


def control_at(t: float, force: float) -> np.ndarray:
    """Open-loop servo targets at time t (s): [left pad, right pad, lift] in m.

    The pad targets ramp at 50 mm/s from 12.5 mm (from t = 0.02 s) up to TOUCH_Q_M plus
    force / SERVO_KP, so each pad ends up pushing about ``force`` (N). The lift target
    follows a 30 mm smoothstep starting at LIFT_START_S.
    """
    pad_target = min(0.0125 + 0.05 * max(t - 0.02, 0.0), TOUCH_Q_M + force / SERVO_KP)
    s = np.clip((t - LIFT_START_S) / LIFT_DURATION_S, 0.0, 1.0)
    lift_target = LIFT_HEIGHT_M * (3 * s * s - 2 * s**3)
    return np.array([pad_target, pad_target, lift_target])


def pad_forces(
    pad_ids: tuple[int, int],
    contact_geom: np.ndarray,
    contact_active: np.ndarray,
    efc_address: np.ndarray,
    contact_dim: np.ndarray,
    efc_force: np.ndarray,
    elliptic: bool,
) -> tuple[tuple[float, float], tuple[int, int]]:
    """Normal force (N) and active contact count of the left and right pad.

    Works on plain arrays so that C (MjData) and MJX (device data) are read the same way:
    the normal force of a pyramidal contact is the sum of its 2 (dim - 1) pyramid-edge
    forces, that of an elliptic contact its first efc row (as ``mj_contactForce`` does).

    Args:
      pad_ids: geom ids of the left and right pad.
      contact_geom: [ncon, 2] geom ids of each contact.
      contact_active: [ncon] whether the contact is in the constraint set.
      efc_address: [ncon] first efc row of each contact.
      contact_dim: [ncon] contact dimensionality.
      efc_force: [nefc] constraint forces (N).
      elliptic: True for the elliptic friction cone.
    """
    force = [0.0, 0.0]
    count = [0, 0]
    for i in np.flatnonzero(contact_active):
        n_rows = 1 if elliptic else 2 * (int(contact_dim[i]) - 1)
        start = int(efc_address[i])
        normal_force = float(np.sum(efc_force[start : start + n_rows]))
        for side, geom_id in enumerate(pad_ids):
            if geom_id in contact_geom[i]:
                force[side] += normal_force
                count[side] += 1
    return (force[0], force[1]), (count[0], count[1])


def tilt_deg(qpos: np.ndarray) -> float:
    """Angle (deg) between the block's z axis and world z, from the free joint quaternion."""
    qx, qy = qpos[4], qpos[5]
    return float(np.degrees(np.arccos(np.clip(1 - 2 * (qx * qx + qy * qy), -1.0, 1.0))))


def simulate(model: mujoco.MjModel, engine: str, args: argparse.Namespace) -> dict[str, np.ndarray]:
    """Run the squeeze-and-lift on one engine ("c" or "mjx") and record every control tick.

    Returns arrays over ticks: t (s, end of tick), force (N, [tick, pad]),
    ncon (contacts, [tick, pad]), z (block height, m), tilt (deg).
    """
    data = mujoco.MjData(model)
    data.qpos[0] += args.px
    data.qpos[1] += args.py
    data.qpos[3:7] = [np.cos(args.pyaw / 2), 0.0, 0.0, np.sin(args.pyaw / 2)]
    mujoco.mj_forward(model, data)
    steps_per_tick = round(CONTROL_TICK_S / model.opt.timestep)
    n_ticks = round(DURATION_S / CONTROL_TICK_S)

    if engine == "mjx":
        import jax
        from mujoco import mjx

        mjx_model = mjx.put_model(model, impl="jax")
        mjx_data = mjx.put_data(model, data, impl="jax")
        # one forward pass normalises the dtypes of the device data (matters under x64)
        mjx_data = jax.jit(lambda d: mjx.forward(mjx_model, d))(mjx_data)
        ctrl_dtype = np.float64 if args.x64 else np.float32

        @jax.jit
        def step_tick(d, ctrl):
            d = d.replace(ctrl=ctrl)
            return jax.lax.scan(
                lambda carry, _: (mjx.step(mjx_model, carry), None),
                d,
                None,
                length=steps_per_tick,
            )[0]

    pad_ids = (model.geom("pad_left").id, model.geom("pad_right").id)
    elliptic = model.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
    rows = {"t": [], "force": [], "ncon": [], "z": [], "tilt": []}
    for tick in range(n_ticks):
        ctrl = control_at(tick * CONTROL_TICK_S, args.force)
        if engine == "c":
            data.ctrl[:] = ctrl
            for _ in range(steps_per_tick):
                mujoco.mj_step(model, data)
            contact = data.contact
            contact_active = contact.efc_address >= 0
            efc_force = data.efc_force
            qpos = data.qpos
        else:
            mjx_data = step_tick(mjx_data, ctrl.astype(ctrl_dtype))
            # MJX keeps a fixed-size contact list; inactive slots have dist > 0 (margin is 0)
            contact = jax.device_get(mjx_data._impl.contact)
            contact_active = contact.dist <= 0.0
            efc_force = np.asarray(mjx_data._impl.efc_force)
            qpos = np.asarray(mjx_data.qpos)
        force, ncon = pad_forces(
            pad_ids,
            contact.geom,
            contact_active,
            contact.efc_address,
            contact.dim,
            efc_force,
            elliptic,
        )
        rows["t"].append((tick + 1) * CONTROL_TICK_S)
        rows["force"].append(force)
        rows["ncon"].append(ncon)
        rows["z"].append(qpos[2])
        rows["tilt"].append(tilt_deg(qpos))
    return {key: np.asarray(value) for key, value in rows.items()}


def summarise(trace: dict[str, np.ndarray]) -> str:
    """One line of squeeze and lift statistics for a trace from simulate()."""
    t = trace["t"]
    squeeze = (t > SQUEEZE_WINDOW_S[0]) & (t < SQUEEZE_WINDOW_S[1])
    weaker_pad = trace["force"][squeeze].min(axis=1)
    ncon = trace["ncon"][squeeze]
    return (
        f"squeeze: pad force mean {trace['force'][squeeze].mean(axis=0).round(2)} N, "
        f"ticks with a pad < 1 N {int((weaker_pad < 1.0).sum())}/{int(squeeze.sum())}, "
        f"contacts/pad {ncon.min()}-{ncon.max()} | "
        f"end: lift {1e3 * trace['z'][-1]:.2f} mm, max tilt {trace['tilt'].max():.2f} deg"
    )


def print_window(trace: dict[str, np.ndarray], window: str) -> None:
    """Print the ticks of a trace with t in "lo:hi" (s)."""
    lo, hi = (float(x) for x in window.split(":"))
    for i in np.flatnonzero((trace["t"] >= lo) & (trace["t"] <= hi)):
        force_left, force_right = trace["force"][i]
        ncon_left, ncon_right = trace["ncon"][i]
        print(
            f"  t {trace['t'][i]:.3f} s  F {force_left:7.2f} {force_right:7.2f} N  "
            f"contacts {ncon_left} {ncon_right}  z {1e3 * trace['z'][i]:7.3f} mm  "
            f"tilt {trace['tilt'][i]:6.2f} deg"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--mu", type=float, default=0.1, help="pad friction (-)")
    parser.add_argument("--force", type=float, default=23.03, help="pad squeeze force (N)")
    parser.add_argument("--obj", choices=("box", "mesh"), default="mesh", help="block geom")
    parser.add_argument("--cone", choices=("pyramidal", "elliptic"), default="pyramidal")
    parser.add_argument("--x64", action="store_true", help="run MJX with jax_enable_x64")
    parser.add_argument("--engines", default="c,mjx", help="comma list of c, mjx")
    parser.add_argument("--px", type=float, default=0.0, help="block x offset (m)")
    parser.add_argument("--py", type=float, default=0.0, help="block y offset (m)")
    parser.add_argument("--pyaw", type=float, default=0.0, help="block yaw (rad)")
    parser.add_argument("--print", dest="window", default="", help="per-tick trace, lo:hi (s)")
    args = parser.parse_args()

    if args.x64:
        import jax

        jax.config.update("jax_enable_x64", True)
    model = mujoco.MjModel.from_xml_string(build_xml(args.mu, args.obj, args.cone))
    print(
        f"block {args.obj}, mu {args.mu}, {args.force} N/pad, cone {args.cone}, "
        f"MJX {'float64' if args.x64 else 'float32'}, perturbation "
        f"x {args.px} m y {args.py} m yaw {args.pyaw} rad"
    )
    traces = {}
    for engine in args.engines.split(","):
        start = time.perf_counter()
        traces[engine] = simulate(model, engine, args)
        elapsed = time.perf_counter() - start
        print(f"{engine:4s} {elapsed:5.1f} s  {summarise(traces[engine])}", flush=True)
    if args.window:
        for engine, trace in traces.items():
            print(engine)
            print_window(trace, args.window)


if __name__ == "__main__":
    main()
