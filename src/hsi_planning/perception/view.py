"""One camera's labelled depth image: back-projection to world points, visibility measures."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from hsi_planning.perception.cloud import LabelledCloud

#: Label of a pixel that shows no geom at all (background) or a geom that is dropped.
NO_GEOM = -2


@dataclass(frozen=True, eq=False)
class CameraView:
    """One camera's labelled depth image and its geometry.

    Attributes:
        camera: camera name.
        depth: (H, W) float32 [m] distance along the camera's viewing axis; inf where no geom.
        label: (H, W) int32 label per pixel; -1 = unmapped body, ``NO_GEOM`` (-2) = nothing/dropped.
        rays: (H, W, 3) float64 camera-frame direction per pixel with z = -1 (point = rays * depth).
        position: (3,) [m] camera position, world frame.
        rotation: (3, 3) camera-to-world rotation (columns: camera x right, y up, z backwards).
    """

    camera: str
    depth: NDArray[np.float32]
    label: NDArray[np.int32]
    rays: NDArray[np.float64]
    position: NDArray[np.float64]
    rotation: NDArray[np.float64]

    def pixel_counts(self) -> dict[int, int]:
        """Pixels showing each label (``NO_GEOM`` excluded)."""
        ids, counts = np.unique(self.label[self.label != NO_GEOM], return_counts=True)
        return {int(i): int(c) for i, c in zip(ids, counts, strict=True)}

    def projected_areas(self) -> dict[int, float]:
        """Per label, the summed footprint [m^2] of its pixels on planes facing the camera
        (depth^2 x pixel angular size): the visible surface area it shows, not counting obliqueness
        (a tilted surface has more area than this)."""
        du = float(self.rays[0, 1, 0] - self.rays[0, 0, 0]) if self.rays.shape[1] > 1 else 0.0
        dv = float(self.rays[0, 0, 1] - self.rays[1, 0, 1]) if self.rays.shape[0] > 1 else du
        seen = self.label != NO_GEOM
        area = self.depth[seen].astype(np.float64) ** 2 * abs(du * (dv or du))
        ids, inverse = np.unique(self.label[seen], return_inverse=True)
        sums = np.bincount(inverse.reshape(-1), area, len(ids))
        return {int(i): float(a) for i, a in zip(ids, sums, strict=True)}

    def points(self, min_depth: float = 0.0, max_depth: float = np.inf) -> LabelledCloud:
        """Back-project the pixels showing a geom with ``min_depth <= depth <= max_depth`` [m]."""
        valid = (self.label != NO_GEOM) & (self.depth >= min_depth) & (self.depth <= max_depth)
        cam = self.rays[valid] * self.depth[valid].astype(np.float64)[:, None]
        world = cam @ self.rotation.T + self.position
        return LabelledCloud(world, self.label[valid])
