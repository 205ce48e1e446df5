"""numpy ↔ ``sensor_msgs/PointCloud2`` conversion (vectorized with numpy structured dtypes).

Clouds written by :func:`cloud_to_msg` are unorganized (``height = 1``), little endian, with fields
``x, y, z`` (FLOAT32, offsets 0, 4, 8) and, when labels are given, ``label`` (**INT32**, offset 12): a
per-point segmentation id, ``>= 0`` for a segment and ``-1`` for "no segment" (the convention of
open3d's DBSCAN clustering). ``point_step`` is 12 without labels and 16 with them.

:func:`msg_to_cloud` reads any well-formed PointCloud2: it honours field offsets and datatypes (every
INT*/UINT*/FLOAT* type), ``point_step``, ``row_step`` (row padding), ``height × width`` organized clouds
and ``is_bigendian``; extra fields (``rgb``, ``intensity``, ...) are ignored; points with a NaN/inf
coordinate are dropped and counted.
"""

from __future__ import annotations

import logging
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__PointCloud2 as PointCloud2
from rosbags.typesys.stores.ros2_jazzy import sensor_msgs__msg__PointField as PointField
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from hsi_nodes.msgs import time_msg
from hsi_planning.errors import CloudError

__all__ = ["LABEL_FIELD", "POINTFIELD_DTYPES", "PointCloud2", "cloud_to_msg", "msg_to_cloud"]

_log = logging.getLogger(__name__)

#: Name of the per-point segmentation label field.
LABEL_FIELD = "label"

#: PointField datatype constant -> numpy scalar type (byte order is applied per message).
POINTFIELD_DTYPES: dict[int, type[np.generic]] = {
    1: np.int8,  # INT8
    2: np.uint8,  # UINT8
    3: np.int16,  # INT16
    4: np.uint16,  # UINT16
    5: np.int32,  # INT32
    6: np.uint32,  # UINT32
    7: np.float32,  # FLOAT32
    8: np.float64,  # FLOAT64
}
_FLOAT32 = 7
_INT32 = 5
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1


def cloud_to_msg(
    points: ArrayLike,
    labels: ArrayLike | None = None,
    frame_id: str = "world",
    stamp: float | Time = 0.0,
) -> PointCloud2:
    """Unorganized PointCloud2 of ``points`` (N, 3) [m] with optional ``labels`` (N,) (INT32 field).

    Args:
        points: (N, 3) [m] coordinates in ``frame_id``; non-finite points are kept (``is_dense`` False).
        labels: (N,) integer segment ids in the int32 range, or None for an x, y, z-only cloud.
        frame_id: frame of the points.
        stamp: header stamp, [s] or a ``builtin_interfaces/Time``.

    Raises:
        CloudError: wrong shapes, non-integer labels or labels outside the int32 range.
    """
    pts = np.asarray(points)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise CloudError(f"points must have shape (N, 3) [m], got {pts.shape}")
    n = pts.shape[0]
    names = ["x", "y", "z"]
    formats: list[type[np.generic]] = [np.float32, np.float32, np.float32]
    lab: NDArray[np.int32] | None = None
    if labels is not None:
        raw = np.asarray(labels)
        if raw.shape != (n,):
            raise CloudError(f"labels must have shape ({n},) to match points, got {raw.shape}")
        if n and raw.dtype.kind not in "iub" and not _integral_floats(raw):
            raise CloudError(f"labels must be integers, got dtype {raw.dtype}")
        if n and (raw.min() < _INT32_MIN or raw.max() > _INT32_MAX):
            raise CloudError(f"labels must fit in int32, got range [{raw.min()}, {raw.max()}]")
        lab = raw.astype(np.int32)
        names.append(LABEL_FIELD)
        formats.append(np.int32)
    dtype = np.dtype({"names": names, "formats": [np.dtype(f).newbyteorder("<") for f in formats]})
    rec = np.empty(n, dtype=dtype)
    pts32 = pts.astype(np.float32)
    rec["x"], rec["y"], rec["z"] = pts32[:, 0], pts32[:, 1], pts32[:, 2]
    if lab is not None:
        rec[LABEL_FIELD] = lab
    fields = [
        PointField(name=name, offset=_offset(dtype, name), datatype=_FLOAT32 if i < 3 else _INT32, count=1)
        for i, name in enumerate(names)
    ]
    header = Header(
        stamp=stamp if isinstance(stamp, Time) else time_msg(float(stamp)), frame_id=str(frame_id)
    )
    return PointCloud2(
        header=header,
        height=1,
        width=n,
        fields=fields,
        is_bigendian=False,
        point_step=dtype.itemsize,
        row_step=dtype.itemsize * n,
        data=rec.view(np.uint8).reshape(-1).copy(),
        is_dense=bool(np.all(np.isfinite(pts32))),
    )


def _offset(dtype: np.dtype, name: str) -> int:
    """Byte offset of field ``name`` in the structured ``dtype``."""
    fields = dtype.fields
    assert fields is not None
    return int(fields[name][1])


def _field_layout(msg: PointCloud2) -> dict[str, tuple[int, np.dtype]]:
    """Validated ``name -> (offset [bytes], dtype)`` of every field of ``msg``."""
    order: Literal["<", ">"] = ">" if msg.is_bigendian else "<"
    point_step = int(msg.point_step)
    layout: dict[str, tuple[int, np.dtype]] = {}
    for f in msg.fields:
        name = str(f.name)
        if int(f.datatype) not in POINTFIELD_DTYPES:
            valid = ", ".join(f"{k} ({np.dtype(v).name})" for k, v in POINTFIELD_DTYPES.items())
            raise CloudError(f"field {name!r} has unknown datatype {f.datatype}; valid: {valid}")
        if name in layout:
            raise CloudError(f"field {name!r} appears twice in the PointCloud2 fields")
        dt = np.dtype(POINTFIELD_DTYPES[int(f.datatype)]).newbyteorder(order)
        count, offset = int(f.count), int(f.offset)
        if name in ("x", "y", "z", LABEL_FIELD) and count != 1:
            raise CloudError(f"field {name!r} has count {count}; only count 1 is supported for it")
        if offset < 0 or offset + dt.itemsize * max(count, 1) > point_step:
            raise CloudError(
                f"point_step {point_step} is too small for field {name!r} "
                f"(offset {offset} + {max(count, 1)} x {dt.itemsize} bytes)"
            )
        layout[name] = (offset, dt)
    missing = [c for c in ("x", "y", "z") if c not in layout]
    if missing:
        have = [str(f.name) for f in msg.fields]
        raise CloudError(f"PointCloud2 lacks field(s) {missing}; it has {have} (x, y and z are required)")
    return layout


def msg_to_cloud(msg: PointCloud2) -> tuple[NDArray[np.float64], NDArray[np.int32] | None, int]:
    """Points of a PointCloud2, row-major for organized clouds.

    Returns:
        ``(points (M, 3) float64 [m], labels (M,) int32 or None when there is no 'label' field,
        dropped)``: ``dropped`` points had a NaN/inf coordinate and are not in ``points``/``labels``.

    Raises:
        CloudError: missing x/y/z, unknown datatype, unsupported count, fields beyond ``point_step``,
            ``row_step < width * point_step`` or ``len(data) != row_step * height``.
    """
    height, width = int(msg.height), int(msg.width)
    point_step, row_step = int(msg.point_step), int(msg.row_step)
    if height < 0 or width < 0 or point_step < 0 or row_step < 0:
        raise CloudError(
            f"negative cloud size: height {height}, width {width}, steps {point_step}/{row_step}"
        )
    layout = _field_layout(msg)
    if row_step < width * point_step:
        raise CloudError(f"row_step {row_step} < width {width} x point_step {point_step}; rows would overlap")
    data = np.asarray(msg.data, dtype=np.uint8).reshape(-1)
    if data.size != row_step * height:
        raise CloudError(
            f"data has {data.size} bytes but row_step {row_step} x height {height} = {row_step * height}"
        )
    has_label = LABEL_FIELD in layout
    if height * width == 0:
        empty_labels = np.zeros(0, dtype=np.int32) if has_label else None
        return np.zeros((0, 3), dtype=np.float64), empty_labels, 0
    used = ["x", "y", "z", *([LABEL_FIELD] if has_label else [])]
    dtype = np.dtype(
        {
            "names": used,
            "formats": [layout[k][1] for k in used],
            "offsets": [layout[k][0] for k in used],
            "itemsize": point_step,
        }
    )
    rec = np.ndarray(shape=(height, width), dtype=dtype, buffer=data, strides=(row_step, point_step))
    pts = np.empty((height * width, 3), dtype=np.float64)
    for i, axis in enumerate(("x", "y", "z")):
        pts[:, i] = rec[axis].reshape(-1)
    finite = np.all(np.isfinite(pts), axis=1)
    dropped = int(finite.size - np.count_nonzero(finite))
    labels: NDArray[np.int32] | None = None
    if has_label:
        labels = _labels_to_int32(rec[LABEL_FIELD].reshape(-1))[finite]
    if dropped:
        _log.debug("dropped %d of %d points with non-finite coordinates", dropped, finite.size)
        pts = pts[finite]
    return pts, labels, dropped


def _integral_floats(raw: NDArray[Any]) -> bool:
    """True when ``raw`` is a float array of finite whole numbers."""
    return raw.dtype.kind == "f" and bool(np.all(np.isfinite(raw))) and bool(np.all(raw == np.round(raw)))


def _labels_to_int32(raw: NDArray[Any]) -> NDArray[np.int32]:
    """int32 copy of a label column of any PointField datatype (CloudError if not representable)."""
    if raw.dtype.kind == "f" and not _integral_floats(raw):
        raise CloudError("float 'label' field holds non-integer or non-finite values")
    if raw.size and (raw.min() < _INT32_MIN or raw.max() > _INT32_MAX):
        raise CloudError(f"'label' values span [{raw.min()}, {raw.max()}], outside the int32 range")
    return raw.astype(np.int32)
