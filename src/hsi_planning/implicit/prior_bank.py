"""The motion-prior bank shipped in the planner checkpoint: per training sample, what prior matching needs.

Per sample k (one demonstration of one training problem): the matching feature
(:func:`hsi_planning.implicit.problem.local_feature`), the condition c (4,), the latent index, the grid
centre (world) and the demonstration resampled to ``T`` samples **in the grid-local frame** (position −
grid centre [m]; world-axis aligned, so quaternions are world-frame), plus the target's box centre and
approach axis in that frame. Stored in the checkpoint's ``meta["prior_bank"]`` as plain data (arrays as
base64 little-endian strings), so ``torch.load(weights_only=True)`` reads it; :meth:`PriorBank.from_meta`
decodes it.
"""

from __future__ import annotations

import base64
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy.spatial.transform import Rotation, Slerp

from hsi_planning.errors import PlanningError
from hsi_planning.implicit.model import COND_DIM
from hsi_planning.trajectory import ACTIONS, HANDS, SEGMENTS, WristTrajectory

_ARRAYS = (
    "features",
    "cond",
    "scene_id",
    "grid_centre",
    "target_centre",
    "approach_axis",
    "t",
    "position",
    "quaternion",
    "contact_index",
)


def encode_array(arr: ArrayLike) -> dict[str, Any]:
    """Plain dict {dtype, shape, data (base64 of the little-endian bytes)} of an array."""
    a = np.ascontiguousarray(arr)
    a = a.astype(a.dtype.newbyteorder("<"), copy=False)
    return {"dtype": a.dtype.str, "shape": list(a.shape), "data": base64.b64encode(a.tobytes()).decode()}


def decode_array(doc: Mapping[str, Any]) -> NDArray[Any]:
    """Inverse of :func:`encode_array` (a writable copy)."""
    try:
        raw = base64.b64decode(str(doc["data"]))
        return np.frombuffer(raw, dtype=np.dtype(str(doc["dtype"]))).reshape(doc["shape"]).copy()
    except (KeyError, ValueError, TypeError) as exc:
        raise PlanningError(f"not an encoded array ({exc})") from exc


def resample_demo(demo: WristTrajectory, samples: int) -> tuple[NDArray[np.float64], ...]:
    """(t (T,) [s], position (T, 3) [m], quaternion (T, 4)) of ``demo`` at ``samples`` uniform times.

    Positions are interpolated linearly, orientations by slerp; both end samples are kept exactly.
    """
    if samples < 2:
        raise PlanningError(f"samples={samples} must be ≥ 2")
    t = np.linspace(demo.t[0], demo.t[-1], samples)
    pos = np.stack([np.interp(t, demo.t, demo.position[:, c]) for c in range(3)], axis=1)
    quat = Slerp(demo.t, Rotation.from_quat(demo.quaternion))(t).as_quat()
    # keep the hemisphere of the source so that consecutive samples stay continuous
    src = np.array([demo.quaternion[np.searchsorted(demo.t, ti, side="right") - 1] for ti in t])
    quat[np.einsum("ij,ij->i", quat, src) < 0.0] *= -1.0
    return t - t[0], pos, quat


@dataclass(frozen=True, eq=False)
class PriorBank:
    """K prior samples (arrays are copied; see the module doc).

    Attributes:
        features: (K, F) float32 matching features.
        cond: (K, 4) float32 conditions.
        scene_id: (K,) int64 latent index of the sample's training problem.
        grid_centre: (K, 3) [m] world grid centre.
        target_centre: (K, 3) [m] target box centre, grid-local.
        approach_axis: (K, 3) unit approach axis (out of the opening).
        t: (K, T) [s] sample times from 0.
        position: (K, T, 3) [m] wrist positions, grid-local.
        quaternion: (K, T, 4) [x y z w] wrist orientations (world axes).
        contact_index: (K,) int64 contact sample (T − 1 for an approach, 0 for a leave).
        layout: (K,) layout id per sample; target: (K,) target label name per sample.
    """

    features: NDArray[np.float32]
    cond: NDArray[np.float32]
    scene_id: NDArray[np.int64]
    grid_centre: NDArray[np.float64]
    target_centre: NDArray[np.float64]
    approach_axis: NDArray[np.float64]
    t: NDArray[np.float64]
    position: NDArray[np.float64]
    quaternion: NDArray[np.float64]
    contact_index: NDArray[np.int64]
    layout: tuple[str, ...]
    target: tuple[str, ...]

    def __post_init__(self) -> None:
        dtypes = {"features": np.float32, "cond": np.float32, "scene_id": np.int64, "contact_index": np.int64}
        for name in _ARRAYS:
            arr = np.array(getattr(self, name), dtype=dtypes.get(name, np.float64), copy=True)
            object.__setattr__(self, name, arr)
        k = self.features.shape[0]
        t_len = self.t.shape[1] if self.t.ndim == 2 else -1
        want = {
            "features": (k, self.features.shape[1] if self.features.ndim == 2 else -1),
            "cond": (k, COND_DIM),
            "scene_id": (k,),
            "grid_centre": (k, 3),
            "target_centre": (k, 3),
            "approach_axis": (k, 3),
            "t": (k, t_len),
            "position": (k, t_len, 3),
            "quaternion": (k, t_len, 4),
            "contact_index": (k,),
        }
        for name, shape in want.items():
            if getattr(self, name).shape != shape or -1 in shape:
                raise PlanningError(
                    f"PriorBank.{name} has shape {getattr(self, name).shape}, expected {shape}"
                )
        if k == 0 or t_len < 2:
            raise PlanningError(f"a prior bank needs K ≥ 1 samples of T ≥ 2 steps, got K={k}, T={t_len}")
        object.__setattr__(self, "layout", tuple(str(s) for s in self.layout))
        object.__setattr__(self, "target", tuple(str(s) for s in self.target))
        if len(self.layout) != k or len(self.target) != k:
            raise PlanningError(
                f"layout and target need {k} entries, got {len(self.layout)}, {len(self.target)}"
            )

    def __len__(self) -> int:
        return int(self.features.shape[0])

    def trajectory(self, k: int, grid_centre: ArrayLike | None = None) -> WristTrajectory:
        """Sample ``k``'s demonstration as a world-frame trajectory around ``grid_centre`` (3,) [m].

        Default centre: the training grid's, i.e. the original demonstration.
        """
        if not 0 <= k < len(self):
            raise PlanningError(f"prior index {k} outside 0..{len(self) - 1}")
        centre = self.grid_centre[k] if grid_centre is None else np.asarray(grid_centre, dtype=np.float64)
        c = self.cond[k]
        return WristTrajectory(
            t=self.t[k],
            position=self.position[k] + centre.reshape(1, 3),
            quaternion=self.quaternion[k],
            hand=HANDS[int(c[1] > 0.0)],
            action=ACTIONS[int(c[2] > 0.5)],
            segment=SEGMENTS[int(c[3] > 0.5)],
            contact_index=int(self.contact_index[k]),
            planner="prior",
            object_name=self.target[k],
        )

    def to_meta(self) -> dict[str, Any]:
        """Plain-data form for a checkpoint's meta (see :meth:`from_meta`)."""
        out: dict[str, Any] = {}
        for name in _ARRAYS:
            arr = getattr(self, name)
            out[name] = encode_array(arr.astype(np.float32) if arr.dtype == np.float64 else arr)
        out["layout"] = list(self.layout)
        out["target"] = list(self.target)
        return out

    @classmethod
    def from_meta(cls, doc: Mapping[str, Any]) -> PriorBank:
        """Decode :meth:`to_meta`'s output (e.g. ``load_checkpoint(path).meta["prior_bank"]``)."""
        missing = [f.name for f in fields(cls) if f.name not in doc]
        if missing:
            raise PlanningError(f"prior bank lacks {missing}")
        arrays = {name: decode_array(doc[name]) for name in _ARRAYS}
        return cls(**arrays, layout=tuple(doc["layout"]), target=tuple(doc["target"]))

    @classmethod
    def concatenate(cls, banks: Sequence[PriorBank]) -> PriorBank:
        """One bank of all samples of ``banks`` (scene ids are kept as they are)."""
        if not banks:
            raise PlanningError("concatenate needs at least one bank")
        arrays = {name: np.concatenate([getattr(b, name) for b in banks]) for name in _ARRAYS}
        layout = tuple(s for b in banks for s in b.layout)
        target = tuple(s for b in banks for s in b.target)
        return cls(**arrays, layout=layout, target=target)
