"""URDF grippers: the shipped Robotiq 2F-85 URDF against its MJCF twin, and every error.

The twin is MuJoCo Menagerie's MJCF of the same gripper (``robotiq-2f85-linkage``): the
two files were drawn separately from Robotiq's CAD, so they agree to the CAD's
tolerance, not to the bit. The bounds below are what the two files' geometry allows
(their pads are 6.35 and 8 mm deep; their kinematics differ by under a millimetre over
the stroke) and the labels of the same pick-points must agree.
"""

import dataclasses
import re
from importlib import resources
from pathlib import Path

import numpy as np
import pytest

import mjx_pick as mp
from mjx_pick.core import mjcf_gripper
from mjx_pick.core.config import ConfigError, from_mapping, to_dict
from mjx_pick.core.procedure import GraspConfig

URDF = "robotiq-2f85-urdf"
TWIN = "robotiq-2f85-linkage"
GRIPPERS = resources.files("mjx_pick.assets") / "grippers"
SHIPPED = Path(str(GRIPPERS / "robotiq_2f85_urdf" / "urdf" / "robotiq_2f_85.urdf"))
MESHES = SHIPPED.parent.parent / "meshes"
PROC = GraspConfig(close_timeout_s=1.0, lift_height_mm=30.0, hold_s=0.3)
TABLE = """
name = "my-2f85"
force_min_n = 20.0
force_max_n = 235.0
speed_min_mm_s = 20.0
speed_max_mm_s = 150.0

[urdf]
file = "{file}"
mount_quat = [0.0, 1.0, 0.0, 0.0]
pad_left_links = ["left_inner_finger_pad"]
pad_right_links = ["right_inner_finger_pad"]
joint = "{joint}"
servo_kp = 1000.0
servo_kv = 10.0
servo_forcerange = 28.5
drive_armature = 0.005
linkage_armature = 0.001
{extra}
"""


def gripper_file(tmp_path, file=SHIPPED, joint="finger_joint", extra="") -> Path:
    path = tmp_path / "g.toml"
    path.write_text(TABLE.format(file=file, joint=joint, extra=extra))
    return path


def urdf_copy(tmp_path, edit=lambda text: text, folder="urdf") -> Path:
    """The shipped URDF, edited, written under tmp_path/folder with absolute mesh paths."""
    text = SHIPPED.read_text()
    text = text.replace('filename="../meshes/', f'filename="{MESHES}/')
    out = tmp_path / folder / "g.urdf"
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(edit(text))
    return out


@pytest.fixture(scope="module")
def pair():
    return mp.load_gripper(URDF), mp.load_gripper(TWIN)


def test_the_urdf_gripper_measures_like_its_mjcf_twin(pair):
    urdf, twin = pair
    assert urdf.mjcf.urdf is not None and urdf.mjcf.actuator == "urdf_servo"
    # stroke: 85.99 vs 85.36 mm (the files' kinematics); the datasheet says 85
    assert urdf.stroke_mm == pytest.approx(twin.stroke_mm, abs=1.0)
    assert urdf.finger_width_mm == pytest.approx(twin.finger_width_mm, abs=0.1)
    assert urdf.pad_height_mm == pytest.approx(twin.pad_height_mm, abs=0.1)
    assert urdf.finger_depth_mm == pytest.approx(6.35, abs=0.05)  # the URDF's pad box
    ku, kt = (mjcf_gripper.characterise(g.mjcf) for g in pair)
    # both linkages' pads descend ~13-14 mm while closing: the same height compensation
    drop = [1e3 * (k.pad_centre_z[0] - k.pad_centre_z.min()) for k in (ku, kt)]
    assert drop[0] == pytest.approx(drop[1], abs=1.5)
    gaps = np.linspace(0.01, 0.08, 8)
    np.testing.assert_allclose(
        ku.height_compensation_m(gaps), kt.height_compensation_m(gaps), atol=1.5e-3
    )
    # the servo pushes the datasheet's 235 N at every opening
    assert ku.force_limit_n.min() >= urdf.force_max_n


def test_the_urdf_gripper_labels_picks_as_its_twin_does(pair, tmp_path):
    urdf, twin = pair
    runs = {
        g.name: mp.evaluate("door_opener", g, n=6, seed=3, grasp=PROC, out=tmp_path / g.name)
        for g in pair
    }
    a, b = (runs[g.name].table for g in pair)
    # the same candidates: both grippers open as wide (within a mm) for each
    assert a["pick_id"].to_pylist() == b["pick_id"].to_pylist()
    assert a["success"].to_pylist() == b["success"].to_pylist()
    # a servo that cannot squeeze (the couplings yielding) fails them all, as both would
    # by a wrong pad height: most hold (the twin: 97 % at this physics)
    assert sum(a["success"].to_pylist()) >= 4
    np.testing.assert_allclose(a["score"].to_numpy(), b["score"].to_numpy(), atol=0.05)
    assert a["failure"].to_pylist() == b["failure"].to_pylist()
    # the P controller reaches F_d on the URDF's servo as on the twin's
    held = np.asarray(a["success"])
    assert np.asarray(a["max_force_left_n"])[held].min() > 0.9 * 50.0


def test_the_saved_config_loads_the_same_gripper(pair):
    urdf, _ = pair
    again = from_mapping(mp.GripperSpec, to_dict(urdf))
    assert again == urdf and again.mjcf.urdf == urdf.mjcf.urdf


def test_mimic_from_the_toml_replaces_the_urdfs_own(tmp_path, pair):
    """The URDF without its <mimic> tags, the couplings given in the TOML instead, makes
    the same gripper (and its package:// mesh paths resolve)."""
    followers = {}

    def strip(text):
        for joint, mult in re.findall(
            r'<joint name="(\w+)"[^>]*>(?:(?!</joint>).)*?<mimic joint="finger_joint" '
            r'multiplier="(-?\d+)"',
            text,
            flags=re.S,
        ):
            followers[joint] = float(mult)
        text = re.sub(r"\s*<mimic [^>]*/>", "", text)
        return text.replace(f'filename="{MESHES}/', 'filename="package://gpkg/meshes/')

    path = urdf_copy(tmp_path / "gpkg", strip)
    (tmp_path / "gpkg" / "meshes").symlink_to(MESHES)
    assert len(followers) == 5
    table = "[urdf.mimic]\n" + "".join(f"{j} = {m}\n" for j, m in followers.items())
    mine = mp.load_gripper(gripper_file(tmp_path, file=path, extra=table))
    assert mine.stroke_mm == pytest.approx(pair[0].stroke_mm, abs=0.01)
    assert mine.finger_depth_mm == pair[0].finger_depth_mm
    without = gripper_file(tmp_path, file=path)  # no couplings: the right finger is loose
    with pytest.raises(ConfigError, match="does not drive the right finger"):
        mp.load_gripper(without)


@pytest.mark.parametrize(
    ("edit", "joint", "extra", "message"),
    [
        (None, "finger_joint2", "", r"\[urdf\] joint = 'finger_joint2': the URDF has no joint"),
        (None, "left_outer_finger_joint", "", r"is a fixed joint: the servo drives a revolute"),
        (
            lambda t: t.replace('lower="0" upper="0.8"', ""),
            "finger_joint",
            "",
            r"finger_joint' has no <limit lower=\.\.\. upper=\.\.\.>",
        ),
        (
            lambda t: t.replace('"left_inner_finger_pad"', '"left_pad_link"'),
            "finger_joint",
            "",
            r"pad_left_links = 'left_inner_finger_pad': the URDF has no link",
        ),
        (
            lambda t: t.replace("robotiq_arg2f_85_inner_knuckle.obj", "knuckle_v2.obj"),
            "finger_joint",
            "",
            r"link 'left_inner_knuckle'.s collision mesh '.*knuckle_v2.obj' is missing",
        ),
        (None, "finger_joint", "[urdf.mimic]\nno_such_joint = 1.0", r"mimic.no_such_joint"),
        (None, "finger_joint", "mount_link = 'tool0'", r"mount_link = 'tool0'"),
        (lambda t: t.replace("robot", "sdf"), "finger_joint", "", r"not a URDF"),
        (lambda t: t[: len(t) // 2], "finger_joint", "", r"is not an XML file"),
    ],
)
def test_a_wrong_urdf_or_table_names_what_is_missing(tmp_path, edit, joint, extra, message):
    path = urdf_copy(tmp_path, edit) if edit else SHIPPED
    with pytest.raises(ConfigError, match=message):
        mp.load_gripper(gripper_file(tmp_path, file=path, joint=joint, extra=extra))


def test_a_missing_urdf_file_and_a_missing_setting_are_named(tmp_path):
    with pytest.raises(ConfigError, match=r"\[urdf\] file = 'nowhere.urdf': no such file"):
        mp.load_gripper(gripper_file(tmp_path, file="nowhere.urdf"))
    text = TABLE.format(file=SHIPPED, joint="finger_joint", extra="").replace(
        "drive_armature = 0.005\n", ""
    )
    (tmp_path / "g.toml").write_text(text)
    with pytest.raises(ConfigError, match="drive_armature"):
        mp.load_gripper(tmp_path / "g.toml")
    both = TABLE.format(file=SHIPPED, joint="finger_joint", extra="") + (
        '[mjcf]\nfile = "x.xml"\nmount_body = "b"\npad_left_geoms = ["a"]\n'
        'pad_right_geoms = ["b"]\nactuator = "c"\n'
    )
    (tmp_path / "g.toml").write_text(both)
    with pytest.raises(ConfigError, match=r"an \[mjcf\] or a \[urdf\] table, not both"):
        mp.load_gripper(tmp_path / "g.toml")


def test_a_preset_based_file_may_swap_the_model(tmp_path):
    """base = the MJCF twin, [urdf] given: the file's model replaces the base's."""
    text = TABLE.format(file=SHIPPED, joint="finger_joint", extra="")
    text = 'base = "robotiq-2f85-linkage"\n' + text.replace("force_min_n = 20.0\n", "")
    (tmp_path / "g.toml").write_text(text)
    g = mp.load_gripper(tmp_path / "g.toml")
    assert g.mjcf.urdf is not None and g.force_min_n == 20.0
    assert dataclasses.replace(g.mjcf, urdf=None).file.endswith(".urdf")


JAW = """<?xml version="1.0"?>
<robot name="jaw">
  <link name="base">
    <inertial><mass value="0.5"/>
      <inertia ixx="1e-3" iyy="1e-3" izz="1e-3" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 -0.01"/><geometry><box size="0.12 0.03 0.02"/></geometry>
    </collision>
  </link>
  {fingers}
</robot>
"""
FINGER = """<link name="{side}">
    <inertial><mass value="0.05"/>
      <inertia ixx="1e-5" iyy="1e-5" izz="1e-5" ixy="0" ixz="0" iyz="0"/></inertial>
    <collision><origin xyz="0 0 0.03"/><geometry><box size="0.008 0.02 0.03"/></geometry>
    </collision>
  </link>
  <joint name="j_{side}" type="prismatic">
    <parent link="base"/><child link="{side}"/><origin xyz="{x} 0 0"/><axis xyz="{axis} 0 0"/>
    <limit lower="0" upper="0.04" effort="200" velocity="0.2"/>
  </joint>"""


def test_a_prismatic_jaw_coupled_in_the_toml_measures_and_picks(tmp_path):
    """Two prismatic fingers (pads 8 x 20 x 30 mm, inner faces 80 mm apart), the right
    one mimicking the left in the TOML: the stroke and pads are the URDF's, and it holds
    the block."""
    fingers = FINGER.format(side="left", x=-0.044, axis=1) + FINGER.format(
        side="right", x=0.044, axis=-1
    )
    (tmp_path / "jaw.urdf").write_text(JAW.format(fingers=fingers))
    text = """
name = "jaw"
force_min_n = 5.0
force_max_n = 100.0
speed_min_mm_s = 5.0
speed_max_mm_s = 150.0

[urdf]
file = "jaw.urdf"
mount_quat = [0.0, 1.0, 0.0, 0.0]
pad_left_links = ["left"]
pad_right_links = ["right"]
joint = "j_left"
servo_kp = 20000.0    # N/m: 10 N/mm at each pad (the drive moves both: F = tau / 2)
servo_kv = 40.0
servo_forcerange = 250.0
drive_armature = 0.5
linkage_armature = 0.5
{extra}
"""
    path = tmp_path / "jaw.toml"
    path.write_text(text.replace("{extra}", ""))
    with pytest.raises(ConfigError, match="does not drive the right finger"):
        mp.load_gripper(path)
    path.write_text(text.replace("{extra}", "[urdf.mimic]\nj_right = 1.0"))
    jaw = mp.load_gripper(path)
    assert jaw.stroke_mm == pytest.approx(80.0, abs=0.05)
    assert (jaw.finger_depth_mm, jaw.finger_width_mm, jaw.pad_height_mm) == pytest.approx(
        (8.0, 20.0, 30.0), abs=0.01
    )
    assert jaw.mjcf.urdf.mimic == (("j_right", 1.0),)
    ev = mp.evaluate("block", jaw, n=3, seed=0, grasp=PROC, out=tmp_path / "run")
    assert ev.table["success"].to_pylist() == [True] * 3
    assert np.asarray(ev.table["max_force_left_n"]).min() > 0.9 * 50.0
