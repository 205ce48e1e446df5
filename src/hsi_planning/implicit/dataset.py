"""The in-memory training set of the auto-decoder and its batch sampling.

A training *sample* k is one (scene, condition) pair: the scene's latent index ``scene_id[k]``, the
condition ``cond[k]`` (4,) and the fields (D_t, D_o, D_toa) on the shared object-centric grid. All
samples use the same grid points (in [-1, 1] grid-local coordinates), so the set stores the points once
and the targets as one (K, N, C) float32 array (33³ points × 3 fields ≈ 0.43 MB per sample).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_planning.errors import ConfigError, PlanningError
from hsi_planning.implicit.model import CHANNELS, COND_DIM


@dataclass(frozen=True)
class Batch:
    """One training batch: B samples × P points.

    Attributes:
        sample: (B,) indices of the samples in the dataset.
        scene: (B,) latent (scene) index per sample.
        cond: (B, 4) condition per sample.
        points: (B, P, 3) [-] grid-local query points.
        targets: (B, P, C) field values in physical units [1/m or 1/s].
    """

    sample: NDArray[np.int64]
    scene: NDArray[np.int64]
    cond: NDArray[np.float32]
    points: NDArray[np.float32]
    targets: NDArray[np.float32]


class FieldDataset:
    """Fields of K training samples on one shared grid of N points.

    Args:
        points: (N, 3) [-] grid-local coordinates in [-1, 1] (see ``model.to_unit_cube``).
        targets: (K, N, C) field values [1/m or 1/s], finite and ≥ 0, one column per channel.
        scene_id: (K,) latent index per sample; every index 0..S-1 must occur.
        cond: (K, 4) condition per sample (height [m], hand ±1, action 0/1, segment 0/1).
        channels: names of the C columns, e.g. ("t", "o", "toa").
        near_fraction_of_grid: [-] fraction of each sample's grid points with the largest D_toa kept as
            the "near the demonstrated path" pool for importance sampling (needs a "toa" channel).
    """

    def __init__(
        self,
        points: ArrayLike,
        targets: ArrayLike,
        scene_id: ArrayLike,
        cond: ArrayLike,
        *,
        channels: Sequence[str] = CHANNELS,
        near_fraction_of_grid: float = 0.1,
    ) -> None:
        pts = np.array(points, dtype=np.float32, copy=True)
        tgt = np.array(targets, dtype=np.float32, copy=True)
        sid = np.array(scene_id, copy=True).reshape(-1)
        cnd = np.array(cond, dtype=np.float32, copy=True)
        chans = tuple(channels)
        if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
            raise PlanningError(f"points must be (N, 3) with N ≥ 1, got {pts.shape}")
        if not np.isfinite(pts).all():
            raise PlanningError("points contain NaN or infinite values")
        if len(chans) == 0 or any(c not in CHANNELS for c in chans) or len(set(chans)) != len(chans):
            raise ConfigError(f"channels={chans!r} must be distinct names from {list(CHANNELS)}")
        k = sid.shape[0]
        if k == 0:
            raise PlanningError("a dataset needs at least one sample")
        if tgt.shape != (k, pts.shape[0], len(chans)):
            raise PlanningError(
                f"targets must be (K, N, C) = ({k}, {pts.shape[0]}, {len(chans)}), got {tgt.shape}"
            )
        if cnd.shape != (k, COND_DIM):
            raise PlanningError(f"cond must be (K, {COND_DIM}) = ({k}, {COND_DIM}), got {cnd.shape}")
        if not np.issubdtype(sid.dtype, np.integer):
            raise PlanningError(f"scene_id must be integers, got dtype {sid.dtype}")
        if not (np.isfinite(tgt).all() and np.isfinite(cnd).all()):
            raise PlanningError("targets and cond must be finite (found NaN or inf)")
        if (tgt < 0.0).any():
            raise PlanningError(f"targets must be ≥ 0 (inverse distances/times), min is {tgt.min():.3g}")
        n_scenes = int(sid.max()) + 1
        if sid.min() < 0 or np.unique(sid).shape[0] != n_scenes:
            raise PlanningError(f"scene_id must use every index 0..S-1, got values {np.unique(sid)[:10]}…")
        if not 0.0 < near_fraction_of_grid <= 1.0:
            raise ConfigError(f"near_fraction_of_grid={near_fraction_of_grid} must be in (0, 1]")
        self.points = pts
        self.targets = tgt
        self.scene_id = sid.astype(np.int64)
        self.cond = cnd
        self.channels = chans
        self.n_scenes = n_scenes
        self.near_fraction_of_grid = near_fraction_of_grid
        self.near_index: NDArray[np.int64] | None = None
        if "toa" in chans:
            m = max(1, round(near_fraction_of_grid * pts.shape[0]))
            toa = tgt[:, :, chans.index("toa")]
            part = np.argpartition(-toa, m - 1, axis=1)[:, :m]
            self.near_index = np.sort(part, axis=1).astype(np.int64)

    def __len__(self) -> int:
        return int(self.scene_id.shape[0])

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @classmethod
    def from_grids(
        cls,
        points: ArrayLike,
        grids: Sequence[Mapping[str, ArrayLike]],
        scene_id: ArrayLike,
        cond: ArrayLike,
        *,
        channels: Sequence[str] = CHANNELS,
        near_fraction_of_grid: float = 0.1,
    ) -> FieldDataset:
        """Build from per-sample field grids, e.g. ``{"t": fs.d_t, "o": fs.d_o, "toa": fs.d_toa}``.

        Each grid array (any shape with N elements, e.g. (n, n, n)) is flattened in C order, which must
        match the order of ``points``.
        """
        cols = []
        for i, g in enumerate(grids):
            missing = [c for c in channels if c not in g]
            if missing:
                raise PlanningError(f"grid {i} lacks channel(s) {missing}; it has {sorted(g)}")
            cols.append(np.stack([np.asarray(g[c], dtype=np.float32).reshape(-1) for c in channels], axis=1))
        if not cols:
            raise PlanningError("from_grids needs at least one grid")
        shapes = {c.shape for c in cols}
        if len(shapes) != 1:
            raise PlanningError(f"all grids must have the same number of points, got shapes {sorted(shapes)}")
        return cls(
            points,
            np.stack(cols),
            scene_id,
            cond,
            channels=channels,
            near_fraction_of_grid=near_fraction_of_grid,
        )

    def select_channels(self, channels: Sequence[str]) -> FieldDataset:
        """A copy with only ``channels`` (e.g. ("t", "toa") for the ablation without D_o)."""
        missing = [c for c in channels if c not in self.channels]
        if missing:
            raise PlanningError(f"channels {missing} not in the dataset's {list(self.channels)}")
        cols = [self.channels.index(c) for c in channels]
        return FieldDataset(
            self.points,
            self.targets[:, :, cols],
            self.scene_id,
            self.cond,
            channels=tuple(channels),
            near_fraction_of_grid=self.near_fraction_of_grid,
        )

    def sample_batch(
        self, rng: np.random.Generator, batch_size: int, n_points: int, near_share: float = 0.0
    ) -> Batch:
        """Draw ``batch_size`` samples and ``n_points`` grid points per sample (with replacement).

        Args:
            rng: numpy generator (seeded by the caller).
            batch_size: [-] samples per batch; drawn without replacement when the set is large enough.
            n_points: [-] points per sample P.
            near_share: [-] share of the P points drawn from the sample's high-D_toa pool (the
                demonstrated path and goal region); the rest uniformly from the grid.
        """
        if batch_size < 1 or n_points < 1:
            raise ConfigError(f"batch_size and n_points must be ≥ 1, got {batch_size}, {n_points}")
        if not 0.0 <= near_share <= 1.0:
            raise ConfigError(f"near_share={near_share} must be in [0, 1]")
        k = len(self)
        sample = rng.choice(k, size=batch_size, replace=batch_size > k).astype(np.int64)
        n_near = round(near_share * n_points)
        idx = rng.integers(0, self.n_points, size=(batch_size, n_points - n_near))
        if n_near > 0:
            if self.near_index is None:
                raise ConfigError("importance sampling (near_share > 0) needs a 'toa' channel in the dataset")
            pool = self.near_index[sample]
            pick = rng.integers(0, pool.shape[1], size=(batch_size, n_near))
            idx = np.concatenate([idx, np.take_along_axis(pool, pick, axis=1)], axis=1)
        return Batch(
            sample=sample,
            scene=self.scene_id[sample],
            cond=self.cond[sample],
            points=self.points[idx],
            targets=self.targets[sample[:, None], idx],
        )

    def save_npz(self, path: str | Path) -> None:
        """Write the set to a compressed ``.npz`` (points, targets, scene_id, cond, channels)."""
        np.savez_compressed(
            Path(path),
            points=self.points,
            targets=self.targets,
            scene_id=self.scene_id,
            cond=self.cond,
            channels=np.array(self.channels),
        )

    @classmethod
    def load_npz(cls, path: str | Path) -> FieldDataset:
        """Read a set written by :meth:`save_npz`."""
        p = Path(path)
        if not p.is_file():
            raise PlanningError(f"{p}: no such dataset file")
        with np.load(p, allow_pickle=False) as data:
            missing = [k for k in ("points", "targets", "scene_id", "cond", "channels") if k not in data]
            if missing:
                raise PlanningError(f"{p}: not a FieldDataset file, missing arrays {missing}")
            return cls(
                data["points"],
                data["targets"],
                data["scene_id"],
                data["cond"],
                channels=tuple(str(c) for c in data["channels"]),
            )
