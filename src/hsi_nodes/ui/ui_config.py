"""The web UI's config: what it serves and how its tasks run (:class:`UiConfig`)."""

from __future__ import annotations

from dataclasses import dataclass

from hsi_planning.errors import ConfigError

__all__ = ["UiConfig"]


@dataclass(frozen=True)
class UiConfig:
    """What the UI serves and how tasks run."""

    scene: str = "kitchen"  #: built-in scene name or spec path [-]
    robot: str = "dual_ur5e"  #: robot (``dual_ur5e``/``dual_arm`` or ``humanoid``) [-]
    planner: str = "implicit"  #: default wrist planner (``hsi_nodes.demo.pipeline.DEMO_PLANNERS``) [-]
    checkpoint: str = "models/planner.pt"  #: implicit planner checkpoint [path]
    host: str = "127.0.0.1"  #: address the web server binds [-]
    port: int = 8080  #: web server port [-]
    fast: bool = False  #: reach-model planner (fast, for tests and quick looks) [-]
    cloud_voxel: float = 0.01  #: voxel size of the rendered scene cloud [m]
    frame_rate: float = 20.0  #: live robot redraws per wall second while a task runs [Hz]
    max_cloud_points: int = 50000  #: scene cloud points sent to the browser (evenly strided) [-]

    def __post_init__(self) -> None:
        from hsi_nodes.demo.pipeline import DEMO_PLANNERS
        from hsi_retarget.robots import robot_name

        object.__setattr__(self, "robot", robot_name(self.robot))
        if self.fast:
            object.__setattr__(self, "planner", "reach_model")
        if self.planner not in DEMO_PLANNERS:
            raise ConfigError(f"UiConfig.planner={self.planner!r}; available: {list(DEMO_PLANNERS)}")
        if not (
            0 <= self.port < 65536
            and self.cloud_voxel > 0.0
            and self.frame_rate > 0.0
            and self.max_cloud_points > 0
        ):
            raise ConfigError(
                "UiConfig: port in [0, 65535], cloud_voxel > 0 m, frame_rate > 0 Hz, max_cloud_points > 0; "
                f"got {self.port}, {self.cloud_voxel}, {self.frame_rate}, {self.max_cloud_points}"
            )
