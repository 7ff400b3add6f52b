"""Fuzzing the input readers (issue 21): random and corrupt images, meshes, CSV and TOML
files always give a valid result or a ConfigError (a clear message naming the input),
never another exception -- and never a silent default: rows reach row validation, a
gripper file's values are its own or its base preset's, a mesh of several bodies is
refused, a byte-order mark changes nothing.

Property-based with hypothesis; each property runs a few dozen examples (derandomized:
the same examples on every run, so CI is reproducible; raise max_examples locally to
search harder).
"""

import string
import tempfile
import warnings
from pathlib import Path

import cv2
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import mjx_pick as mp
from mjx_pick.core.config import ConfigError, load_toml
from mjx_pick.core.objects import ObjectModel
from mjx_pick.studies.calibration import read_outcomes
from mjx_pick.studies.pickfiles import read_picks_csv

FUZZ = settings(
    max_examples=30,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
)
text_lines = st.text(alphabet=string.printable, max_size=400)


_FOLDER: list[Path] = []  # this module's temporary folder, set by _in_pytests_tmp


@pytest.fixture(scope="module", autouse=True)
def _in_pytests_tmp(tmp_path_factory):
    """The examples' files go under pytest's temporary folder, which pytest prunes (a
    folder per example in the system's /tmp left 480 behind on every run)."""
    _FOLDER[:] = [tmp_path_factory.mktemp("fuzz")]
    yield
    _FOLDER.clear()


def _file(suffix: str, data: bytes | str) -> Path:
    """A fresh file (hypothesis reruns a test body many times: no pytest tmp_path)."""
    folder = Path(tempfile.mkdtemp(dir=_FOLDER[0]))
    path = folder / f"input{suffix}"
    if isinstance(data, str):
        path.write_text(data)
    else:
        path.write_bytes(data)
    return path


def _valid_or_config_error(fn, *args, **kwargs):
    try:
        return fn(*args, **kwargs)
    except ConfigError as err:
        assert str(err).strip(), "an empty error message"
        return None


# --------------------------------------------------------------------------- images
@FUZZ
@given(data=st.binary(max_size=2000), suffix=st.sampled_from([".png", ".jpg", ".bmp"]))
def test_corrupt_image_files_give_a_clear_error(data, suffix):
    path = _file(suffix, data)
    obj = _valid_or_config_error(mp.load_object, path, px_per_mm=2.0, thickness_mm=5.0, mass_g=10.0)
    assert obj is None or isinstance(obj, ObjectModel)


@FUZZ
@given(
    h=st.integers(1, 48),
    w=st.integers(1, 48),
    seed=st.integers(0, 2**16),
    kind=st.sampled_from(["noise", "blob", "blank", "stripes"]),
    px_per_mm=st.floats(0.05, 50.0),
    thickness_mm=st.floats(0.1, 200.0),
    mass_g=st.floats(0.1, 5000.0),
)
def test_random_images_give_an_object_or_a_clear_error(
    h, w, seed, kind, px_per_mm, thickness_mm, mass_g
):
    rng = np.random.default_rng(seed)
    img = np.full((h, w), 255, np.uint8)
    if kind == "noise":
        img = rng.integers(0, 256, (h, w), dtype=np.uint8)
    elif kind == "blob":
        cy, cx = rng.integers(0, h), rng.integers(0, w)
        r = int(rng.integers(1, max(h, w) + 1))
        cv2.circle(img, (int(cx), int(cy)), r, 0, -1)
    elif kind == "stripes":
        img[:, :: max(1, w // 4)] = 0
    path = _file(".png", b"")
    cv2.imwrite(str(path), img)
    obj = _valid_or_config_error(
        mp.load_object, path, px_per_mm=px_per_mm, thickness_mm=thickness_mm, mass_g=mass_g
    )
    if obj is not None:
        assert obj.polygon.is_valid and obj.polygon.area > 0
        assert obj.mass_kg > 0 and np.isfinite(obj.height_mm)


# --------------------------------------------------------------------------- meshes
@FUZZ
@given(data=st.binary(max_size=3000), suffix=st.sampled_from([".stl", ".obj", ".ply"]))
def test_corrupt_mesh_files_give_a_clear_error(data, suffix):
    path = _file(suffix, data)
    obj = _valid_or_config_error(mp.load_object, path, unit="mm", mass_g=50.0)
    assert obj is None or isinstance(obj, ObjectModel)


@FUZZ
@given(text=text_lines)
def test_corrupt_obj_text_gives_a_clear_error(text):
    path = _file(".obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n" + text)
    obj = _valid_or_config_error(mp.load_object, path, unit="mm", mass_g=50.0)
    assert obj is None or isinstance(obj, ObjectModel)


# --------------------------------------------------------------------------- CSV
@FUZZ
@given(body=text_lines, header=st.sampled_from(["x_mm,y_mm,yaw_deg\n", "x_mm,y_mm\n", ""]))
def test_picks_csv_gives_rows_or_a_clear_error(body, header):
    path = _file(".csv", header + body)
    out = _valid_or_config_error(read_picks_csv, path)
    if out is not None:
        x, y, yaw = out
        assert len(x) == len(y) == len(yaw) > 0
        assert np.isfinite(np.concatenate([x, y, yaw])).all()


cells = st.one_of(
    st.integers(-5, 40).map(str),
    st.floats(-1e3, 1e3, allow_nan=False).map(lambda v: f"{v:.3g}"),
    st.sampled_from(["", "nan", "inf", "x", "1e400", " 2 ", "-0"]),
)


def _csv(header: list[str], rows: list[list[str]]) -> str:
    return ",".join(header) + "\n" + "".join(",".join(r) + "\n" for r in rows)


@FUZZ
@given(body=text_lines)
def test_outcomes_csv_gives_outcomes_or_a_clear_error(body):
    # the whole required header: the rows below it are validated (with a header that
    # lacked grip_force_n, trials and successes every example stopped at the header)
    header = "x_mm,y_mm,yaw_deg,grip_force_n,trials,successes\n"
    path = _file(".csv", header + body)
    _valid_or_config_error(read_outcomes, path)


@FUZZ
@given(rows=st.lists(st.lists(cells, min_size=6, max_size=6), min_size=1, max_size=6))
def test_outcome_rows_are_validated(rows):
    header = ["x_mm", "y_mm", "yaw_deg", "grip_force_n", "trials", "successes"]
    out = _valid_or_config_error(read_outcomes, _file(".csv", _csv(header, rows)))
    if out is not None:
        assert len(out.x_mm) == len(rows)
        assert (out.successes <= out.trials).all() and (out.successes >= 0).all()
        assert np.isfinite(out.grip_force_n).all() and (out.grip_force_n > 0).all()


@FUZZ
@given(
    rows=st.lists(st.lists(cells, min_size=4, max_size=4), min_size=1, max_size=6),
    with_id=st.booleans(),
    repeat=st.booleans(),
    extra=st.sampled_from([None, "grip_force_n", "note", "coverage"]),
)
def test_pick_rows_keep_their_ids_or_give_a_clear_error(rows, with_id, repeat, extra):
    header = (["pick_id"] if with_id else []) + ["x_mm", "y_mm", "yaw_deg"]
    rows = [r[: len(header)] for r in rows] + ([rows[0][: len(header)]] if repeat else [])
    if extra:
        header, rows = header + [extra], [r + ["1"] for r in rows]
    out = _valid_or_config_error(read_picks_csv, _file(".csv", _csv(header, rows)))
    if out is not None:
        assert extra in (None, "coverage") and not repeat  # never a silent pass
        assert len(out.pick_id) == len(rows) == len(set(out.pick_id.tolist()))
        expected = [int(float(r[0])) for r in rows] if with_id else list(range(len(rows)))
        assert out.pick_id.tolist() == expected
        poses = set(zip(out.x_mm, out.y_mm, out.yaw_deg, strict=True))
        assert len(poses) == len(rows)


@FUZZ
@given(
    reader=st.sampled_from(["picks", "outcomes", "sheet"]),
    rows=st.lists(st.tuples(st.integers(-20, 20), st.integers(1, 9)), min_size=1, max_size=5),
    crlf=st.booleans(),
)
def test_a_byte_order_mark_changes_nothing(reader, rows, crlf):
    """Excel's UTF-8 CSVs start with a byte-order mark: every CSV reader takes them."""
    from mjx_pick.studies.calibration.trials.sheet import read_sheet

    header = ["x_mm", "y_mm", "yaw_deg", "grip_force_n", "trials", "successes"]
    body = [[str(x), str(i), "0", str(f), "2", "1"] for i, (x, f) in enumerate(rows)]
    if reader == "picks":
        header, body = header[:3], [r[:3] for r in body]
    if reader == "sheet":
        header, body = ["pick_id", *header], [[str(i), *r] for i, r in enumerate(body)]
    text = _csv(header, body).replace("\n", "\r\n" if crlf else "\n")
    plain, marked = _file(".csv", text.encode()), _file(".csv", "\ufeff".encode() + text.encode())
    if reader == "sheet":
        (plain.parent / "trials.csv").write_bytes(plain.read_bytes())
        (marked.parent / "trials.csv").write_bytes(marked.read_bytes())
        assert read_sheet(plain.parent) == read_sheet(marked.parent)
        return
    read = read_picks_csv if reader == "picks" else read_outcomes
    a, b = _valid_or_config_error(read, plain), _valid_or_config_error(read, marked)
    assert (a is None) == (b is None)
    if a is not None:
        for u, v in zip(a, b, strict=True) if reader == "picks" else [(a.x_mm, b.x_mm)]:
            np.testing.assert_array_equal(u, v)


# --------------------------------------------------------------------------- TOML
toml_values = st.one_of(
    st.integers(-(10**6), 10**6),
    st.floats(allow_nan=True, allow_infinity=True),
    st.booleans(),
    st.text(string.ascii_letters, max_size=8),
    st.lists(st.floats(-10, 10), max_size=6),
)


def _toml_line(key, value) -> str:
    if isinstance(value, bool):
        v = "true" if value else "false"
    elif isinstance(value, float):
        v = {float("inf"): "inf", float("-inf"): "-inf"}.get(value, repr(value))
        v = "nan" if value != value else v
    elif isinstance(value, str):
        v = f'"{value}"'
    elif isinstance(value, list):
        v = "[" + ", ".join(repr(x) for x in value) + "]"
    else:
        v = str(value)
    return f"{key} = {v}\n"


@pytest.mark.parametrize("cls", [mp.ContactParams, mp.SolverParams, mp.GraspConfig])
@FUZZ
@given(data=st.data())
def test_toml_configs_load_or_give_a_clear_error(cls, data):
    import dataclasses

    names = [f.name for f in dataclasses.fields(cls)] + ["not_a_field"]
    keys = data.draw(st.lists(st.sampled_from(names), max_size=4, unique=True))
    text = "".join(_toml_line(k, data.draw(toml_values)) for k in keys)
    text += data.draw(st.sampled_from(["", "[oops\n", "x = \n", "= 1\n"]))
    path = _file(".toml", text)
    out = _valid_or_config_error(load_toml, cls, path)
    assert out is None or isinstance(out, cls)


@FUZZ
@given(data=st.data())
def test_gripper_toml_loads_or_gives_a_clear_error(data):
    import dataclasses

    names = [f.name for f in dataclasses.fields(mp.GripperSpec)] + ["mjcf", "bogus"]
    keys = data.draw(st.lists(st.sampled_from(names), max_size=4, unique=True))
    text = "".join(_toml_line(k, data.draw(toml_values)) for k in keys)
    path = _file(".toml", text)
    out = _valid_or_config_error(mp.load_gripper, path)
    assert out is None or isinstance(out, mp.GripperSpec)


@FUZZ
@given(data=st.data())
def test_gripper_toml_values_are_its_own_never_a_silent_default(data):
    """A gripper file with keys left out: a ConfigError naming them, or (every required
    key given, or a base preset named) a gripper whose every value is the file's own or
    its base's -- never the 2F-85's under the user's name."""
    from mjx_pick.core.gripper import REQUIRED, preset_names

    spec = mp.GripperSpec(name="fuzzed", stroke_mm=100.0, finger_width_mm=20.0, force_min_n=5.0)
    values = {k: getattr(spec, k) for k in REQUIRED}
    keys = data.draw(st.lists(st.sampled_from(REQUIRED), unique=True))
    base = data.draw(st.sampled_from([None, *[p for p in preset_names() if "linkage" not in p]]))
    text = "".join(_toml_line(k, values[k]) for k in keys)
    text += "" if base is None else f'base = "{base}"\n'
    out = _valid_or_config_error(mp.load_gripper, _file(".toml", text))
    if out is None:
        return
    assert base is not None or set(keys) == set(REQUIRED)
    origin = mp.load_gripper(base) if base is not None else None
    for k in REQUIRED:
        expected = values[k] if k in keys else getattr(origin, k)
        assert getattr(out, k) == expected, k


# ------------------------------------------------------------------- meshes, made


@FUZZ
@given(
    boxes=st.lists(
        st.tuples(
            st.tuples(*[st.sampled_from([0.0, 1e-4, 0.5, 5.0, 30.0, 2000.0])] * 3),
            st.tuples(*[st.sampled_from([0.0, 3.0, 40.0, 5000.0])] * 3),
        ),
        min_size=1,
        max_size=3,
    ),
    largest=st.booleans(),
    suffix=st.sampled_from([".stl", ".obj", ".ply"]),
)
def test_made_meshes_give_one_body_or_a_clear_error(hull_pieces, boxes, largest, suffix):
    """Boxes of any size (flat, tiny, huge) at any offsets, overlapping or apart: one
    solid object, or a ConfigError -- a mesh of several bodies never loads silently."""
    import trimesh

    parts = []
    for extents, offset in boxes:
        box_ = trimesh.creation.box(extents)
        box_.apply_translation(offset)
        parts.append(box_)
    path = _file(suffix, b"")
    trimesh.util.concatenate(parts).export(path)
    solid = [float(np.prod(extents)) for extents, _ in boxes if np.prod(extents) > 0]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the dropped bodies' warning (largest_body)
        obj = _valid_or_config_error(
            mp.load_object, path, unit="mm", density_kg_m3=2700.0, largest_body=largest
        )
    if obj is not None:
        assert isinstance(obj, ObjectModel) and obj.mass_kg > 0
        # one box's solid, never several boxes' mass under one outline
        assert obj.mesh.volume * 1e9 == pytest.approx(max(solid), rel=1e-6)
