"""``scene_cloud_node``: renders the labelled point cloud of a scene from its MuJoCo cameras.

It builds the scene's MuJoCo model, renders the fused labelled cloud (depth + segmentation of every
camera, see :mod:`hsi_planning.perception.render`) and publishes it as ``sensor_msgs/PointCloud2`` with
fields ``x, y, z, label`` on ``topic`` (latched, so late subscribers get the last cloud): once at start,
then every ``period_s`` when that is > 0. The label table goes out once, latched, on ``labels_topic`` as
``std_msgs/String`` JSON ``{"<id>": {"name", "semantic_class", "kind", "parent"}}``.

To follow the simulation it subscribes to ``/tf`` (object poses from ``sim_node``) and
``/scene/joint_states`` (door and drawer positions) and applies the latest values to its own model
before the next render. Bad messages (unknown frame or joint, non-finite values, wrong parent frame or
array sizes) are logged (each kind of problem once at WARNING, then at DEBUG), counted in
:attr:`SceneCloudNode.ignored` and otherwise ignored.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from hsi_nodes.msgs import msg_class, ns_to_time
from hsi_nodes.node import Node
from hsi_nodes.pointcloud2 import cloud_to_msg
from hsi_nodes.transport.base import QoS
from hsi_planning.errors import ConfigError
from hsi_planning.gl import ensure_headless_gl
from hsi_planning.perception import CloudConfig, LabelledCloud
from hsi_planning.perception.render import label_maps

if TYPE_CHECKING:
    from hsi_planning.scene import SceneSpec

ensure_headless_gl()  # before mujoco is first imported: it picks its OpenGL backend at import
import mujoco  # noqa: E402

__all__ = ["SceneCloudConfig", "SceneCloudNode", "label_table_json"]

_CLOUD = "sensor_msgs/msg/PointCloud2"
_STRING = "std_msgs/msg/String"
_TF = "tf2_msgs/msg/TFMessage"
_JOINT_STATE = "sensor_msgs/msg/JointState"
#: Delay of the first render after start [s] (a one-shot timer, so render errors are guarded).
_FIRST_DELAY_S = 1e-3


@dataclass(frozen=True)
class SceneCloudConfig:
    """Parameters of :class:`SceneCloudNode`."""

    #: Scene: built-in name (``kitchen``) or path of a spec YAML [-].
    scene: str = "kitchen"
    #: Cameras to fuse; empty = every camera of the scene [-].
    cameras: tuple[str, ...] = ()
    #: Rendered image width [px].
    width: int = 320
    #: Rendered image height [px].
    height: int = 240
    #: Voxel edge of the fused downsampling; 0 keeps every pixel [m].
    voxel_size: float = 0.01
    #: Re-render period; 0 = publish once at start [s].
    period_s: float = 0.0
    #: Frame of the published points [-].
    frame_id: str = "world"
    #: Cloud topic (latched) [-].
    topic: str = "/scene/points"
    #: Label table topic (latched, JSON) [-].
    labels_topic: str = "/scene/labels"
    #: Object poses to follow; empty = do not follow [-].
    tf_topic: str = "/tf"
    #: Door/drawer positions to follow; empty = do not follow [-].
    joint_states_topic: str = "/scene/joint_states"

    def __post_init__(self) -> None:
        if not self.scene:
            raise ConfigError("SceneCloudConfig.scene: give a built-in scene name or a spec path")
        if not (1 <= self.width <= 4096 and 1 <= self.height <= 4096):
            raise ConfigError(
                f"SceneCloudConfig width/height must be in 1..4096 [px], got {self.width}x{self.height}"
            )
        if not (self.voxel_size >= 0.0 and math.isfinite(self.voxel_size)):
            raise ConfigError(f"SceneCloudConfig.voxel_size must be >= 0 [m], got {self.voxel_size}")
        if not (self.period_s >= 0.0 and math.isfinite(self.period_s)):
            raise ConfigError(f"SceneCloudConfig.period_s must be >= 0 [s] (0 = once), got {self.period_s}")
        if not (self.frame_id and self.topic and self.labels_topic):
            raise ConfigError("SceneCloudConfig: frame_id, topic and labels_topic must not be empty")
        CloudConfig(self.cameras, self.width, self.height, self.voxel_size)  # validates camera names


def label_table_json(spec: SceneSpec) -> str:
    """The JSON text of a scene's label table, ``{"<id>": {name, semantic_class, kind, parent}}``."""
    from hsi_planning.scene import scene_labels

    table = {
        str(lab.id): {
            "name": lab.name,
            "semantic_class": lab.semantic_class,
            "kind": lab.kind,
            "parent": lab.parent,
        }
        for lab in scene_labels(spec)
    }
    return json.dumps(table, sort_keys=False)


class SceneCloudNode(Node[SceneCloudConfig]):
    """Publishes the rendered labelled cloud of a scene and follows ``/tf`` (see the module docstring)."""

    config_class = SceneCloudConfig

    def __init__(self, name: str = "scene_cloud_node", **kwargs: Any) -> None:
        super().__init__(name, **kwargs)
        from hsi_planning.perception import CloudRenderer
        from hsi_planning.scene import articulated_parts, build_mjcf, object_names, scene_labels
        from hsi_planning.scene_paths import load_scene

        cfg = self.config
        self.spec = load_scene(cfg.scene)
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(self.spec))
        self.data = mujoco.MjData(self.model)
        mujoco.mj_forward(self.model, self.data)
        ids, names, classes = label_maps(scene_labels(self.spec))
        self.renderer = CloudRenderer(self.model, ids, label_names=names, label_classes=classes)
        missing = sorted(set(cfg.cameras) - set(self.renderer.camera_names()))
        if missing:
            self.renderer.close()
            raise ConfigError(
                f"cameras {missing} not in scene {self.spec.name!r}; it has {self.renderer.camera_names()}"
            )
        self._cloud_config = CloudConfig(cfg.cameras, cfg.width, cfg.height, cfg.voxel_size)
        self._free_qpos = {n: self._qpos_adr(n) for n in object_names(self.spec)}
        self._part_qpos = {n: self._qpos_adr(n) for n in articulated_parts(self.spec)}
        self._pending_poses: dict[str, NDArray[np.float64]] = {}
        self._pending_joints: dict[str, float] = {}
        self._problems: set[str] = set()
        #: Clouds published; transforms / joint values ignored as invalid.
        self.published = 0
        self.ignored = 0
        #: The last published cloud (read-only arrays).
        self.last_cloud: LabelledCloud | None = None
        latched = QoS(depth=1, latched=True)
        self.cloud_pub = self.create_publisher(cfg.topic, _CLOUD, latched)
        self.labels_pub = self.create_publisher(cfg.labels_topic, _STRING, latched)
        self.labels_pub.publish(msg_class(_STRING)(data=label_table_json(self.spec)))
        if cfg.tf_topic:
            self.create_subscription(cfg.tf_topic, _TF, self._on_tf, 100)
        if cfg.joint_states_topic:
            self.create_subscription(cfg.joint_states_topic, _JOINT_STATE, self._on_joints, 10)
        self._first = self.create_timer(_FIRST_DELAY_S, self._publish_first)
        self.timer = self.create_timer(cfg.period_s, self._publish_periodic) if cfg.period_s > 0 else None

    def _qpos_adr(self, joint: str) -> int:
        jid = mujoco.mj_name2id(self.model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        return int(self.model.jnt_qposadr[jid])

    # ------------------------------------------------------------------------------------- inputs

    def _ignore(self, problem: str, detail: str) -> None:
        """Count and log an ignored input: WARNING the first time per ``problem``, DEBUG afterwards."""
        self.ignored += 1
        first = problem not in self._problems
        self._problems.add(problem)
        log = self.get_logger().warning if first else self.get_logger().debug
        log("ignored %s: %s%s", problem, detail, " (further ones logged at DEBUG)" if first else "")

    def _on_tf(self, msg: Any) -> None:
        for tf in getattr(msg, "transforms", None) or []:
            child, parent = str(tf.child_frame_id), str(tf.header.frame_id)
            if child not in self._free_qpos:
                self._ignore(f"/tf child {child!r}", f"not an object of scene {self.spec.name!r}")
                continue
            t, r = tf.transform.translation, tf.transform.rotation
            pose = np.array([t.x, t.y, t.z, r.w, r.x, r.y, r.z], dtype=np.float64)  # MuJoCo (w, x, y, z)
            norm = float(np.linalg.norm(pose[3:]))
            if parent.lstrip("/") != self.config.frame_id:
                self._ignore(
                    "/tf parent frame", f"{parent!r} for {child!r}; expected {self.config.frame_id!r}"
                )
            elif not (np.all(np.isfinite(pose)) and norm > 1e-9):
                self._ignore("/tf non-finite pose", f"{child!r}: {pose.tolist()}")
            else:
                pose[3:] /= norm
                self._pending_poses[child] = pose

    def _on_joints(self, msg: Any) -> None:
        names, positions = list(msg.name), np.asarray(msg.position, dtype=np.float64).reshape(-1)
        if len(names) != positions.size:
            self._ignore("joint state size", f"{len(names)} names but {positions.size} positions")
            return
        for name, value in zip(names, positions, strict=True):
            if name not in self._part_qpos:
                self._ignore(f"joint {name!r}", f"not a door/drawer of scene {self.spec.name!r}")
            elif not math.isfinite(float(value)):
                self._ignore("non-finite joint position", f"{name!r}: {value}")
            else:
                self._pending_joints[name] = float(value)

    def _apply_pending(self) -> None:
        """Move the model to the latest received poses and joint positions."""
        if not (self._pending_poses or self._pending_joints):
            return
        for name, pose in self._pending_poses.items():
            adr = self._free_qpos[name]
            self.data.qpos[adr : adr + 7] = pose
        for name, value in self._pending_joints.items():
            self.data.qpos[self._part_qpos[name]] = value
        self._pending_poses.clear()
        self._pending_joints.clear()
        mujoco.mj_forward(self.model, self.data)

    # ------------------------------------------------------------------------------------ outputs

    def _publish_first(self) -> None:
        self._first.cancel()
        self.publish_cloud()

    def _publish_periodic(self) -> None:
        self.publish_cloud()

    def publish_cloud(self) -> LabelledCloud:
        """Apply the pending poses, render, publish and return the cloud."""
        self._apply_pending()
        cloud = self.renderer.render_cloud(self.data, self._cloud_config)
        self.cloud_pub.publish(
            cloud_to_msg(cloud.points, cloud.labels, self.config.frame_id, ns_to_time(self.now_ns()))
        )
        self.last_cloud = cloud
        self.published += 1
        self.get_logger().debug("published cloud %d: %d points", self.published, len(cloud.points))
        return cloud

    def on_shutdown(self) -> None:
        self.renderer.close()
