"""ROS 2 message types, CDR (de)serialization and small message builders.

Every message of the stack goes through this module: the standard ROS 2 types come from the
``rosbags`` type store of :data:`ROS_DISTRO` (Jazzy), and the stack's own ``msg/*.msg`` files are parsed
from their text and registered under the ROS 2 package ``hsi`` (type names ``hsi/msg/Keyframe``, ...).
Serialization is CDR, little endian, with the 4-byte encapsulation header, byte for byte what a ROS 2
node sends on the wire and what ``ros2 bag`` stores.

The ``.msg`` files are found by :func:`msg_dir` (the repo's ``msg/`` from a checkout, else package data).
The standard classes re-exported here (``Time``, ``Header``, ``Point``, ``Pose``, ``Quaternion``) come from
the Jazzy store module: change those imports together with :data:`STORE`.
"""

from __future__ import annotations

import difflib
import logging
import math
import os
import sys
from functools import cache, lru_cache
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore
from rosbags.typesys.stores.ros2_jazzy import builtin_interfaces__msg__Time as Time
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Point as Point
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Pose as Pose
from rosbags.typesys.stores.ros2_jazzy import geometry_msgs__msg__Quaternion as Quaternion
from rosbags.typesys.stores.ros2_jazzy import std_msgs__msg__Header as Header

from hsi_planning.errors import MessageError

if TYPE_CHECKING:
    from rosbags.typesys.store import Typestore

__all__ = [
    "HSI_PACKAGE",
    "ROS_DISTRO",
    "STORE",
    "Header",
    "Point",
    "Pose",
    "Quaternion",
    "Time",
    "deserialize",
    "hsi_typenames",
    "make_header",
    "make_pose",
    "message_definition",
    "message_fields",
    "messages_equal",
    "msg_class",
    "msg_dir",
    "normalize_typename",
    "ns_to_time",
    "pose_to_arrays",
    "serialize",
    "stamp_to_ns",
    "stamp_to_seconds",
    "time_msg",
    "type_hash",
    "typestore",
]

_log = logging.getLogger(__name__)

#: The rosbags type store of the standard ROS 2 messages (one distro for the whole stack).
STORE = Stores.ROS2_JAZZY
#: ROS 2 distribution name matching :data:`STORE` (written into bag metadata).
ROS_DISTRO = "jazzy"
#: ROS 2 package name of the stack's own messages (see package.xml).
HSI_PACKAGE = "hsi"

_MSG_DIR_ENV = "HSI_MSG_DIR"
_NS_PER_S = 1_000_000_000
_INT32_MAX = 2**31 - 1


def msg_dir() -> Path:
    """The folder holding the stack's ``.msg`` files.

    Looked up in order: ``$HSI_MSG_DIR``; ``<repo>/msg`` (source checkout or editable install);
    ``hsi_nodes/msg`` (package data of a wheel); ``<sys.prefix>/share/hsi/msg`` (setuptools data-files or
    an ament install).

    Raises:
        MessageError: none of them holds ``.msg`` files.
    """
    here = Path(__file__).resolve().parent
    candidates = [here.parents[1] / "msg", here / "msg", Path(sys.prefix) / "share" / HSI_PACKAGE / "msg"]
    if env := os.environ.get(_MSG_DIR_ENV):
        candidates.insert(0, Path(env))
    for cand in candidates:
        if cand.is_dir() and any(cand.glob("*.msg")):
            return cand
    tried = ", ".join(str(c) for c in candidates)
    raise MessageError(f"no .msg files of package {HSI_PACKAGE!r} found; looked in: {tried}")


@lru_cache(maxsize=1)
def typestore() -> Typestore:
    """The shared type store: ROS 2 Jazzy standard types plus every ``hsi/msg/*`` type (cached)."""
    store = get_typestore(STORE)
    folder = msg_dir()
    types: dict[str, Any] = {}
    for path in sorted(folder.glob("*.msg")):
        name = f"{HSI_PACKAGE}/msg/{path.stem}"
        try:
            types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
        except (TypesysError, ValueError) as exc:  # parser errors
            raise MessageError(f"cannot parse {path} as ROS 2 message {name}: {exc}") from exc
    try:
        store.register(types)
    except TypesysError as exc:
        raise MessageError(f"cannot register the {HSI_PACKAGE} messages from {folder}: {exc}") from exc
    _log.debug("registered %d %s message types from %s", len(types), HSI_PACKAGE, folder)
    return store


def hsi_typenames() -> tuple[str, ...]:
    """Names of the stack's own message types, e.g. ``('hsi/msg/Keyframe', ...)``, sorted."""
    prefix = f"{HSI_PACKAGE}/msg/"
    return tuple(sorted(t for t in typestore().types if t.startswith(prefix)))


def normalize_typename(typename: str) -> str:
    """Canonical ``pkg/msg/Type`` name; also accepts ``pkg/Type`` and ``pkg::msg::Type``.

    Raises:
        MessageError: the name has no package part.
    """
    name = typename.strip().replace("::", "/")
    parts = [p for p in name.split("/") if p]
    if len(parts) == 2:
        parts = [parts[0], "msg", parts[1]]
    if len(parts) != 3:
        raise MessageError(
            f"invalid message type name {typename!r}; "
            "expected 'pkg/msg/Type' (e.g. 'sensor_msgs/msg/JointState')"
        )
    return "/".join(parts)


def msg_class(typename: str) -> type[Any]:
    """The message class of ``typename`` (e.g. ``'sensor_msgs/msg/PointCloud2'``, ``'hsi/msg/Keyframe'``).

    Raises:
        MessageError: unknown type; the message lists the closest known names.
    """
    name = normalize_typename(typename)
    types = typestore().types
    cls = types.get(name)
    if cls is None:
        close = difflib.get_close_matches(name, list(types), n=5, cutoff=0.6)
        hint = f"; did you mean: {', '.join(close)}" if close else ""
        raise MessageError(
            f"unknown message type {typename!r} in the {ROS_DISTRO} + {HSI_PACKAGE} type store{hint}"
        )
    return cls


def _typename_of(msg: object, typename: str | None) -> str:
    if typename is not None:
        name = normalize_typename(typename)
        msg_class(name)
        actual = getattr(msg, "__msgtype__", None)
        if actual is not None and actual != name:
            raise MessageError(f"message is a {actual}, not the requested {name}")
        return name
    actual = getattr(msg, "__msgtype__", None)
    if not isinstance(actual, str):
        raise MessageError(f"{type(msg).__name__} is not a ROS message; pass a message built by msg_class()")
    return actual


def serialize(msg: object, typename: str | None = None) -> bytes:
    """CDR bytes (little endian, with the 4-byte encapsulation header) of ``msg``.

    ``typename`` defaults to the message's own type; when given it must match.

    Raises:
        MessageError: not a message, type mismatch, or a field of the wrong type/size.
    """
    name = _typename_of(msg, typename)
    try:
        return bytes(typestore().serialize_cdr(msg, name))
    except Exception as exc:  # rosbags raises struct/attribute/serde errors for bad fields
        raise MessageError(f"cannot serialize {name}: {type(exc).__name__}: {exc}") from exc


def deserialize(data: bytes | bytearray | memoryview, typename: str) -> Any:
    """Decode CDR bytes (either endianness, with encapsulation header) into a ``typename`` message.

    Primitive array fields (e.g. ``PointCloud2.data``, ``JointState.position``) are **read-only** numpy
    views of a private copy of ``data``: replace them instead of writing into them.

    Raises:
        MessageError: unknown type, or the bytes are truncated/not a ``typename``.
    """
    name = normalize_typename(typename)
    msg_class(name)
    raw = bytes(data)
    if len(raw) < 4 or raw[0] != 0 or raw[1] not in (0, 1):
        raise MessageError(
            f"cannot deserialize {name}: {len(raw)} bytes without a CDR encapsulation header "
            "(expected 00 00 or 00 01 followed by 2 option bytes)"
        )
    try:
        return typestore().deserialize_cdr(raw, name)
    except Exception as exc:  # rosbags raises struct/index/assertion errors on malformed data
        raise MessageError(
            f"cannot deserialize {len(raw)} bytes as {name}: {type(exc).__name__}: {exc}"
        ) from exc


def message_definition(typename: str) -> str:
    """The ``ros2msg`` definition text of ``typename`` with all dependent definitions appended.

    Dependencies follow in the ``'=' * 80 + '\\nMSG: pkg/Type\\n'`` format that rosbag2, mcap-ros2-support
    and Foxglove use for MCAP schemas.
    """
    name = normalize_typename(typename)
    msg_class(name)
    text, _ = typestore().generate_msgdef(name, ros_version=2)
    return text


def type_hash(typename: str) -> str:
    """The ROS 2 type description hash (``'RIHS01_<sha256 hex>'``) of ``typename``."""
    name = normalize_typename(typename)
    msg_class(name)
    return str(typestore().hash_rihs01(name))


@cache
def message_fields(typename: str) -> tuple[str, ...]:
    """Attribute names of the data fields of ``typename``, in wire order (constants excluded)."""
    name = normalize_typename(typename)
    msg_class(name)
    return tuple(field for field, _ in typestore().get_msgdef(name).fields)


def messages_equal(a: object, b: object) -> bool:
    """Deep equality of two messages (numpy array fields compared element-wise, NaN == NaN)."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        x, y = np.asarray(a), np.asarray(b)
        if x.shape != y.shape:
            return False
        if x.dtype.kind in "fc" or y.dtype.kind in "fc":
            return bool(np.array_equal(x, y, equal_nan=True))
        return bool(np.array_equal(x, y))
    typename = getattr(a, "__msgtype__", None)
    if isinstance(typename, str):
        if type(a) is not type(b):
            return False
        return all(messages_equal(getattr(a, f), getattr(b, f)) for f in message_fields(typename))
    if isinstance(a, list | tuple) and isinstance(b, list | tuple):
        return len(a) == len(b) and all(messages_equal(x, y) for x, y in zip(a, b, strict=True))
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b):
        return True
    return bool(a == b)


# ----------------------------------------------------------------------------------------- builders


def ns_to_time(t_ns: int) -> Time:
    """``builtin_interfaces/Time`` of an integer time ``t_ns`` [ns] (exact; ``nanosec`` in [0, 1e9)).

    Raises:
        MessageError: the seconds do not fit the int32 ``sec`` field.
    """
    sec, nanosec = divmod(int(t_ns), _NS_PER_S)
    if not -(2**31) <= sec <= _INT32_MAX:
        raise MessageError(f"time {t_ns} ns is outside the int32 seconds range of builtin_interfaces/Time")
    return Time(sec=sec, nanosec=nanosec)


def time_msg(seconds: float) -> Time:
    """``builtin_interfaces/Time`` of ``seconds`` [s], rounded to the nearest nanosecond.

    Raises:
        MessageError: ``seconds`` is not finite or out of the int32 range.
    """
    if not math.isfinite(seconds):
        raise MessageError(f"time must be a finite number of seconds, got {seconds!r}")
    return ns_to_time(round(seconds * _NS_PER_S))


def stamp_to_ns(stamp: Time) -> int:
    """Integer nanoseconds [ns] of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) * _NS_PER_S + int(stamp.nanosec)


def stamp_to_seconds(stamp: Time) -> float:
    """Seconds [s] of a ``builtin_interfaces/Time``."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def make_header(stamp_s: float, frame_id: str) -> Header:
    """``std_msgs/Header`` with stamp ``stamp_s`` [s] and ``frame_id``."""
    return Header(stamp=time_msg(stamp_s), frame_id=str(frame_id))


def make_pose(position: ArrayLike, quat_xyzw: ArrayLike = (0.0, 0.0, 0.0, 1.0)) -> Pose:
    """``geometry_msgs/Pose`` from ``position`` (3,) [m] and a quaternion ``quat_xyzw`` (4,) (x, y, z, w).

    The quaternion is normalized.

    Raises:
        MessageError: wrong shapes, non-finite values or a zero quaternion.
    """
    p = np.asarray(position, dtype=np.float64)
    q = np.asarray(quat_xyzw, dtype=np.float64)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise MessageError(f"position must be 3 finite numbers [m], got shape {p.shape}: {p!r}")
    norm = float(np.linalg.norm(q)) if q.shape == (4,) else 0.0
    if q.shape != (4,) or not np.all(np.isfinite(q)) or norm < 1e-12:
        raise MessageError(f"quat_xyzw must be 4 finite numbers (x, y, z, w) of non-zero norm, got {q!r}")
    q = q / norm
    return Pose(
        position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
        orientation=Quaternion(x=float(q[0]), y=float(q[1]), z=float(q[2]), w=float(q[3])),
    )


def pose_to_arrays(pose: Pose) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """``(position (3,) [m], quat_xyzw (4,))`` of a ``geometry_msgs/Pose`` (new arrays)."""
    pos = np.array([pose.position.x, pose.position.y, pose.position.z], dtype=np.float64)
    o = pose.orientation
    quat = np.array([o.x, o.y, o.z, o.w], dtype=np.float64)
    return pos, quat
