"""Connections that define a standard type otherwise (occmap.io.bags.definitions): bags written
with rosbags whose connection declares a changed LaserScan, TFMessage or Odometry are refused
with an error saying what differs, before a byte is decoded the wrong way; the standard
definitions pass, by their digests (ROS's published md5sums) and by their parsed fields alike."""

from __future__ import annotations

import numpy as np
import pytest

from occmap.errors import FormatError
from occmap.io.bags import open_bag, read_frame_tree, read_odometry
from occmap.io.bags.definitions import difference, standard_digest
from occmap.sources import BagScans

rosbags = pytest.importorskip("rosbags")
from rosbags.typesys import Stores, get_types_from_msg, get_typestore  # noqa: E402

from bag_writing import CLOUD, KINDS, ODOM, SCAN, TF, Msgs, quat_xyzw_of_yaw, standard_store, write_bag  # noqa: E402

# md5sums of the messages as ROS 1 publishes them (rosmsg md5 ...)
ROS1_MD5 = {SCAN: "90c7ef2dc6895d81024acba2ac42f369", TF: "94810edda583a504dfda3829e70d7eec",
            "tf/msg/tfMessage": "94810edda583a504dfda3829e70d7eec", ODOM: "cd5e73d190d741a2f92e81eda573aca7",
            CLOUD: "1158d486dd51d683ce2f1be655c3c181"}


def test_standard_digests_are_ros_ones():
    assert {t: standard_digest("ros1", t) for t in ROS1_MD5} == ROS1_MD5
    assert standard_digest("cdr", SCAN).startswith("RIHS01_")


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_standard_definitions_pass_when_parsed(kind):
    """Without a digest to go by (ROS 2 bags before Iron), the definition text decides: the
    standard one, as recorders write it, has the standard fields."""
    store, encoding = standard_store(kind), "ros1" if kind == "ros1" else "cdr"
    for msgtype in (SCAN, TF, ODOM, CLOUD):
        text = store.generate_msgdef(msgtype, ros_version=1 if kind == "ros1" else 2)[0]
        assert difference(encoding, msgtype, "", "msg", text) == ""
        assert difference(encoding, msgtype, "", "", "") == ("" if encoding == "cdr" else
                                                           f"md5sum '', not the standard {ROS1_MD5[msgtype]!r}")


def redefined(kind, msgtype, edit):
    """A type store whose ``msgtype`` is the standard definition text changed by ``edit``."""
    text = standard_store(kind).generate_msgdef(msgtype, ros_version=1 if kind.startswith("ros1") else 2)[0]
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(edit(text), msgtype))
    return store


def custom_scan(m):
    """One LaserScan of the store's own definition: the standard values, ``scan_id`` and
    ``distances`` for the fields a changed definition adds or renames."""
    values = dict(header=m.header(1.0, "laser"), angle_min=0.25, angle_max=0.45, angle_increment=0.1,
                  time_increment=0.0, scan_time=0.0, range_min=0.0, range_max=5.0,
                  ranges=np.array([1.0, 2.0, 3.0], np.float32), intensities=np.zeros(0, np.float32),
                  scan_id=7, distances=np.array([1.0, 2.0, 3.0], np.float32))
    yield "/scan", SCAN, 1.0, m.T[SCAN](**{name: values[name] for name, _ in m.ts.fielddefs[SCAN][1]})


CHANGES = {  # a changed LaserScan: the edit of its definition, and what the error must say
    "inserted": (lambda t: t.replace("header\n", "header\nuint32 scan_id\n", 1),
                 r"has an extra field scan_id \(uint32\)"),
    "renamed": (lambda t: t.replace("float32[] ranges", "float32[] distances"),
                r"lacks field ranges \(float32\[\]\); has an extra field distances \(float32\[\]\)"),
}


@pytest.mark.parametrize("change", CHANGES)
@pytest.mark.parametrize("kind", KINDS)
def test_changed_laser_scan_is_refused(tmp_path, kind, change, reader_for):
    edit, said = CHANGES[change]
    path = write_bag(tmp_path, kind, custom_scan, typestore=redefined(kind, SCAN, edit))
    reader_for(kind)
    with pytest.raises(FormatError, match=f"topic '/scan' declares its own {SCAN}.*: {said}") as e:
        BagScans(path)
    assert str(path) in str(e.value)


@pytest.mark.parametrize("kind", ["ros1_chunks", "sqlite3"])
def test_changed_nested_tf_and_odometry_are_refused(tmp_path, kind, reader_for):
    """A field renamed inside TransformStamped, and one added to Odometry's end."""
    def build(m):
        G = m.T
        transform = G["geometry_msgs/msg/Transform"](translation=G["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                                     rotation=G["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0,
                                                                                               w=1.0))
        stamped = G["geometry_msgs/msg/TransformStamped"](header=m.header(1.0, "odom"), child="laser",
                                                          transform=transform)
        yield "/tf", TF, 1.0, G[TF](transforms=[stamped])

    tf_store = redefined(kind, TF, lambda t: t.replace("string child_frame_id", "string child"))
    path = write_bag(tmp_path, kind, build, "tf", typestore=tf_store)
    reader_for(kind)
    with pytest.raises(FormatError, match=r"topic '/tf' declares its own tf2_msgs/msg/TFMessage.*lacks field "
                                          r"transforms\[\]\.child_frame_id \(string\)"):
        with open_bag(path) as bag:
            read_frame_tree(bag)

    odom_store = redefined(kind, ODOM, lambda t: t.replace("TwistWithCovariance twist\n",
                                                           "TwistWithCovariance twist\nuint8 quality\n", 1))

    def odometry(m):
        msg = Msgs(standard_store(kind)).odometry(1.0, "odom", "base_link", (1.0, 2.0, 0.0), quat_xyzw_of_yaw(0.0))
        yield "/odom", ODOM, 1.0, m.T[ODOM](**{name: getattr(msg, name, 3) for name, _ in m.ts.fielddefs[ODOM][1]})

    path = write_bag(tmp_path, kind, odometry, "odom", typestore=odom_store)
    with pytest.raises(FormatError, match=r"topic '/odom' declares its own nav_msgs/msg/Odometry.*has an extra "
                                          r"field quality \(uint8\)"):
        with open_bag(path) as bag:
            read_odometry(bag, "/odom")


@pytest.mark.parametrize("kind", ["ros1", "mcap"])
def test_standard_bag_passes(tmp_path, kind):
    """The same scan in the standard definition is read, with its values."""
    path = write_bag(tmp_path, kind, lambda m: [
        ("/tf", TF, 1.0, m.tf([m.transform(1.0, "odom", "laser", (0.0, 0.0, 0.0), quat_xyzw_of_yaw(0.0))])),
        *custom_scan(m)])
    (scan,) = BagScans(path)
    assert np.allclose(scan.angles, [0.25, 0.35, 0.45]) and np.array_equal(scan.ranges, [1.0, 2.0, 3.0])


LASER_SCAN_IDL = """module sensor_msgs {
  module msg {
    struct LaserScan {
      std_msgs::msg::Header header;
      float angle_min;
      float angle_max;
      float angle_increment;
      float time_increment;
      float scan_time;
      float range_min;
      float range_max;
      sequence<float> ranges;
      sequence<float> intensities;
    };
  };
};
"""


def test_idl_definitions_are_compared_too():
    """MCAP schemas may hold ``.idl`` text (ros2idl): parsed and compared the same way."""
    assert difference("cdr", SCAN, "", "idl", LASER_SCAN_IDL) == ""
    assert difference("cdr", SCAN, "", "idl", LASER_SCAN_IDL.replace("float scan_time", "double scan_time")) \
        == "field scan_time is float64, not float32"
    assert difference("cdr", SCAN, "", "idl", "module broken {").startswith("its definition does not parse")
