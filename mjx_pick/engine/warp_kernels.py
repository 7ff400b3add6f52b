"""The MuJoCo Warp backend's kernels over the pool's slots: the controller tick, buffer
and solver bookkeeping after each physics step, a slot's start and its pick's results.

Each launches one thread per slot (``engine.warp_direct`` launches them); a slot runs
the one-pick functions of ``kernels.grasp_warp``.
"""

import warp as wp

from mjx_pick.kernels import grasp_warp as gw


@wp.kernel(enable_backward=False)
def tick(
    ad: gw.Addresses,
    dr: gw.Drive,
    n_ticks: int,
    record: int,
    params: wp.array(dtype=gw.Params),
    ctl: wp.array(dtype=gw.Control),
    acc: wp.array(dtype=gw.Acc),
    pos0: wp.array(dtype=wp.vec3),
    quat0: wp.array(dtype=wp.vec4),
    k: wp.array(dtype=int),
    live: wp.array(dtype=int),
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    cfrc_ext: wp.array2d(dtype=wp.spatial_vector),
    ctrl: wp.array2d(dtype=float),
    trace: wp.array3d(dtype=float),
):
    w = wp.tid()
    s = ctl[w]
    a = acc[w]
    kw = k[w]
    if gw.finished(s, a, kw, n_ticks):
        # a finished pick's control state, metrics and commands stay as they are
        live[w] = 0
        return
    live[w] = 1
    p = params[w]
    m = gw.measure(p, ad, dr, qpos[w], qvel[w], cfrc_ext[w])
    s_next = gw.control_step(p, s, m)
    acc[w] = gw.accumulate(p, a, s, s_next, m, pos0[w], quat0[w])
    ctl[w] = s_next
    gw.write_command(ad, dr, s_next, ctrl[w])
    if record != 0:
        gw.trace_row(a, s, m, trace[w, kw])
    k[w] = kw + 1


@wp.kernel(enable_backward=False)
def buffer_use(
    live: wp.array(dtype=int),
    nefc: wp.array(dtype=int),
    nacon: wp.array(dtype=int),
    niter: wp.array(dtype=int),
    nefc_max: wp.array(dtype=int),
    nacon_max: wp.array(dtype=int),
    niter_hist: wp.array(dtype=int),
    niter_step_max: wp.array(dtype=int),
):
    """After each physics step: each live slot's most constraint rows and contacts
    (of the whole pool) so far; and the solver's iterations (a histogram over live
    world-steps, and this step's largest in niter_step_max[0])."""
    w = wp.tid()
    if live[w] == 0:
        return
    nefc_max[w] = wp.max(nefc_max[w], nefc[w])
    nacon_max[w] = wp.max(nacon_max[w], nacon[0])
    it = wp.min(niter[w], niter_hist.shape[0] - 1)
    wp.atomic_add(niter_hist, it, 1)
    wp.atomic_max(niter_step_max, 0, niter[w])


@wp.kernel(enable_backward=False)
def step_done(cap: int, niter_step_max: wp.array(dtype=int), steps: wp.array(dtype=int)):
    """Counts this step (steps[0]) and whether every live world converged before the
    iteration cap (steps[1]); clears the step's largest iteration count."""
    steps[0] = steps[0] + 1
    if niter_step_max[0] < cap:
        steps[1] = steps[1] + 1
    niter_step_max[0] = 0


@wp.kernel(enable_backward=False)
def start(
    ad: gw.Addresses,
    dr: gw.Drive,
    fresh: wp.array(dtype=int),
    slot_pick: wp.array(dtype=int),
    in_qpos0: wp.array2d(dtype=float),
    in_params: wp.array(dtype=gw.Params),
    in_friction: wp.array2d(dtype=gw.vec5),
    in_solref: wp.array2d(dtype=wp.vec2),
    in_solimp: wp.array2d(dtype=gw.vec5),
    params: wp.array(dtype=gw.Params),
    ctl: wp.array(dtype=gw.Control),
    acc: wp.array(dtype=gw.Acc),
    pos0: wp.array(dtype=wp.vec3),
    quat0: wp.array(dtype=wp.vec4),
    k: wp.array(dtype=int),
    nefc_max: wp.array(dtype=int),
    nacon_max: wp.array(dtype=int),
    qpos: wp.array2d(dtype=float),
    qvel: wp.array2d(dtype=float),
    ctrl: wp.array2d(dtype=float),
    pair_friction: wp.array2d(dtype=gw.vec5),
    pair_solref: wp.array2d(dtype=wp.vec2),
    pair_solimp: wp.array2d(dtype=gw.vec5),
):
    """A fresh slot takes its pick: inputs into its data and model rows, the
    controller's initial state and command (after reset_data cleared the slot)."""
    w = wp.tid()
    if fresh[w] == 0:
        return
    i = slot_pick[w]
    q0 = in_qpos0[i]
    for j in range(qpos.shape[1]):
        qpos[w, j] = q0[j]
    for j in range(qvel.shape[1]):
        qvel[w, j] = 0.0
    for j in range(pair_friction.shape[1]):
        pair_friction[w, j] = in_friction[i, j]
        pair_solref[w, j] = in_solref[i, j]
        pair_solimp[w, j] = in_solimp[i, j]
    params[w] = in_params[i]
    s = gw.initial_control(ad, dr, q0)
    ctl[w] = s
    acc[w] = gw.initial_acc()
    o = ad.object_qpos
    pos0[w] = wp.vec3(q0[o], q0[o + 1], q0[o + 2])
    quat0[w] = wp.vec4(q0[o + 3], q0[o + 4], q0[o + 5], q0[o + 6])
    k[w] = 0
    nefc_max[w] = 0
    nacon_max[w] = 0
    gw.write_command(ad, dr, s, ctrl[w])


@wp.kernel(enable_backward=False)
def copy_rows(
    fresh: wp.array(dtype=int),
    slot_pick: wp.array(dtype=int),
    src: wp.array2d(dtype=float),
    dst: wp.array2d(dtype=float),
):
    """dst[slot] = src[its pick] for fresh slots (a model field's values, flat)."""
    w, j = wp.tid()
    if fresh[w] != 0:
        dst[w, j] = src[slot_pick[w], j]


@wp.kernel(enable_backward=False)
def after_forward(
    fresh: wp.array(dtype=int),
    saved_cfrc: wp.array2d(dtype=wp.spatial_vector),
    cfrc_ext: wp.array2d(dtype=wp.spatial_vector),
    nefc: wp.array(dtype=int),
    nacon: wp.array(dtype=int),
    nefc_max: wp.array(dtype=int),
    nacon_max: wp.array(dtype=int),
):
    """After the refill's forward pass (every world): a running slot keeps the
    external forces of its last physics step (what its next tick measures); a fresh
    one starts its buffer counts."""
    w, b = wp.tid()
    if fresh[w] == 0:
        cfrc_ext[w, b] = saved_cfrc[w, b]
    elif b == 0:
        nefc_max[w] = nefc[w]
        nacon_max[w] = nacon[0]


@wp.kernel(enable_backward=False)
def save(
    n_ticks: int,
    slot_pick: wp.array(dtype=int),
    ctl: wp.array(dtype=gw.Control),
    acc: wp.array(dtype=gw.Acc),
    k: wp.array(dtype=int),
    overflow: wp.array(dtype=int),
    nefc_max: wp.array(dtype=int),
    nacon_max: wp.array(dtype=int),
    ended: wp.array(dtype=int),
    out_acc: wp.array(dtype=gw.Acc),
    out_k: wp.array(dtype=int),
    out_phase: wp.array(dtype=int),
    out_overflow: wp.array(dtype=int),
    out_nefc_max: wp.array(dtype=int),
    out_nacon_max: wp.array(dtype=int),
):
    """Slots whose pick has ended write it to its row; ended[slot] says which."""
    w = wp.tid()
    i = slot_pick[w]
    done = i >= 0 and gw.finished(ctl[w], acc[w], k[w], n_ticks)
    if not done:
        ended[w] = 0
        return
    ended[w] = 1
    out_acc[i] = acc[w]
    out_k[i] = k[w]
    out_phase[i] = ctl[w].phase
    out_overflow[i] = overflow[w]
    out_nefc_max[i] = nefc_max[w]
    out_nacon_max[i] = nacon_max[w]


@wp.kernel(enable_backward=False)
def finalize(
    params: wp.array(dtype=gw.Params),
    acc: wp.array(dtype=gw.Acc),
    out: wp.array(dtype=gw.Result),
):
    i = wp.tid()
    out[i] = gw.finalize(params[i], acc[i])


@wp.kernel(enable_backward=False)
def gather_bytes(
    order: wp.array(dtype=int), src: wp.array2d(dtype=wp.uint8), dst: wp.array2d(dtype=wp.uint8)
):
    """dst[j] = src[order[j]] where order[j] >= 0: a world's row of any per-world array,
    seen as its bytes (one kernel for every array type: a generic kernel would add an
    overload, and so change and rebuild this module, for each type a run first moves)."""
    j, c = wp.tid()
    i = order[j]
    if i >= 0:
        dst[j, c] = src[i, c]


@wp.kernel(enable_backward=False)
def idle_slots(order: wp.array(dtype=int), n_ticks: int, k: wp.array(dtype=int)):
    """Slots that took no pick in a compaction count as ended."""
    j = wp.tid()
    if order[j] < 0:
        k[j] = n_ticks
