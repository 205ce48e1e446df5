"""Message types, CDR round trips, known wire bytes and builders (hsi_nodes.msgs)."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from hsi_nodes import msgs
from hsi_nodes.pointcloud2 import cloud_to_msg
from hsi_planning.errors import MessageError

HSI_TYPES = ("Keyframe", "PickPlaceGoal", "Schedule", "TaskReport", "WristTrajectory")


def _c(typename: str) -> type[Any]:
    return msgs.msg_class(typename)


def _header(t: float = 12.25, frame: str = "world") -> Any:
    return msgs.make_header(t, frame)


def _transform_stamped(child: str, x: float) -> Any:
    return _c("geometry_msgs/msg/TransformStamped")(
        header=_header(3.5, "world"),
        child_frame_id=child,
        transform=_c("geometry_msgs/msg/Transform")(
            translation=_c("geometry_msgs/msg/Vector3")(x=x, y=-0.25, z=1.0),
            rotation=msgs.Quaternion(x=0.0, y=0.0, z=0.6, w=0.8),
        ),
    )


def _keyframe(t: float, joint: str) -> Any:
    return _c("hsi/msg/Keyframe")(
        time=t,
        key_joint=joint,
        pose=msgs.make_pose([0.4, -0.2, 0.9], [0.0, 0.0, 0.0, 1.0]),
        action="grasp",
        contact_event="grasp",
        hand="left",
        object_name="mug_1",
    )


def _marker(i: int) -> Any:
    c = _c
    return c("visualization_msgs/msg/Marker")(
        header=_header(1.0, "world"),
        ns="objects",
        id=i,
        type=7,  # SPHERE_LIST
        action=0,
        pose=msgs.make_pose([0.0, 0.0, 0.1 * i]),
        scale=c("geometry_msgs/msg/Vector3")(x=0.01, y=0.01, z=0.01),
        color=c("std_msgs/msg/ColorRGBA")(r=1.0, g=0.5, b=0.25, a=1.0),
        lifetime=c("builtin_interfaces/msg/Duration")(sec=1, nanosec=5),
        frame_locked=True,
        points=[msgs.Point(x=float(k), y=0.5, z=-1.0) for k in range(3)],
        colors=[c("std_msgs/msg/ColorRGBA")(r=0.0, g=1.0, b=0.0, a=0.5)] * 3,
        texture_resource="",
        texture=c("sensor_msgs/msg/CompressedImage")(header=_header(), format="", data=np.zeros(0, np.uint8)),
        uv_coordinates=[],
        text=f"marker {i}",
        mesh_resource="",
        mesh_file=c("visualization_msgs/msg/MeshFile")(filename="", data=np.zeros(0, np.uint8)),
        mesh_use_embedded_materials=False,
    )


def sample_messages() -> dict[str, Any]:
    """One non-trivial message of every type the stack uses (also used by test_bag.py)."""
    c = _c
    rng = np.random.default_rng(7)
    pts = rng.uniform(-1.0, 1.0, size=(50, 3))
    poses = [msgs.make_pose(rng.normal(size=3), rng.normal(size=4)) for _ in range(4)]
    joint_names = ["shoulder", "elbow", "wrist"]
    return {
        "sensor_msgs/msg/PointCloud2": cloud_to_msg(pts, rng.integers(-1, 5, size=50), "camera", 2.5),
        "sensor_msgs/msg/JointState": c("sensor_msgs/msg/JointState")(
            header=_header(),
            name=joint_names,
            position=np.array([0.1, -0.2, 0.3]),
            velocity=np.array([1.0, 2.0, 3.0]),
            effort=np.zeros(0),
        ),
        "geometry_msgs/msg/PointStamped": c("geometry_msgs/msg/PointStamped")(
            header=_header(), point=msgs.Point(x=0.5, y=-0.5, z=0.75)
        ),
        "geometry_msgs/msg/PoseStamped": c("geometry_msgs/msg/PoseStamped")(header=_header(), pose=poses[0]),
        "geometry_msgs/msg/PoseArray": c("geometry_msgs/msg/PoseArray")(header=_header(), poses=poses),
        "geometry_msgs/msg/TransformStamped": _transform_stamped("left_hand", 0.5),
        "tf2_msgs/msg/TFMessage": c("tf2_msgs/msg/TFMessage")(
            transforms=[_transform_stamped("a", 1.0), _transform_stamped("b", 2.0)]
        ),
        "trajectory_msgs/msg/JointTrajectory": c("trajectory_msgs/msg/JointTrajectory")(
            header=_header(),
            joint_names=joint_names,
            points=[
                c("trajectory_msgs/msg/JointTrajectoryPoint")(
                    positions=rng.normal(size=3),
                    velocities=rng.normal(size=3),
                    accelerations=np.zeros(0),
                    effort=np.zeros(0),
                    time_from_start=c("builtin_interfaces/msg/Duration")(sec=k, nanosec=250_000_000),
                )
                for k in range(3)
            ],
        ),
        "visualization_msgs/msg/MarkerArray": c("visualization_msgs/msg/MarkerArray")(
            markers=[_marker(0), _marker(1)]
        ),
        "nav_msgs/msg/Path": c("nav_msgs/msg/Path")(
            header=_header(),
            poses=[
                c("geometry_msgs/msg/PoseStamped")(header=_header(0.1 * k), pose=p)
                for k, p in enumerate(poses)
            ],
        ),
        "std_msgs/msg/String": c("std_msgs/msg/String")(data="héllo wörld"),
        "hsi/msg/PickPlaceGoal": c("hsi/msg/PickPlaceGoal")(
            header=_header(),
            task_id="task-7",
            object_name="",
            pick_point=msgs.Point(x=0.4, y=0.1, z=0.8),
            has_place=True,
            place_pose=poses[1],
            hand="both",
            planner="implicit",
        ),
        "hsi/msg/Keyframe": _keyframe(1.5, "left_wrist"),
        "hsi/msg/Schedule": c("hsi/msg/Schedule")(
            header=_header(),
            task_id="task-7",
            keyframes=[_keyframe(0.0, "root"), _keyframe(1.0, "hip"), _keyframe(2.0, "right_wrist")],
            steps=["navigate to table", "grasp mug_1 with left hand"],
        ),
        "hsi/msg/WristTrajectory": c("hsi/msg/WristTrajectory")(
            header=_header(),
            task_id="task-7",
            hand="right",
            action="grasp",
            segment="approach",
            planner="minjerk",
            object_name="mug_1",
            time_from_start=np.linspace(0.0, 1.5, 4),
            poses=poses,
            contact_index=3,
        ),
        "hsi/msg/TaskReport": c("hsi/msg/TaskReport")(
            header=_header(),
            task_id="task-7",
            stage="sim",
            success=False,
            message="object slipped",
            object_name="mug_1",
            robot="dual_ur5e",
            planner="implicit",
            placement_error_m=float("nan"),
            duration_s=4.25,
            collisions=2,
            max_tracking_error_m=0.0125,
            details_json='{"retries": 1}',
        ),
    }


def test_msg_dir_lookup(repo_root: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv("HSI_MSG_DIR", raising=False)
    assert msgs.msg_dir() == repo_root / "msg"
    monkeypatch.setenv("HSI_MSG_DIR", str(tmp_path))  # empty folder: skipped, falls back to the repo
    assert msgs.msg_dir() == repo_root / "msg"
    (tmp_path / "Keyframe.msg").write_text((repo_root / "msg" / "Keyframe.msg").read_text())
    assert msgs.msg_dir() == tmp_path


def test_hsi_types_registered_from_msg_files() -> None:
    assert msgs.hsi_typenames() == tuple(f"hsi/msg/{t}" for t in HSI_TYPES)
    goal_fields = [f[0] for f in msgs.typestore().fielddefs["hsi/msg/PickPlaceGoal"][1]]
    assert goal_fields == [
        "header",
        "task_id",
        "object_name",
        "pick_point",
        "has_place",
        "place_pose",
        "hand",
        "planner",
    ]
    assert msgs.typestore() is msgs.typestore()  # cached


@pytest.mark.parametrize("typename", sorted(sample_messages()))
def test_round_trip_every_type(typename: str) -> None:
    msg = sample_messages()[typename]
    data = msgs.serialize(msg, typename)
    assert data[:4] == b"\x00\x01\x00\x00"  # CDR little-endian encapsulation
    back = msgs.deserialize(data, typename)
    assert type(back) is type(msg)
    assert msgs.messages_equal(back, msg)
    assert msgs.serialize(back) == data  # typename inferred; deterministic bytes


def test_messages_equal_detects_differences() -> None:
    a = sample_messages()["hsi/msg/WristTrajectory"]
    b = msgs.deserialize(msgs.serialize(a), "hsi/msg/WristTrajectory")
    assert not b.time_from_start.flags.writeable  # decoded arrays are read-only views of the bytes
    b.time_from_start = b.time_from_start + np.array([0.0, 0.0, 1e-9, 0.0])
    assert not msgs.messages_equal(a, b)
    c = msgs.deserialize(msgs.serialize(a), "hsi/msg/WristTrajectory")
    c.poses[1].orientation.w = 0.5
    assert not msgs.messages_equal(a, c)


def test_known_bytes_std_string() -> None:
    data = msgs.serialize(_c("std_msgs/msg/String")(data="hi"))
    # encapsulation CDR_LE, uint32 length incl. NUL = 3, 'h' 'i' NUL
    assert data == bytes.fromhex("00010000" + "03000000" + "686900")
    # a sender that pads the payload to 4 bytes (Fast DDS) decodes the same
    assert msgs.deserialize(data + b"\x00", "std_msgs/msg/String").data == "hi"


def test_known_bytes_point_stamped_alignment() -> None:
    msg = _c("geometry_msgs/msg/PointStamped")(
        header=_header(1.5, "w"), point=msgs.Point(x=1.0, y=2.0, z=3.0)
    )
    expected = (
        b"\x00\x01\x00\x00"
        + struct.pack("<iI", 1, 500_000_000)
        + struct.pack("<I", 2)
        + b"w\x00"
        + b"\x00\x00"  # pad to 8-byte alignment (relative to the payload start) for float64
        + struct.pack("<3d", 1.0, 2.0, 3.0)
    )
    assert msgs.serialize(msg) == expected


def test_big_endian_cdr_is_decoded() -> None:
    data = b"\x00\x00\x00\x00" + struct.pack(">3d", 1.0, -2.0, 0.5)  # CDR_BE
    p = msgs.deserialize(data, "geometry_msgs/msg/Point")
    assert (p.x, p.y, p.z) == (1.0, -2.0, 0.5)


def test_type_hash_matches_ros2() -> None:
    # the value `ros2 interface` (Jazzy) reports for std_msgs/msg/String
    assert (
        msgs.type_hash("std_msgs/msg/String")
        == "RIHS01_df668c740482bbd48fb39d76a70dfd4bd59db1288021743503259e948f6b1a18"
    )
    h = msgs.type_hash("hsi/msg/Schedule")
    assert h.startswith("RIHS01_") and len(h) == 7 + 64
    assert h != msgs.type_hash("hsi/msg/Keyframe")


@pytest.mark.parametrize("name", HSI_TYPES)
def test_message_definition_reparses_to_same_fields(name: str) -> None:
    typename = f"hsi/msg/{name}"
    text = msgs.message_definition(typename)
    sep = "=" * 80 + "\nMSG: "
    assert "MSG: std_msgs/Header" in text or name == "Keyframe"
    assert "MSG: geometry_msgs/Pose\n" in text or name in ("TaskReport",)
    # parse the main and every dependent definition into a fresh store: same field layout
    store = get_typestore(Stores.EMPTY)
    main, *deps = text.split(sep)
    types = get_types_from_msg(main, typename)
    for dep in deps:
        dep_name, body = dep.split("\n", 1)
        pkg, typ = dep_name.strip().split("/")
        types.update(get_types_from_msg(body, f"{pkg}/msg/{typ}"))
    store.register(types)
    assert store.fielddefs[typename] == msgs.typestore().fielddefs[typename]


def test_unknown_type_lists_close_matches() -> None:
    with pytest.raises(MessageError, match=r"hsi/msg/Keyframe"):
        msgs.msg_class("hsi/msg/Keyframes")
    with pytest.raises(MessageError, match="expected 'pkg/msg/Type'"):
        msgs.msg_class("Keyframe")
    assert msgs.msg_class("hsi/Keyframe") is msgs.msg_class("hsi::msg::Keyframe")


@pytest.mark.parametrize(
    ("make", "match"),
    [
        (lambda: msgs.serialize(object()), "not a ROS message"),
        (lambda: msgs.serialize(_c("std_msgs/msg/String")(data="x"), "geometry_msgs/msg/Point"), "not the"),
        (lambda: msgs.serialize(_c("std_msgs/msg/String")(data=3)), "cannot serialize"),  # type: ignore[arg-type]
        (lambda: msgs.deserialize(b"\x00\x01", "std_msgs/msg/String"), "encapsulation"),
        (lambda: msgs.deserialize(b"\x07\x07\x00\x00abcd", "std_msgs/msg/String"), "encapsulation"),
        (lambda: msgs.deserialize(b"\x00\x01\x00\x00\xff\x00\x00\x00ab", "std_msgs/msg/String"), "cannot"),
        (lambda: msgs.deserialize(b"\x00\x01\x00\x00\x00", "geometry_msgs/msg/Point"), "cannot deserialize"),
        (lambda: msgs.deserialize(b"\x00\x01\x00\x00", "nope/msg/Nothing"), "unknown message type"),
    ],
)
def test_bad_serialization_raises(make: Callable[[], object], match: str) -> None:
    with pytest.raises(MessageError, match=match):
        make()


def test_time_builders_exact() -> None:
    t = msgs.time_msg(1.5)
    assert (t.sec, t.nanosec) == (1, 500_000_000)
    t = msgs.time_msg(-0.25)  # ROS convention: floor seconds, non-negative nanosec
    assert (t.sec, t.nanosec) == (-1, 750_000_000)
    assert msgs.stamp_to_seconds(t) == pytest.approx(-0.25, abs=1e-12)
    big = 1_700_000_000_123_456_789
    assert msgs.stamp_to_ns(msgs.ns_to_time(big)) == big
    assert abs(msgs.stamp_to_seconds(msgs.time_msg(1_700_000_000.123456)) - 1_700_000_000.123456) < 1e-6
    for bad in (float("nan"), float("inf"), 3e9):
        with pytest.raises(MessageError):
            msgs.time_msg(bad)
    h = msgs.make_header(2.000000001, "map")
    assert (h.stamp.sec, h.stamp.nanosec, h.frame_id) == (2, 1, "map")


def test_pose_builders() -> None:
    pose = msgs.make_pose([1.0, 2.0, 3.0], [0.0, 0.0, 2.0, 2.0])  # normalized on the way in
    pos, quat = msgs.pose_to_arrays(pose)
    np.testing.assert_allclose(pos, [1.0, 2.0, 3.0])
    np.testing.assert_allclose(quat, [0.0, 0.0, np.sqrt(0.5), np.sqrt(0.5)], atol=1e-15)
    pos[0] = 99.0  # returned arrays are copies
    assert pose.position.x == 1.0
    ident = msgs.pose_to_arrays(msgs.make_pose(np.zeros(3)))[1]
    np.testing.assert_array_equal(ident, [0.0, 0.0, 0.0, 1.0])
    for p, q in (([1.0, 2.0], [0, 0, 0, 1]), ([0, 0, np.nan], [0, 0, 0, 1]), ([0, 0, 0], [0, 0, 0, 0])):
        with pytest.raises(MessageError):
            msgs.make_pose(p, q)
