"""Fuzzing the input readers (issue 21): random and corrupt images, meshes, CSV and TOML
files always give a valid result or a ConfigError (a clear message naming the input),
never another exception.

Property-based with hypothesis; each property runs a few dozen examples (derandomized:
the same examples on every run, so CI is reproducible; raise max_examples locally to
search harder).
"""

import string
import tempfile
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


def _file(suffix: str, data: bytes | str) -> Path:
    """A fresh file (hypothesis reruns a test body many times: no pytest tmp_path)."""
    folder = Path(tempfile.mkdtemp(prefix="mjx_pick_fuzz_"))
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


@FUZZ
@given(body=text_lines)
def test_outcomes_csv_gives_outcomes_or_a_clear_error(body):
    header = "x_mm,y_mm,yaw_deg,success\n"
    path = _file(".csv", header + body)
    _valid_or_config_error(read_outcomes, path)


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
