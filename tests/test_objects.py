"""Object import: segmentation accuracy, holes, mass properties, meshes, bad inputs."""

import math
import warnings

import cv2
import mujoco
import numpy as np
import pytest
import shapely
import trimesh
from shapely.geometry import Point, box

import mjx_pick as mp
from mjx_pick.core.config import PlausibilityWarning
from mjx_pick.core.objects import convex_partition, rasterize
from mjx_pick.engine.mjx_backend import jax_model

PX = 10.0  # px per mm of the drawn test images


def draw(tmp_path, poly, style="dark_on_light", name="obj.png", margin_mm=10.0, size=None):
    """Anti-aliased rasterisation of a polygon (mm) into a PNG at PX px/mm."""
    x0, y0, x1, y1 = poly.bounds
    w = int(math.ceil((x1 - x0 + 2 * margin_mm) * PX)) if size is None else size[0]
    h = int(math.ceil((y1 - y0 + 2 * margin_mm) * PX)) if size is None else size[1]

    def pts(coords):
        xy = np.asarray(coords)
        col = (xy[:, 0] - x0 + margin_mm) * PX - 0.5
        row = (y1 + margin_mm - xy[:, 1]) * PX - 0.5
        return np.round(np.column_stack([col, row]) * 16).astype(np.int32)

    geoms = getattr(poly, "geoms", [poly])
    mask = np.zeros((h, w), np.uint8)
    for g in geoms:
        cv2.fillPoly(mask, [pts(g.exterior.coords)], 255, cv2.LINE_AA, 4)
        for hole in g.interiors:
            cv2.fillPoly(mask, [pts(hole.coords)], 0, cv2.LINE_AA, 4)
    if style == "dark_on_light":
        img = 240 - (mask.astype(np.float32) * 0.8).astype(np.uint8)
    elif style == "light_on_dark":
        img = 20 + (mask.astype(np.float32) * 0.8).astype(np.uint8)
    else:
        img = np.zeros((h, w, 4), np.uint8)
        img[..., :3] = 128
        img[..., 3] = mask
    path = tmp_path / name
    cv2.imwrite(str(path), img)
    return path


@pytest.mark.parametrize("style", ["dark_on_light", "light_on_dark", "alpha"])
def test_rectangle_area_within_one_percent(tmp_path, style):
    # 40 x 20 mm at 10 px/mm must give 800 mm^2 +- 1%, whatever the image polarity
    path = draw(tmp_path, shapely.affinity.rotate(box(0, 0, 40, 20), 17), style)
    obj = mp.object_from_image(path, px_per_mm=PX, thickness_mm=5, mass_g=10)
    assert obj.area_mm2 == pytest.approx(800.0, rel=0.01)


def test_disc_and_hole_areas(tmp_path):
    ring = Point(0, 0).buffer(30, quad_segs=64).difference(Point(0, 0).buffer(12, quad_segs=64))
    obj = mp.object_from_image(draw(tmp_path, ring), px_per_mm=PX, thickness_mm=4, mass_g=10)
    assert len(obj.polygon.interiors) == 1, "the hole must survive segmentation"
    assert obj.area_mm2 == pytest.approx(math.pi * (30**2 - 12**2), rel=0.01)
    hole = shapely.Polygon(obj.polygon.interiors[0])
    assert hole.area == pytest.approx(math.pi * 12**2, rel=0.02)
    # the extruded mesh keeps the hole: its volume is the ring's, not the disc's
    assert obj.mesh.is_watertight
    assert obj.mesh.volume * 1e9 == pytest.approx(obj.area_mm2 * 4, rel=1e-6)


def test_block_mass_and_inertia_match_analytic(tmp_path):
    a, b, c, m = 40e-3, 20e-3, 20e-3, 0.0432
    expected = np.diag([m * (b * b + c * c), m * (a * a + c * c), m * (a * a + b * b)]) / 12
    for obj in (
        mp.object_from_polygon(box(-20, -10, 20, 10), thickness_mm=20, mass_g=43.2),
        mp.object_from_image(
            draw(tmp_path, box(0, 0, 40, 20)), px_per_mm=PX, thickness_mm=20, mass_g=43.2
        ),
    ):
        assert obj.mass_kg == pytest.approx(m)
        np.testing.assert_allclose(np.diag(obj.inertia_kg_m2), np.diag(expected), rtol=0.01)
        assert abs(obj.inertia_kg_m2[0, 1]) < 0.01 * expected[0, 0]
        np.testing.assert_allclose(obj.com_m, [0, 0, 0.01], atol=1e-4)


def test_density_gives_mass():
    obj = mp.object_from_polygon(box(0, 0, 10, 10), thickness_mm=10, density_kg_m3=1000)
    assert obj.mass_kg == pytest.approx(1e-3)


def test_convex_partition_is_exact_and_keeps_the_hook_gap(door_opener):
    # every piece is convex, pieces tile the polygon, and the hook's slot stays empty
    poly = shapely.Polygon(
        [(0, 0), (30, 0), (30, 30), (20, 30), (20, 10), (10, 10), (10, 30), (0, 30)]
    )
    parts = convex_partition(poly)
    assert sum(shapely.Polygon(p).area for p in parts) == pytest.approx(poly.area)
    for p in parts:
        sp = shapely.Polygon(p)
        assert sp.convex_hull.area == pytest.approx(sp.area)
    slot_point = Point(15, 20)
    assert not any(shapely.Polygon(p).contains(slot_point) for p in parts)
    # the shipped door opener: a point in the slot of its hook lies in no piece's hull
    x0, y0, x1, y1 = door_opener.polygon.bounds
    hull = door_opener.polygon.convex_hull
    gap = hull.difference(door_opener.polygon.buffer(1.0))
    probe = gap.representative_point()
    for piece in door_opener.pieces:
        hull2d = shapely.MultiPoint(piece[:, :2] * 1e3).convex_hull
        assert not hull2d.contains(probe)
    assert all(len(p) <= 32 for p in door_opener.pieces), "MJX vertex budget"


def test_rasterize_matches_area():
    poly = shapely.affinity.rotate(box(-20, -10, 20, 10), 30)
    mask, _ = rasterize(poly, 0.25)
    assert mask.sum() * 0.25**2 == pytest.approx(800.0, rel=0.01)


@pytest.mark.parametrize("asset", ["door_opener", "ring", "l_bracket"])
def test_rasterize_is_shapely_point_in_polygon_on_every_centre(asset):
    # scan lines give exactly the centres shapely finds inside, for the shipped outlines
    # (a hook, a hole, a corner) and a two-piece outline whose axis-aligned edges lie on
    # centre lines at 0 and 90 degrees (on the outline: outside), and at yaws between
    poly = mp.load_asset(asset).polygon
    two = shapely.MultiPolygon(
        [box(-30, -5, -10, 5), Point(20, 3).buffer(8).difference(box(18, 0, 30, 2))]
    )
    for shape in (poly, two):
        radius = float(np.hypot(*shapely.get_coordinates(shape).T).max())
        for yaw in (0.0, 0.3, 0.5 * math.pi, 2.5):
            mask, (x0, _) = rasterize(shape, 0.4, yaw, radius_mm=radius)
            rot = shapely.affinity.rotate(shape, yaw, origin=(0, 0), use_radians=True)
            centres = x0 + (np.arange(mask.shape[0]) + 0.5) * 0.4
            xs, ys = np.meshgrid(centres, centres)
            inside = shapely.contains_xy(rot, xs.ravel(), ys.ravel()).reshape(xs.shape)
            np.testing.assert_array_equal(mask, inside.astype(np.uint8))


@pytest.mark.parametrize("asset", mp.asset_names())
@pytest.mark.parametrize("preset", mp.preset_names())
def test_every_asset_and_preset_compiles_in_mujoco_and_mjx(asset, preset):
    scene = mp.build_scene(mp.load_asset(asset), mp.load_gripper(preset))
    data = mujoco.MjData(scene.model)
    mujoco.mj_forward(scene.model, data)
    assert data.warning.number.sum() == 0
    jax_model(scene.model)  # the MJX backend's model
    assert scene.index.pad_pairs and scene.index.table_pairs


def test_mesh_import_with_notch_keeps_it(tmp_path):
    # a U-shaped bracket in mm: CoACD must not fill the notch
    u = shapely.union_all([box(0, 0, 60, 10), box(0, 0, 10, 30), box(50, 0, 60, 30)])
    mesh = trimesh.creation.extrude_polygon(u, 10.0)
    mesh.apply_transform(trimesh.transformations.rotation_matrix(0.3, [0, 0, 1]))
    path = tmp_path / "u.stl"
    mesh.export(path)
    obj = mp.object_from_mesh(path, unit="mm", density_kg_m3=1000)
    assert obj.height_mm == pytest.approx(10.0, abs=0.01)
    assert obj.pick_height_mm is None  # the procedure's grasp-height rule applies
    assert obj.area_mm2 == pytest.approx(1000, rel=0.01)
    assert obj.mass_kg == pytest.approx(1000 * 10 * 1e-9 * 1000, rel=1e-6)
    # the notch centre, (30, 20) in the drawing, moved into the object frame
    c = shapely.affinity.rotate(u, 0.3, origin=(0, 0), use_radians=True).centroid
    notch = shapely.affinity.rotate(Point(30, 20), 0.3, origin=(0, 0), use_radians=True)
    notch = Point(notch.x - c.x, notch.y - c.y)
    assert not obj.polygon.contains(notch)
    assert len(obj.pieces) >= 2
    for piece in obj.pieces:
        assert not shapely.MultiPoint(piece[:, :2] * 1e3).convex_hull.contains(notch)
    scene = mp.build_scene(obj, mp.load_gripper("robotiq-2f85"))
    jax_model(scene.model)  # the MJX backend's model


# ----------------------------------------------------------------------- bad inputs


def test_unreadable_file(tmp_path):
    bad = tmp_path / "x.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(mp.ConfigError, match="cannot be read"):
        mp.object_from_image(bad, px_per_mm=10, thickness_mm=5, mass_g=10)
    with pytest.raises(mp.ConfigError, match="does not exist"):
        mp.object_from_image(tmp_path / "missing.png", px_per_mm=10, thickness_mm=5, mass_g=10)


def test_blank_image_has_no_object(tmp_path):
    path = tmp_path / "blank.png"
    cv2.imwrite(str(path), np.full((100, 100), 200, np.uint8))
    with pytest.raises(mp.ConfigError, match="no object found"):
        mp.object_from_image(path, px_per_mm=10, thickness_mm=5, mass_g=10)


def test_several_objects_refused_but_specks_dropped_with_warning(tmp_path):
    two = shapely.MultiPolygon([box(0, 0, 20, 20), box(30, 0, 50, 20)])
    with pytest.raises(mp.ConfigError, match="disconnected objects"):
        mp.object_from_image(draw(tmp_path, two), px_per_mm=10, thickness_mm=5, mass_g=10)
    speck = shapely.MultiPolygon([box(0, 0, 40, 40), box(45, 0, 46, 1)])
    with pytest.warns(UserWarning, match="kept the largest"):
        obj = mp.object_from_image(
            draw(tmp_path, speck, name="s.png"), px_per_mm=10, thickness_mm=5, mass_g=10
        )
    assert obj.area_mm2 == pytest.approx(1600, rel=0.01)


def test_object_touching_border(tmp_path):
    path = draw(tmp_path, box(0, 0, 20, 20))
    img = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
    cv2.imwrite(str(path), img[:, int(10 * PX) + 5 :])  # crop into the object's left side
    with pytest.raises(mp.ConfigError, match="touches the image border"):
        mp.object_from_image(path, px_per_mm=10, thickness_mm=5, mass_g=10)


@pytest.mark.parametrize(
    "kwargs, match",
    [
        ({"px_per_mm": None, "thickness_mm": 5, "mass_g": 1}, "px_per_mm is required"),
        ({"px_per_mm": 10, "thickness_mm": 0, "mass_g": 1}, "thickness_mm = 0"),
        ({"px_per_mm": 10, "thickness_mm": -1, "mass_g": 1}, "thickness_mm = -1"),
        ({"px_per_mm": 10, "thickness_mm": 5, "mass_g": 0}, "mass_g = 0"),
        ({"px_per_mm": 10, "thickness_mm": 5}, "give mass_g or density"),
        ({"px_per_mm": 0, "thickness_mm": 5, "mass_g": 1}, "px_per_mm = 0"),
    ],
)
def test_bad_numbers(tmp_path, kwargs, match):
    path = draw(tmp_path, box(0, 0, 20, 20))
    with pytest.raises(mp.ConfigError, match=match):
        mp.object_from_image(path, **kwargs)


# a 20 x 20 mm square, 5 mm thick (about 2000 mm^3)
@pytest.mark.parametrize(
    "kwargs, match",
    [
        # a traceback (trimesh: "mesh volume is too small") before
        ({"px_per_mm": 1000, "thickness_mm": 5, "mass_g": 1}, "is 0.202 x 0.201 mm: allowed"),
        # the CLI's and the GUI's rule for a scale (core.numbers) is the library's
        ({"px_per_mm": 1e6, "thickness_mm": 5, "mass_g": 1}, "px_per_mm = 1000000.0 is out"),
        # trimesh's "Height must be nonzero!" before: a thickness has its own range
        ({"px_per_mm": 10, "thickness_mm": 1e-6, "mass_g": 1}, "allowed 0.1 <= thickness_mm"),
        # 2 m across: ran silently for minutes
        ({"px_per_mm": 0.1, "thickness_mm": 5, "mass_g": 1}, "is 2020 x 2010 mm: allowed 1 mm"),
        ({"px_per_mm": 10, "thickness_mm": 1e5, "mass_g": 1}, "thickness_mm = 100000"),
        ({"px_per_mm": 10, "thickness_mm": 5, "mass_g": 1e9}, "density of 4.98..e.11 kg/m.3; no"),
        ({"px_per_mm": 10, "thickness_mm": 5, "mass_g": 1e-6}, "density of 0.000498.. kg/m.3; no"),
        ({"px_per_mm": 10, "thickness_mm": 5, "density_kg_m3": 0.5}, "no solid is"),
    ],
)
def test_implausible_scale_size_and_mass_are_refused(tmp_path, kwargs, match):
    path = draw(tmp_path, box(0, 0, 20, 20))
    with pytest.raises(mp.ConfigError, match=match):
        mp.object_from_image(path, **kwargs)


def test_unlikely_density_is_a_warning_with_numbers():
    with pytest.warns(PlausibilityWarning, match=r"density of 30000 kg/m\^3, outside.*50-25000"):
        mp.object_from_polygon(box(0, 0, 10, 10), thickness_mm=10, mass_g=30.0)
    with pytest.warns(PlausibilityWarning, match=r"density_kg_m3 = 20 kg/m\^3"):
        mp.object_from_polygon(box(0, 0, 10, 10), thickness_mm=10, density_kg_m3=20.0)


def test_huge_image_is_refused_from_its_header(tmp_path, monkeypatch):
    from mjx_pick.core import objects

    path = draw(tmp_path, box(0, 0, 20, 20))
    monkeypatch.setattr(objects, "MAX_IMAGE_PIXELS", 1000)
    monkeypatch.setattr(objects.cv2, "imread", lambda *a: pytest.fail("decoded"))
    with pytest.raises(mp.ConfigError, match=r"is 400 x 400 pixels: allowed at most 0.001 million"):
        mp.object_from_image(path, px_per_mm=10, thickness_mm=5, mass_g=1)


def test_an_image_too_large_to_decode_is_refused_with_its_size(tmp_path):
    # a 20000 x 20000 PNG was refused as "inf x inf pixels" (Pillow's decompression-bomb
    # refusal names no size): the header's size is said, through the installed command
    import shutil
    import struct
    import subprocess
    import sys
    import zlib

    def chunk(kind: bytes, data: bytes) -> bytes:
        crc = zlib.crc32(kind + data) & 0xFFFFFFFF
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", crc)

    header = struct.pack(">IIBBBBB", 20000, 20000, 8, 0, 0, 0, 0)  # 8-bit gray
    path = tmp_path / "scan.png"  # its header alone: no 400 MB to decode
    path.write_bytes(
        b"\x89PNG\r\n\x1a\n"
        + chunk(b"IHDR", header)
        + chunk(b"IDAT", zlib.compress(bytes(64)))
        + chunk(b"IEND", b"")
    )
    cmd = (shutil.which("mjx-pick") or f"{sys.executable} -m mjx_pick.cli").split()
    argv = ["picks", str(path), "--px-per-mm", "10", "--thickness-mm", "5", "--mass-g", "10"]
    res = subprocess.run(
        cmd + argv + ["--out", str(tmp_path / "out")], capture_output=True, text=True, timeout=120
    )
    assert res.returncode == 2, res.stderr
    assert "is 20000 x 20000 pixels: allowed at most 100 million" in res.stderr
    assert not (tmp_path / "out").exists()


def test_mesh_face_and_file_limits(tmp_path, monkeypatch):
    from mjx_pick.core import objects

    path = tmp_path / "sphere.stl"
    trimesh.creation.icosphere(subdivisions=3, radius=10.0).export(path)  # 1280 faces
    monkeypatch.setattr(objects, "MAX_MESH_FACES", 1000)
    with pytest.raises(mp.ConfigError, match="1280 triangles: allowed at most 1000; decimate"):
        mp.load_object(path, unit="mm", mass_g=5)
    monkeypatch.setattr(objects, "MAX_MESH_FILE_BYTES", 1000)
    with pytest.raises(mp.ConfigError, match="MiB file: allowed at most"):
        mp.load_object(path, unit="mm", mass_g=5)


def test_feasibility_raster_stays_within_its_memory_limit():
    # a 600 mm part at the default 0.5 mm raster took 23 GB and was killed: the raster
    # is coarsened to fit (said with numbers), computed before anything is allocated
    from mjx_pick.core import pickpoints as pp

    big = mp.object_from_polygon(box(0, 0, 600, 400), thickness_mm=5, mass_g=3000)
    radius = max(np.hypot(x, y) for x, y in big.polygon.exterior.coords)
    with pytest.warns(PlausibilityWarning, match=r"uses [0-9.]+ mm cells instead of .* = 0.5"):
        res = pp.raster_resolution(big.name, radius, 0.5)
    assert res > 0.5 and pp.raster_cells(radius, res) <= pp.MAX_RASTER_CELLS
    with pytest.warns(PlausibilityWarning):
        pp.check_raster(big)
    with warnings.catch_warnings():  # a part that fits keeps the resolution asked for
        warnings.simplefilter("error")
        assert pp.raster_resolution("small", 50.0, 0.5) == 0.5
    huge = mp.object_from_polygon(box(0, 0, 990, 990), thickness_mm=5, mass_g=9000)
    with pytest.raises(mp.ConfigError, match="even at picks.resolution_mm = 2 .*object's scale"):
        pp.check_raster(huge)


def test_timestep_above_the_converged_one_is_warned():
    with pytest.warns(PlausibilityWarning, match=r"timestep_s = 0.005 is above 0.002 s"):
        mp.SolverParams(timestep_s=0.005)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        mp.SolverParams(timestep_s=0.002)


def test_bad_gripper():
    with pytest.raises(mp.ConfigError, match="unknown gripper preset 'nope'"):
        mp.load_gripper("nope")
    with pytest.raises(mp.ConfigError, match="fingers cannot fit the stroke"):
        mp.GripperSpec(stroke_mm=10, finger_depth_mm=8)
    with pytest.raises(mp.ConfigError, match="finger_width_mm = -1"):
        mp.GripperSpec(finger_width_mm=-1)
    with pytest.raises(mp.ConfigError, match="force_min_n"):
        mp.GripperSpec(force_min_n=300)


def test_gripper_file_roundtrip(tmp_path):
    from mjx_pick.core.config import to_toml

    spec = mp.GripperSpec(name="custom", stroke_mm=60, finger_width_mm=15)
    path = tmp_path / "g.toml"
    path.write_text(to_toml(spec))
    assert mp.load_gripper(str(path)) == spec
    path.write_text('name = "x"\nstroke_mmm = 3\n')
    with pytest.raises(mp.ConfigError, match="unknown setting.*stroke_mmm"):
        mp.load_gripper(str(path))


@pytest.mark.parametrize(
    "text, missing",
    [
        ("", "name, stroke_mm, finger_width_mm"),
        ('name = "onrobot-rg2"\nstroke_mm = 110.0\nforce_max_n = 40.0\n', "finger_width_mm"),
        (
            'name = "mine"\n' + "".join(f"{k} = 10.0\n" for k in ("stroke_mm", "force_max_n")),
            "finger_width_mm.*speed_max_mm_s, finger_mass_g, body_mass_g;",
        ),
    ],
)
def test_gripper_file_missing_keys_are_named_not_filled_with_a_preset(tmp_path, text, missing):
    # they were completed with Robotiq 2F-85 values under the user's gripper name
    path = tmp_path / "g.toml"
    path.write_text(text)
    with pytest.raises(mp.ConfigError, match=f"missing {missing}.*base = "):
        mp.load_gripper(str(path))


def test_gripper_file_can_extend_a_preset_by_name(tmp_path):
    path = tmp_path / "g.toml"
    path.write_text('base = "onrobot-rg2"\nname = "rg2-long"\nfinger_width_mm = 30.0\n')
    g = mp.load_gripper(str(path))
    rg2 = mp.load_gripper("onrobot-rg2")
    assert g.name == "rg2-long" and g.finger_width_mm == 30.0
    assert (g.stroke_mm, g.force_max_n) == (rg2.stroke_mm, rg2.force_max_n)
    assert "based on onrobot-rg2" in g.source
    # an MJCF preset's model path is its own folder's
    path.write_text('base = "robotiq-2f85-linkage"\nname = "soft"\nforce_max_n = 100.0\n')
    g = mp.load_gripper(str(path))
    assert g.mjcf is not None and g.force_max_n == 100.0
    for text, match in [
        ('base = "robotiq-2f85"\nstroke_mm = 80.0\n', "give the gripper a name"),
        ('base = "nope"\nname = "x"\n', "base = 'nope' is not a gripper preset"),
    ]:
        path.write_text(text)
        with pytest.raises(mp.ConfigError, match=match):
            mp.load_gripper(str(path))


def test_mesh_bad_inputs(tmp_path):
    path = tmp_path / "b.stl"
    trimesh.creation.box([10, 10, 10]).export(path)
    with pytest.raises(mp.ConfigError, match="unit"):
        mp.object_from_mesh(path, unit="cm", mass_g=1)
    with pytest.raises(mp.ConfigError, match="check the unit"):
        mp.object_from_mesh(path, unit="m", mass_g=1)  # a 10 m cube
    with pytest.raises(mp.ConfigError, match="give its unit"):
        mp.load_object(str(path), mass_g=1)


def test_contact_mapping_clamps_table1_stiffness():
    from mjx_pick.core.physics import mujoco_contact

    solver = mp.SolverParams(timestep_s=0.001)
    mjc = mujoco_contact(mp.ContactParams(), solver, mass_kg=0.013, patch_mm=(22.0, 5.0))
    # Table 1's 1e5 N/mm cannot be integrated at 1 ms: clamped to tc = 2 ms, critical
    assert mjc.pad_solref == pytest.approx((-1 / 0.002**2, -2 / 0.002))
    assert "pad_stiffness" in mjc.clamped
    soft = mujoco_contact(
        mp.ContactParams(pad_stiffness_n_per_mm=1e-3, pad_damping_ns_per_mm=1e-5),
        solver,
        mass_kg=0.01,
        patch_mm=(22.0, 5.0),
    )
    assert soft.pad_solref == pytest.approx((-100.0, -1.0))
    assert not any(c.startswith("pad") for c in soft.clamped)
    with pytest.raises(mp.ConfigError, match="contact.pad_friction = -0.1"):
        mp.ContactParams(pad_friction=-0.1)
