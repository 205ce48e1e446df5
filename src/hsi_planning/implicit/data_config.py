"""Configuration of the planner's training-data build (:func:`.data_build.build_planner_data`)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

from hsi_planning.errors import ConfigError
from hsi_planning.implicit.problem import TRAIN_SEEDS
from hsi_planning.trajectory import ACTIONS, HANDS, SEGMENTS, Action, Hand, Segment

BUILTIN_SCENES = (
    "sim/scenes/kitchen.yaml",
    "sim/scenes/narrow_shelf.yaml",
    "sim/scenes/cluttered_drawer.yaml",
)


@dataclass(frozen=True)
class DataBuildConfig:
    """What training data to build (defaults: 3 scenes × 2 groups × 6 layouts × 3 targets × 8 conditions)."""

    scenes: tuple[str, ...] = BUILTIN_SCENES  #: [-] scene spec files (relative paths: to the repository root)
    layout_seed: int = 0  #: [-] seed of generate_layouts; must lie in TRAIN_SEEDS (0–9999)
    layouts_per_group: int = 6  #: [-] layouts per scene and layout group
    reshape_groups: tuple[bool, ...] = (False, True)  #: [-] layout groups: without / with container reshaping
    targets_per_layout: int = 3  #: [-] targets picked per layout
    hands: tuple[str, ...] = HANDS  #: [-] hands demonstrated per target
    actions: tuple[str, ...] = ACTIONS  #: [-] actions demonstrated per target
    segments: tuple[str, ...] = SEGMENTS  #: [-] segments demonstrated per target
    demo_seed: int = 0  #: [-] seed of target picks, start poses and demonstrations
    start_centre: tuple[float, float, float] = (0.2, 0.25, 1.0)  #: [m] free wrist pose, body frame, left hand
    start_noise: float = 0.03  #: [m] std of the free pose's Gaussian noise per axis
    palm_offset: float = 0.06  #: [m] wrist distance from the target's box along the approach axis
    door_fraction: float = 0.9  #: [-] opened door hinge, fraction of its range
    drawer_fraction: float = 0.6  #: [-] pulled-out drawer slide, fraction of its travel
    bank_samples: int = 60  #: [-] samples per demonstration in the prior bank
    cloud_width: int = 320  #: [px] rendered image width
    cloud_height: int = 240  #: [px] rendered image height
    cloud_voxel: float = 0.01  #: [m] voxel size of the fused cloud
    workers: int = 2  #: [-] field worker processes
    chunk_jobs: int = 32  #: [-] field jobs computed per pool run (bounds memory)

    def __post_init__(self) -> None:
        if not self.scenes:
            raise ConfigError("DataBuildConfig.scenes is empty; name at least one scene spec")
        if self.layout_seed not in TRAIN_SEEDS:
            raise ConfigError(
                f"DataBuildConfig.layout_seed={self.layout_seed} must lie in the training range "
                f"{TRAIN_SEEDS.start}..{TRAIN_SEEDS.stop - 1} (seeds ≥ 100000 are for benchmarks/tests)"
            )
        for name in ("layouts_per_group", "targets_per_layout", "workers", "chunk_jobs"):
            if getattr(self, name) < 1:
                raise ConfigError(f"DataBuildConfig.{name}={getattr(self, name)} must be ≥ 1")
        if self.bank_samples < 2 or self.cloud_width < 8 or self.cloud_height < 8:
            raise ConfigError("DataBuildConfig: bank_samples ≥ 2 and cloud_width/height ≥ 8 px required")
        for name, valid in (("hands", HANDS), ("actions", ACTIONS), ("segments", SEGMENTS)):
            values = getattr(self, name)
            if not values or any(v not in valid for v in values) or len(set(values)) != len(values):
                raise ConfigError(
                    f"DataBuildConfig.{name}={values!r} must be distinct values of {list(valid)}"
                )
        if not self.reshape_groups or len(set(self.reshape_groups)) != len(self.reshape_groups):
            raise ConfigError(f"DataBuildConfig.reshape_groups={self.reshape_groups!r}: distinct booleans")
        if not (0.0 <= self.start_noise < 0.2 and 0.0 <= self.palm_offset < 0.3 and self.cloud_voxel >= 0.0):
            raise ConfigError("DataBuildConfig: start_noise in [0, 0.2) m, palm_offset in [0, 0.3) m")
        if not (0.0 < self.door_fraction <= 1.0 and 0.0 < self.drawer_fraction <= 1.0):
            raise ConfigError("DataBuildConfig: door_fraction and drawer_fraction must be in (0, 1]")

    @property
    def conditions(self) -> list[tuple[Hand, Action, Segment]]:
        """The (hand, action, segment) triples demonstrated per target."""
        return [
            (cast(Hand, h), cast(Action, a), cast(Segment, s))
            for h in self.hands
            for a in self.actions
            for s in self.segments
        ]
