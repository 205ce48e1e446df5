"""Labelled point clouds: the container, label-preserving voxel downsampling, and PLY files.

A :class:`LabelledCloud` holds world-frame points with one integer label per point (``-1`` =
unlabelled), optionally the names and semantic classes of the labels (from the scene's label table).
PLY files store the properties ``x y z`` (float or double) and ``label`` (int); label names and classes
travel in ``comment`` lines, so a cloud round-trips through :func:`write_ply` / :func:`read_ply`.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import CloudError

#: Label of a point that belongs to no known body.
UNLABELLED = -1

_PLY_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1",
    "short": "i2", "int16": "i2", "ushort": "u2", "uint16": "u2",
    "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}  # fmt: skip
_PLY_FORMATS = {"ascii": "", "binary_little_endian": "<", "binary_big_endian": ">"}
_COMMENT = re.compile(r"^hsi_(label|class) (-?\d+) (.*)$")


def _copy_names(names: Mapping[int, str] | None, what: str) -> dict[int, str] | None:
    if names is None:
        return None
    out: dict[int, str] = {}
    for key, value in names.items():
        if not isinstance(key, (int, np.integer)) or not isinstance(value, str) or "\n" in value:
            raise CloudError(f"{what} must map int label ids to one-line strings; got {key!r}: {value!r}")
        out[int(key)] = value
    return out


@dataclass(frozen=True, eq=False)
class LabelledCloud:
    """Points with one integer label each, in the world frame.

    Attributes:
        points: (N, 3) float32 or float64 [m], world frame, finite. Stored as a read-only copy.
        labels: (N,) int32 label ids; ``-1`` = unlabelled. Stored as a read-only copy.
        label_names: label id -> body/label name (e.g. ``3: "mug1"``), or None.
        label_classes: label id -> semantic class (e.g. ``3: "mug"``), or None.
    """

    points: NDArray[np.floating]
    labels: NDArray[np.int32]
    label_names: dict[int, str] | None = field(default=None)
    label_classes: dict[int, str] | None = field(default=None)

    def __post_init__(self) -> None:
        points = np.asarray(self.points)
        if points.ndim != 2 or points.shape[1] != 3:
            raise CloudError(f"points must have shape (N, 3), got {points.shape}")
        if points.dtype not in (np.float32, np.float64):
            if not np.issubdtype(points.dtype, np.number) or np.iscomplexobj(points):
                raise CloudError(f"points must be real numbers (float32/float64), got dtype {points.dtype}")
            points = points.astype(np.float64)
        if not np.all(np.isfinite(points)):
            bad = int(np.count_nonzero(~np.all(np.isfinite(points), axis=1)))
            raise CloudError(f"points must be finite; {bad} of {len(points)} points contain NaN or inf")
        labels = np.asarray(self.labels)
        if labels.shape != (len(points),):
            raise CloudError(f"labels must have shape ({len(points)},) to match points, got {labels.shape}")
        if labels.size and not np.issubdtype(labels.dtype, np.integer):
            raise CloudError(f"labels must be integers, got dtype {labels.dtype}")
        info = np.iinfo(np.int32)
        if labels.size and (labels.min() < info.min or labels.max() > info.max):
            raise CloudError("labels must fit in int32")
        points = np.array(points, copy=True)
        labels = np.array(labels, dtype=np.int32, copy=True)
        points.setflags(write=False)
        labels.setflags(write=False)
        object.__setattr__(self, "points", points)
        object.__setattr__(self, "labels", labels)
        object.__setattr__(self, "label_names", _copy_names(self.label_names, "label_names"))
        object.__setattr__(self, "label_classes", _copy_names(self.label_classes, "label_classes"))

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def label_id(self, name: str) -> int:
        """The id of label ``name``; raises :class:`CloudError` listing the known names."""
        for key, value in (self.label_names or {}).items():
            if value == name:
                return key
        raise CloudError(f"label {name!r} unknown; known: {sorted((self.label_names or {}).values())}")

    def mask(self, label: int | str) -> NDArray[np.bool_]:
        """(N,) bool: points carrying ``label`` (an id or a name)."""
        ident = self.label_id(label) if isinstance(label, str) else int(label)
        return np.asarray(self.labels == ident)

    def select(self, mask: NDArray[np.bool_] | NDArray[np.integer]) -> LabelledCloud:
        """A new cloud of the points picked by a boolean mask (N,) or an index array."""
        return LabelledCloud(self.points[mask], self.labels[mask], self.label_names, self.label_classes)

    def present_labels(self) -> NDArray[np.int32]:
        """Sorted unique label ids present in the cloud (``-1`` included if present)."""
        return np.unique(self.labels).astype(np.int32)

    def without_labels(self) -> LabelledCloud:
        """The same points, every label ``-1`` (what a real, unsegmented sensor delivers)."""
        return LabelledCloud(self.points, np.full(len(self), UNLABELLED, np.int32))


def voxel_downsample(cloud: LabelledCloud, voxel_size: float) -> LabelledCloud:
    """One point per occupied voxel, keeping the majority label of the voxel.

    The output point is the centroid of the voxel's points that carry the majority label (not of all
    its points, so a voxel straddling two surfaces keeps a point on the winning surface). Ties go to
    the smaller label id. Output order: by voxel key (deterministic).

    Args:
        cloud: input cloud, N points.
        voxel_size: edge of the cubic voxels [m], > 0.
    """
    if not voxel_size > 0.0 or not np.isfinite(voxel_size):
        raise CloudError(f"voxel_size must be a positive number of metres, got {voxel_size!r}")
    if len(cloud) == 0:
        return cloud
    pts = cloud.points
    # Non-negative offsets, so truncation is floor.
    cells = ((pts - pts.min(axis=0)) * (1.0 / voxel_size)).astype(np.int64)
    dims = cells.max(axis=0) + 1
    labels = cloud.labels.astype(np.int64)
    lab_min = int(labels.min())
    n_lab = int(labels.max()) - lab_min + 1
    if float(dims[0]) * float(dims[1]) * float(dims[2]) * n_lab >= 2.0**62:
        raise CloudError(f"cloud too large for voxel_size {voxel_size} m (grid {dims.tolist()})")
    pair = ((cells[:, 2] * dims[1] + cells[:, 1]) * dims[0] + cells[:, 0]) * n_lab + (labels - lab_min)
    order = np.argsort(pair)
    pair_sorted = pair[order]
    new_run = np.empty(len(pair_sorted), bool)
    new_run[0] = True
    np.not_equal(pair_sorted[1:], pair_sorted[:-1], out=new_run[1:])
    starts = np.flatnonzero(new_run)
    counts = np.diff(np.append(starts, len(pair_sorted)))
    pair_voxel = pair_sorted[starts] // n_lab
    # Per voxel, the (voxel, label) run with the most points; ties -> smaller label (earlier run).
    best = np.lexsort((np.arange(len(starts)), -counts, pair_voxel))
    first = np.r_[True, pair_voxel[best][1:] != pair_voxel[best][:-1]]
    keep = best[first]
    run_id = np.cumsum(new_run) - 1
    sorted_pts = pts[order]
    sums = np.stack([np.bincount(run_id, sorted_pts[:, k], len(starts))[keep] for k in range(3)], axis=1)
    centroids = (sums / counts[keep, None]).astype(pts.dtype)
    new_labels = (pair_sorted[starts[keep]] % n_lab + lab_min).astype(np.int32)
    return LabelledCloud(centroids, new_labels, cloud.label_names, cloud.label_classes)


def write_ply(path: str | Path, cloud: LabelledCloud, fmt: Literal["binary", "ascii"] = "binary") -> Path:
    """Write ``cloud`` as a PLY file with vertex properties ``x y z`` and ``label`` (int32).

    Coordinates are written as ``float`` for float32 clouds and ``double`` for float64 clouds (exact
    round trip). ``fmt="binary"`` writes binary little-endian. Label names/classes go into comments.
    Returns the path written.
    """
    if fmt not in ("binary", "ascii"):
        raise CloudError(f"PLY format must be 'binary' or 'ascii', got {fmt!r}")
    path = Path(path)
    ctype, code = ("float", "f4") if cloud.points.dtype == np.float32 else ("double", "f8")
    lines = ["ply", f"format {'binary_little_endian' if fmt == 'binary' else 'ascii'} 1.0"]
    lines.append("comment hsi labelled cloud")
    lines += [f"comment hsi_label {k} {v}" for k, v in sorted((cloud.label_names or {}).items())]
    lines += [f"comment hsi_class {k} {v}" for k, v in sorted((cloud.label_classes or {}).items())]
    lines += [f"element vertex {len(cloud)}"]
    lines += [f"property {ctype} {axis}" for axis in "xyz"] + ["property int label", "end_header"]
    header = ("\n".join(lines) + "\n").encode("ascii")
    dtype = np.dtype([("x", "<" + code), ("y", "<" + code), ("z", "<" + code), ("label", "<i4")])
    rec = np.empty(len(cloud), dtype=dtype)
    for i, axis in enumerate("xyz"):
        rec[axis] = cloud.points[:, i]
    rec["label"] = cloud.labels
    with path.open("wb") as fh:
        fh.write(header)
        if fmt == "binary":
            fh.write(rec.tobytes())
        else:
            float_fmt = "%.9g" if code == "f4" else "%.17g"
            np.savetxt(fh, rec, fmt=[float_fmt] * 3 + ["%d"])
    return path


def _parse_header(path: Path, raw: bytes) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]], int]:
    """(format, [(element, count, [(property, numpy code)])], data offset) of a PLY file."""
    end = raw.find(b"end_header")
    if not raw.startswith(b"ply") or end < 0:
        raise CloudError(f"{path}: not a PLY file (needs 'ply' ... 'end_header')")
    newline = raw.find(b"\n", end)
    if newline < 0:
        raise CloudError(f"{path}: PLY header not terminated by a newline")
    text = raw[:end].decode("ascii", errors="replace").replace("\r", "")
    fmt = ""
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    for lineno, line in enumerate(text.split("\n")[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format" and len(words) >= 2 and words[1] in _PLY_FORMATS:
            fmt = words[1]
        elif words[0] == "element" and len(words) == 3 and words[2].isdigit():
            elements.append((words[1], int(words[2]), []))
        elif words[0] == "property" and elements and len(words) == 3 and words[1] in _PLY_TYPES:
            elements[-1][2].append((words[2], _PLY_TYPES[words[1]]))
        elif words[0] == "property" and elements and words[1] == "list":
            elements[-1][2].append((words[-1], "list"))
        else:
            raise CloudError(f"{path}:{lineno}: unsupported PLY header line {line!r}")
    if not fmt:
        raise CloudError(f"{path}: PLY format must be one of {sorted(_PLY_FORMATS)}")
    return fmt, elements, newline + 1


def read_ply(path: str | Path) -> LabelledCloud:
    """Read a PLY point cloud: ``x y z`` (any numeric type) and, if present, ``label`` (else -1).

    The vertex element must come first (or follow only elements without list properties). Label
    names and classes written by :func:`write_ply` are restored. Malformed or truncated files raise
    :class:`CloudError` naming the file.
    """
    path = Path(path)
    if not path.is_file():
        raise CloudError(f"{path}: no such PLY file")
    raw = path.read_bytes()
    fmt, elements, offset = _parse_header(path, raw)
    names: dict[int, str] = {}
    classes: dict[int, str] = {}
    for line in raw[:offset].decode("ascii", errors="replace").splitlines():
        match = _COMMENT.match(line[len("comment ") :]) if line.startswith("comment ") else None
        if match:
            (names if match.group(1) == "label" else classes)[int(match.group(2))] = match.group(3)
    order = _PLY_FORMATS[fmt]
    skip_rows = 0
    for name, count, props in elements:
        if any(code == "list" for _, code in props):
            raise CloudError(f"{path}: element {name!r} has list properties before/in the vertex data")
        if name == "vertex":
            break
        skip_rows += count if fmt == "ascii" else 0
        offset += 0 if fmt == "ascii" else count * sum(np.dtype(code).itemsize for _, code in props)
    else:
        raise CloudError(f"{path}: no 'vertex' element in the PLY header")
    prop_names = [p for p, _ in props]
    if not {"x", "y", "z"} <= set(prop_names):
        raise CloudError(f"{path}: vertex element needs properties x, y, z; has {prop_names}")
    dtype = np.dtype([(p, (order or "<") + code) for p, code in props])
    if fmt == "ascii":
        rows = raw[offset:].decode("ascii", errors="replace").splitlines()[skip_rows : skip_rows + count]
        try:
            table = np.loadtxt(rows, dtype=np.float64, ndmin=2) if count else np.empty((0, len(props)))
        except ValueError as exc:
            raise CloudError(f"{path}: malformed ASCII vertex data: {exc}") from exc
        if table.shape != (count, len(props)):
            raise CloudError(
                f"{path}: expected {count} vertex rows of {len(props)} values, got {table.shape}"
            )
        cols = {p: table[:, i] for i, p in enumerate(prop_names)}
    else:
        if len(raw) - offset < count * dtype.itemsize:
            raise CloudError(f"{path}: truncated: {count} vertices need {count * dtype.itemsize} bytes")
        rec = np.frombuffer(raw, dtype=dtype, count=count, offset=offset)
        cols = {p: rec[p] for p in prop_names}
    float_out = np.float32 if all(dict(props)[a] == "f4" for a in "xyz") else np.float64
    points: NDArray[np.floating] = np.stack([cols["x"], cols["y"], cols["z"]], axis=1).astype(float_out)
    labels = cols["label"].astype(np.int32) if "label" in cols else np.full(count, UNLABELLED, np.int32)
    return LabelledCloud(points, labels, names or None, classes or None)
