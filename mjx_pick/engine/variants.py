"""Gripper variants as data: which scenes can share ONE compiled program, and the
per-simulation model fields that make each variant what it is.

Details: docs/engine.md (engine/variants.py).
"""

from __future__ import annotations

import functools
import hashlib
import typing

import mujoco
import numpy as np

from mjx_pick.core.procedure import GraspConfig
from mjx_pick.core.scene import Scene
from mjx_pick.engine import registry
from mjx_pick.engine.inputs import PickInputs, addresses

# solver options a backend may take per simulation (MjOption fields, as mujoco.batch
# names them): traced arrays in MJX's Option, expandable in a batch
OPT_FIELDS = ("opt.impratio", "opt.tolerance", "opt.ls_tolerance")
# per-pick inputs of their own (PickInputs.pair_friction/solref/solimp)
PAIR_FIELDS = ("pair_friction", "pair_solref", "pair_solimp")
# collision margins: MJX's JAX implementation collides without them
MARGIN_FIELDS = ("geom_margin", "pair_margin")
# bookkeeping of names and paths: never read by the physics (a variant's name -- the
# model is named after the gripper -- changes their lengths and addresses, not the
# simulation), and the model buffer's size, which holds the names (every array's size
# is a field of its own)
_NAME_FIELDS = ("names_map", "nnames", "nnames_map", "npaths", "nbuffer")
# the smallest mass MuJoCo and Warp treat as a mass (a value crossing it changes what
# Warp's model builder derives from it: see program_key)
_MINVAL = 1e-15


@functools.cache
def carried_fields(backend: str) -> frozenset[str]:
    """The model fields a backend can apply per simulation, by backend name ('auto'
    resolved here): its entry's ``model_fields`` of those ``mujoco.batch`` can expand
    (float arrays and :data:`OPT_FIELDS`, the contact pairs apart)."""
    import mujoco.batch

    entry = registry.entry(backend)
    if entry.model_fields is None:
        return frozenset()
    probe = mujoco.MjModel.from_xml_string("<mujoco/>")
    out = set()
    for field in mujoco.batch.MODEL_FIELDS:
        if field.startswith("opt.") or field in PAIR_FIELDS:
            continue
        template = getattr(probe, field, None)
        if isinstance(template, np.ndarray) and template.dtype.kind == "f":
            out.add(field)
    out.update(f for f in OPT_FIELDS if f in mujoco.batch.MODEL_FIELDS)
    return frozenset(registry.load(entry.model_fields)(frozenset(out)))


def batch_fields(fields: frozenset[str]) -> frozenset[str]:
    """The C engine's: all of them (MJX is not imported for it: seconds of a C run's
    start)."""
    return fields


def mjx_fields(fields: frozenset[str]) -> frozenset[str]:
    """MJX's JAX physics': those MJX traces (one it holds as numpy is static in its
    programs; one it lacks is unread), without the collision margins (its JAX collider
    has none between a box and a mesh: ``mjx_backend.jax_model`` zeroes them) and the
    impedance ratio (the differentiable physics' own: a variant of another ratio gets a
    backend of its own, which refuses it, ``mjx_backend.check_physics``)."""
    return _mjx_traced(fields) - set(MARGIN_FIELDS) - {"opt.impratio"}


def mjx_warp_fields(fields: frozenset[str]) -> frozenset[str]:
    """MuJoCo Warp's (through MJX): those MJX traces that Warp holds per world or does
    not hold at all (one it holds once for all worlds would be read from the first
    variant only)."""
    from mujoco.mjx.warp import types as mjxw_types

    per_world = mjxw_types._BATCH_DIM["Model"]
    options = mjxw_types._BATCH_DIM["Option"]
    return frozenset(
        f
        for f in _mjx_traced(fields)
        if (options.get(f[4:], False) if f.startswith("opt.") else per_world.get(f, True))
    )


def _mjx_traced(fields: frozenset[str]) -> frozenset[str]:
    from mujoco import mjx

    hints = typing.get_type_hints(mjx.Model)
    return frozenset(
        f for f in fields if f.startswith("opt.") or (f in hints and hints[f] is not np.ndarray)
    )


def model_value(model: mujoco.MjModel, name: str) -> np.ndarray:
    """A model field's values by its batch name: an MjModel array, ``opt.<field>`` or
    ``stat.<field>``."""
    if name.startswith(("opt.", "stat.")):
        group, _, field = name.partition(".")
        return np.asarray(getattr(getattr(model, group), field))
    return getattr(model, name)


def _digest(h, value) -> None:
    a = np.ascontiguousarray(value)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes())


def program_key(scene: Scene, grasp: GraspConfig, backend: str) -> tuple:
    """What decides whether scenes may share one compiled program on a backend.

    Equal keys: the two models differ at most in the values of ``carried_fields(backend)``
    and the contact pairs, and the rollouts are the same program (addresses, scan length,
    physics steps per control period). The key holds every size, a digest of every other
    array and option of the model, the zero pattern of the carried fields (a field
    that becomes zero or non-zero changes what Warp's model builder derives: an affine
    gain, a massless body), and the values the backend's program reads that no
    simulation carries (its entry's ``program_reads``: the C engine's solver scales by
    the mean inertia, which a batch cannot give per simulation).
    """
    m = scene.model
    entry = registry.entry(backend)
    carried = carried_fields(entry.name)
    h = hashlib.sha256()
    sizes = []
    for field in sorted(dir(m)):
        if field.startswith(("_", "name_")) or field in _NAME_FIELDS or field in PAIR_FIELDS:
            continue
        value = getattr(m, field)
        if isinstance(value, int):
            sizes.append((field, value))
        elif isinstance(value, np.ndarray):
            h.update(field.encode())
            if field in carried:
                _digest(h, value != 0)
                _digest(h, np.abs(value) >= _MINVAL)
            else:
                _digest(h, value)
    for field in sorted(dir(m.opt)):
        value = getattr(m.opt, field)
        if not field.startswith("_") and isinstance(value, int | float | np.ndarray):
            h.update(field.encode())
            value = np.asarray(value)
            _digest(h, value != 0 if f"opt.{field}" in carried else value)
    for name in entry.program_reads:
        _digest(h, np.float64(model_value(m, name)))
    return (
        tuple(sizes),
        h.hexdigest(),
        addresses(scene),
        grasp.n_ticks(),
        grasp.substeps(scene.solver),
    )


def varying_fields(base: mujoco.MjModel, models, carried: frozenset[str]) -> tuple[str, ...]:
    """The carried fields in which any of models differs from base (sorted names)."""
    return tuple(
        sorted(
            f
            for f in carried
            if any(not np.array_equal(model_value(base, f), model_value(m, f)) for m in models)
        )
    )


def with_model_fields(inputs: PickInputs, model: mujoco.MjModel, names) -> PickInputs:
    """inputs with every pick-point carrying model's values of the fields `names`:
    ``inputs.model[name]`` (N, *field shape), float64 as MuJoCo holds them (MJX and
    Warp cast to their float32 on the device). A field the inputs carry already (a
    grasp's tilt, made from the same model) is kept."""
    n = len(inputs)
    fields = {}
    for f in names:
        value = model_value(model, f)
        fields[f] = np.broadcast_to(value, (n, *value.shape)).astype(np.float64)
    return inputs.replace(model={**fields, **inputs.model})
