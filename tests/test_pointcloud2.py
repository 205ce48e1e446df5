"""numpy ↔ sensor_msgs/PointCloud2 (hsi_nodes.pointcloud2): layouts, byte orders, malformed clouds."""

from __future__ import annotations

import struct
import time
from typing import Any

import numpy as np
import pytest

from hsi_nodes import msgs
from hsi_nodes.pointcloud2 import PointCloud2, cloud_to_msg, msg_to_cloud
from hsi_planning.errors import CloudError

INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64 = range(1, 9)
_FMT = {INT8: "b", UINT8: "B", INT16: "h", UINT16: "H", INT32: "i", UINT32: "I", FLOAT32: "f", FLOAT64: "d"}


def _field(name: str, offset: int, datatype: int, count: int = 1) -> Any:
    return msgs.msg_class("sensor_msgs/msg/PointField")(
        name=name, offset=offset, datatype=datatype, count=count
    )


def _cloud(
    fields: list[Any],
    data: bytes,
    *,
    height: int,
    width: int,
    point_step: int,
    row_step: int,
    big: bool = False,
) -> PointCloud2:
    return PointCloud2(
        header=msgs.make_header(0.0, "cam"),
        height=height,
        width=width,
        fields=fields,
        is_bigendian=big,
        point_step=point_step,
        row_step=row_step,
        data=np.frombuffer(data, dtype=np.uint8),
        is_dense=False,
    )


def _pack_points(
    rows: list[list[tuple[float, ...]]],
    layout: list[tuple[str, int, int]],
    point_step: int,
    row_step: int,
    order: str = "<",
) -> bytes:
    """Bytes of an organized cloud, one struct.pack_into per field; padding filled with 0xAB garbage."""
    buf = bytearray(b"\xab" * (row_step * len(rows)))
    for r, row in enumerate(rows):
        for c, values in enumerate(row):
            for (_name, offset, dt), v in zip(layout, values, strict=True):
                struct.pack_into(order + _FMT[dt], buf, r * row_step + c * point_step + offset, v)
    return bytes(buf)


def test_round_trip_with_labels_and_header() -> None:
    rng = np.random.default_rng(0)
    pts = rng.uniform(-3.0, 3.0, size=(1000, 3))
    labels = rng.integers(-1, 20, size=1000)
    msg = cloud_to_msg(pts, labels, frame_id="camera_depth", stamp=12.5)
    assert (msg.height, msg.width, msg.point_step, msg.row_step) == (1, 1000, 16, 16000)
    assert [(f.name, f.offset, f.datatype, f.count) for f in msg.fields] == [
        ("x", 0, FLOAT32, 1),
        ("y", 4, FLOAT32, 1),
        ("z", 8, FLOAT32, 1),
        ("label", 12, INT32, 1),
    ]
    assert msg.header.frame_id == "camera_depth" and msg.header.stamp.sec == 12 and msg.is_dense
    back, back_labels, dropped = msg_to_cloud(msg)
    assert dropped == 0 and back.dtype == np.float64 and back.shape == (1000, 3)
    np.testing.assert_allclose(back, pts, atol=3.0 * 2.0**-23 * 2)  # float32 rounding
    assert back_labels is not None and back_labels.dtype == np.int32
    np.testing.assert_array_equal(back_labels, labels)
    # through the wire format too
    wire = msgs.deserialize(msgs.serialize(msg), "sensor_msgs/msg/PointCloud2")
    back2, labels2, _ = msg_to_cloud(wire)
    np.testing.assert_array_equal(back2, back)
    np.testing.assert_array_equal(labels2, labels)


def test_round_trip_without_labels_and_empty() -> None:
    pts = np.array([[1.0, 2.0, 3.0], [-1.0, 0.5, 0.25]])
    msg = cloud_to_msg(pts, None, "world", msgs.time_msg(1.0))
    assert msg.point_step == 12 and [f.name for f in msg.fields] == ["x", "y", "z"]
    back, labels, dropped = msg_to_cloud(msg)
    np.testing.assert_array_equal(back, pts)  # exactly representable in float32
    assert labels is None and dropped == 0
    empty = cloud_to_msg(np.zeros((0, 3)), np.zeros(0, dtype=int))
    back, labels, dropped = msg_to_cloud(empty)
    assert back.shape == (0, 3) and labels is not None and labels.shape == (0,) and dropped == 0


def test_cloud_to_msg_copies_input() -> None:
    pts = np.ones((4, 3))
    labels = np.arange(4)
    msg = cloud_to_msg(pts, labels)
    pts[:] = 7.0
    labels[:] = 9
    back, back_labels, _ = msg_to_cloud(msg)
    np.testing.assert_array_equal(back, np.ones((4, 3)))
    np.testing.assert_array_equal(back_labels, np.arange(4))


def test_nan_and_inf_points_dropped_and_counted() -> None:
    pts = np.arange(18, dtype=float).reshape(6, 3)
    pts[1, 0] = np.nan
    pts[3, 2] = np.inf
    pts[4, 1] = -np.inf
    msg = cloud_to_msg(pts, np.arange(6) * 10)
    assert not msg.is_dense
    back, labels, dropped = msg_to_cloud(msg)
    assert dropped == 3
    np.testing.assert_array_equal(back, pts[[0, 2, 5]])
    np.testing.assert_array_equal(labels, [0, 20, 50])


def test_big_endian_cloud_built_with_struct() -> None:
    layout = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("label", 12, UINT16)]
    rows = [[(1.5, -2.0, 0.25, 7), (3.0, 4.0, 5.0, 65535)]]
    data = _pack_points(rows, layout, point_step=14, row_step=28, order=">")
    assert data[:4] == struct.pack(">f", 1.5)
    fields = [_field(n, o, d) for n, o, d in layout]
    pts, labels, dropped = msg_to_cloud(
        _cloud(fields, data, height=1, width=2, point_step=14, row_step=28, big=True)
    )
    np.testing.assert_array_equal(pts, [[1.5, -2.0, 0.25], [3.0, 4.0, 5.0]])
    np.testing.assert_array_equal(labels, [7, 65535])
    assert dropped == 0


def test_padded_point_step_with_extra_fields_in_any_order() -> None:
    # PCL-style XYZRGB+intensity: x y z <pad> rgb intensity <pad to 32>
    layout = [
        ("z", 8, FLOAT32),
        ("x", 0, FLOAT32),
        ("y", 4, FLOAT32),
        ("rgb", 16, FLOAT32),
        ("intensity", 20, FLOAT32),
    ]
    rows = [[(3.0, 1.0, 2.0, 1e-38, 0.5), (6.0, 4.0, 5.0, 2e-38, 0.75), (9.0, 7.0, 8.0, 0.0, 1.0)]]
    data = _pack_points(rows, layout, point_step=32, row_step=96)
    fields = [_field(n, o, d) for n, o, d in layout]
    pts, labels, dropped = msg_to_cloud(_cloud(fields, data, height=1, width=3, point_step=32, row_step=96))
    np.testing.assert_array_equal(pts, [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    assert labels is None and dropped == 0


def test_organized_cloud_with_row_padding_and_float64() -> None:
    layout = [("x", 0, FLOAT64), ("y", 8, FLOAT64), ("z", 16, FLOAT64), ("label", 24, INT8)]
    height, width, point_step, row_step = 3, 4, 25, 4 * 25 + 7  # 7 garbage bytes after each row
    rows = [
        [(r + 0.1 * c, -r - 1e-12 * c, 1e300 if c == 3 else 0.5, r * 10 + c - 20) for c in range(width)]
        for r in range(height)
    ]
    data = _pack_points(rows, layout, point_step, row_step)
    fields = [_field(n, o, d) for n, o, d in layout]
    msg = _cloud(fields, data, height=height, width=width, point_step=point_step, row_step=row_step)
    pts, labels, dropped = msg_to_cloud(msg)
    expected = np.array([v[:3] for row in rows for v in row])
    np.testing.assert_array_equal(pts, expected)  # row-major, float64 exact
    np.testing.assert_array_equal(labels, [v[3] for row in rows for v in row])
    assert dropped == 0


@pytest.mark.parametrize("datatype", [INT8, UINT8, INT16, UINT16, INT32, UINT32, FLOAT32, FLOAT64])
@pytest.mark.parametrize("big", [False, True])
def test_every_datatype_for_coordinates_and_label(datatype: int, big: bool) -> None:
    size = struct.calcsize(_FMT[datatype])
    layout = [
        ("x", 0, datatype),
        ("y", size, datatype),
        ("z", 2 * size, datatype),
        ("label", 3 * size, datatype),
    ]
    values = [(1, 2, 3, 4), (5, 6, 7, 100), (0, 1, 0, 127)]
    step = 4 * size
    data = _pack_points([values], layout, step, step * 3, order=">" if big else "<")
    msg = _cloud(
        [_field(*f) for f in layout], data, height=1, width=3, point_step=step, row_step=3 * step, big=big
    )
    pts, labels, _ = msg_to_cloud(msg)
    np.testing.assert_array_equal(pts, [v[:3] for v in values])
    np.testing.assert_array_equal(labels, [v[3] for v in values])


def _good() -> dict[str, Any]:
    layout = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32)]
    return {
        "fields": [_field(*f) for f in layout],
        "data": _pack_points([[(1.0, 2.0, 3.0), (4.0, 5.0, 6.0)]], layout, 12, 24),
        "height": 1,
        "width": 2,
        "point_step": 12,
        "row_step": 24,
    }


@pytest.mark.parametrize(
    ("change", "match"),
    [
        ({"fields": [_field("x", 0, FLOAT32), _field("y", 4, FLOAT32)]}, r"lacks field\(s\) \['z'\]"),
        ({"data": b"\x00" * 23}, r"data has 23 bytes but row_step 24 x height 1 = 24"),
        ({"data": b"\x00" * 25}, r"data has 25 bytes"),
        (
            {"point_step": 10, "row_step": 20, "data": b"\x00" * 20},
            r"point_step 10 is too small for field 'z'",
        ),
        ({"row_step": 20, "data": b"\x00" * 20}, r"row_step 20 < width 2 x point_step 12"),
        ({"fields": [*_good()["fields"], _field("rgb", 8, 9)]}, r"field 'rgb' has unknown datatype 9"),
        (
            {"fields": [_field("x", 0, FLOAT32, 2), _field("y", 4, FLOAT32), _field("z", 8, FLOAT32)]},
            r"'x' has count 2",
        ),
        ({"fields": [*_good()["fields"], _field("x", 0, FLOAT32)]}, r"'x' appears twice"),
        ({"fields": [*_good()["fields"], _field("normal", 4, FLOAT32, 3)]}, r"too small for field 'normal'"),
    ],
)
def test_malformed_clouds_rejected(change: dict[str, Any], match: str) -> None:
    spec = _good() | change
    with pytest.raises(CloudError, match=match):
        msg_to_cloud(_cloud(**spec))


def test_label_values_must_fit_int32() -> None:
    layout = [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("label", 12, UINT32)]
    data = _pack_points([[(0.0, 0.0, 0.0, 2**32 - 1)]], layout, 16, 16)
    with pytest.raises(CloudError, match="outside the int32 range"):
        msg_to_cloud(
            _cloud([_field(*f) for f in layout], data, height=1, width=1, point_step=16, row_step=16)
        )
    layout[3] = ("label", 12, FLOAT32)
    data = _pack_points([[(0.0, 0.0, 0.0, 1.5)]], layout, 16, 16)
    with pytest.raises(CloudError, match="non-integer"):
        msg_to_cloud(
            _cloud([_field(*f) for f in layout], data, height=1, width=1, point_step=16, row_step=16)
        )


@pytest.mark.parametrize(
    ("points", "labels", "match"),
    [
        (np.zeros((4, 2)), None, r"shape \(N, 3\)"),
        (np.zeros(3), None, r"shape \(N, 3\)"),
        (np.zeros((4, 3)), np.zeros(3, dtype=int), r"labels must have shape \(4,\)"),
        (np.zeros((2, 3)), np.array([0.5, 1.0]), "labels must be integers"),
        (np.zeros((1, 3)), np.array([2**40]), "fit in int32"),
    ],
)
def test_cloud_to_msg_rejects_bad_input(points: Any, labels: Any, match: str) -> None:
    with pytest.raises(CloudError, match=match):
        cloud_to_msg(points, labels)


def test_100k_points_fast() -> None:
    rng = np.random.default_rng(3)
    pts = rng.normal(size=(100_000, 3))
    labels = rng.integers(0, 50, size=100_000)
    t0 = time.perf_counter()
    msg = cloud_to_msg(pts, labels)
    back, back_labels, _ = msg_to_cloud(msg)
    elapsed = time.perf_counter() - t0
    np.testing.assert_array_equal(back_labels, labels)
    np.testing.assert_allclose(back, pts, rtol=1e-6, atol=1e-6)
    assert elapsed < 0.5, f"100k-point round trip took {elapsed:.3f} s"
