"""Labelled point clouds from MuJoCo cameras: depth + segmentation rendering, back-projection, fusion.

One segmentation pass per camera gives both buffers: the id colour of each pixel names a geom, and the
depth buffer of the same pass gives its distance along the camera axis. Geoms map to labels through
``model.geom_bodyid`` and the body tree (a body not in the label mapping inherits its nearest mapped
ancestor; a geom of the world body is looked up by its own name, e.g. ``floor``). Pixels are
back-projected with the camera's frustum (MuJoCo cameras look along -z with y up), moved to the world
frame with ``data.cam_xpos`` / ``data.cam_xmat``, fused over cameras and voxel-downsampled keeping the
majority label per voxel. ``mujoco`` is imported lazily, after :func:`ensure_headless_gl`.
"""

from __future__ import annotations

import logging
import os
from collections.abc import Mapping
from dataclasses import dataclass
from types import TracebackType
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import NDArray

from hsi_planning.errors import CloudError, ConfigError
from hsi_planning.gl import ensure_headless_gl
from hsi_planning.perception.cloud import LabelledCloud, voxel_downsample
from hsi_planning.perception.labels import body_labels, geom_labels, label_maps
from hsi_planning.perception.view import NO_GEOM, CameraView

if TYPE_CHECKING:
    import mujoco

    from hsi_planning.scene import SceneSpec

__all__ = [
    "NO_GEOM",
    "CameraView",
    "CloudConfig",
    "CloudRenderer",
    "body_labels",
    "label_maps",
    "render_cloud",
    "render_rgb",
    "scene_cloud",
    "scene_renderer",
]

_LOG = logging.getLogger(__name__)

# Importing this module picks the headless GL backend, so a later ``import mujoco`` uses it.
ensure_headless_gl()


@dataclass(frozen=True)
class CloudConfig:
    """How a labelled cloud is rendered from the model's cameras."""

    cameras: tuple[str, ...] = ()  #: camera names [-]; empty = every camera of the model
    width: int = 320  #: image width [px]
    height: int = 240  #: image height [px]
    voxel_size: float = 0.01  #: voxel edge of the fused downsampling [m]; 0 keeps every pixel
    min_depth: float = 0.05  #: pixels nearer than this (along the camera axis) are dropped [m]
    max_depth: float = 4.0  #: pixels farther than this (along the camera axis) are dropped [m]
    keep_unlabelled: bool = False  #: keep geoms of unmapped bodies as label -1 (else drop them) [-]

    def __post_init__(self) -> None:
        if len(set(self.cameras)) != len(self.cameras) or not all(self.cameras):
            raise ConfigError(f"cameras must be distinct non-empty names, got {self.cameras!r}")
        if not (1 <= self.width <= 8192 and 1 <= self.height <= 8192):
            raise ConfigError(f"width/height must be in 1..8192 px, got {self.width}x{self.height}")
        if not (self.voxel_size >= 0.0 and np.isfinite(self.voxel_size)):
            raise ConfigError(f"voxel_size must be >= 0 m (0 = no downsampling), got {self.voxel_size}")
        if not (0.0 <= self.min_depth < self.max_depth and np.isfinite(self.max_depth)):
            raise ConfigError(
                f"need 0 <= min_depth < max_depth < inf [m], got {self.min_depth}, {self.max_depth}"
            )


class CloudRenderer:
    """Owns one offscreen OpenGL context for a model; renders labelled views, clouds and RGB images.

    Creating the context is slow (~0.2 s); keep one renderer per model and reuse it. Use as a context
    manager or call :meth:`close`. Not thread-safe (OpenGL contexts are per thread).

    Args:
        model: the MuJoCo model (not copied; it must outlive the renderer and not change its geoms).
        labels: body name -> label id; None = every named body with its body id (see :func:`body_labels`).
        label_names / label_classes: carried into the clouds (default: inverted ``labels``).
        keep_unlabelled: geoms of bodies missing from ``labels`` give label -1 instead of being dropped.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        labels: Mapping[str, int] | None = None,
        *,
        label_names: Mapping[int, str] | None = None,
        label_classes: Mapping[int, str] | None = None,
        keep_unlabelled: bool = False,
    ) -> None:
        ensure_headless_gl()
        import mujoco

        self._model = model
        if labels is None:
            labels, default_names = body_labels(model)
        else:
            default_names = {int(v): k for k, v in labels.items()}
        self._label_names = dict(label_names) if label_names is not None else default_names
        self._label_classes = dict(label_classes) if label_classes is not None else None
        self._labels = dict(labels)
        self._geom_label = {keep_unlabelled: geom_labels(model, self._labels, keep_unlabelled)}
        self._max_size = (int(model.vis.global_.offwidth), int(model.vis.global_.offheight))
        self._gl: Any = None
        self._ctx: Any = None
        try:
            self._gl = mujoco.GLContext(*self._max_size)
            self._gl.make_current()
            self._ctx = mujoco.MjrContext(model, mujoco.mjtFontScale.mjFONTSCALE_100.value)
        except (mujoco.FatalError, RuntimeError, ImportError) as exc:
            self.close()
            raise CloudError(
                f"cannot create an offscreen OpenGL context (MUJOCO_GL={os.environ.get('MUJOCO_GL')!r}): "
                f"{exc}; set MUJOCO_GL=egl (or osmesa with libosmesa6) before mujoco is first imported"
            ) from exc
        mujoco.mjr_setBuffer(mujoco.mjtFramebuffer.mjFB_OFFSCREEN.value, self._ctx)
        self._ctx.readDepthMap = mujoco.mjtDepthMap.mjDEPTH_ZEROFAR
        self._scene = mujoco.MjvScene(model, maxgeom=max(1000, 2 * model.ngeom))
        self._option = mujoco.MjvOption()
        self._camera = mujoco.MjvCamera()
        self._camera.type = mujoco.mjtCamera.mjCAMERA_FIXED
        self._rays: dict[tuple[int, int, int], NDArray[np.float64]] = {}
        _LOG.debug("CloudRenderer: offscreen buffer %dx%d, %d geoms", *self._max_size, model.ngeom)

    # -- lifecycle -------------------------------------------------------------------------------
    def close(self) -> None:
        """Free the OpenGL resources (idempotent)."""
        if getattr(self, "_ctx", None) is not None:
            self._gl.make_current()
            self._ctx.free()
            self._ctx = None
        if getattr(self, "_gl", None) is not None:
            self._gl.free()
            self._gl = None

    def __enter__(self) -> CloudRenderer:
        return self

    def __exit__(
        self, exc: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def __del__(self) -> None:
        try:
            self.close()
        except Exception as exc:  # interpreter shutdown: GL libraries may be gone already
            _LOG.debug("CloudRenderer.__del__: %s", exc)

    # -- rendering -------------------------------------------------------------------------------
    def _camera_id(self, camera: str) -> int:
        import mujoco

        if camera.startswith("#") and camera[1:].isdigit():
            cid = int(camera[1:]) if int(camera[1:]) < self._model.ncam else -1
        else:
            cid = mujoco.mj_name2id(self._model, mujoco.mjtObj.mjOBJ_CAMERA, camera)
        if cid < 0:
            raise CloudError(f"camera {camera!r} not in the model; cameras: {self.camera_names()}")
        return int(cid)

    def camera_names(self) -> list[str]:
        """Names of the model's cameras, in model order (unnamed cameras as ``#<id>``)."""
        import mujoco

        return [
            mujoco.mj_id2name(self._model, mujoco.mjtObj.mjOBJ_CAMERA, c) or f"#{c}"
            for c in range(self._model.ncam)
        ]

    def _draw(self, data: mujoco.MjData, cid: int, width: int, height: int, segment: bool) -> Any:
        import mujoco

        if self._ctx is None:
            raise CloudError("CloudRenderer used after close()")
        if width > self._max_size[0] or height > self._max_size[1]:
            raise CloudError(
                f"{width}x{height} px exceeds the offscreen buffer {self._max_size[0]}x{self._max_size[1]}; "
                "raise <visual><global offwidth=.. offheight=../> in the model"
            )
        self._camera.fixedcamid = cid
        mujoco.mjv_updateScene(
            self._model, data, self._option, None, self._camera, mujoco.mjtCatBit.mjCAT_ALL.value, self._scene
        )
        self._scene.flags[mujoco.mjtRndFlag.mjRND_SEGMENT] = segment
        self._scene.flags[mujoco.mjtRndFlag.mjRND_IDCOLOR] = segment
        rect = mujoco.MjrRect(0, 0, width, height)
        self._gl.make_current()
        mujoco.mjr_render(rect, self._scene, self._ctx)
        return rect

    def _rays_for(self, cid: int, width: int, height: int) -> NDArray[np.float64]:
        """(H, W, 3) camera-frame pixel rays with z = -1, from the frustum MuJoCo renders with."""
        key = (cid, width, height)
        if key not in self._rays:
            cam = self._scene.camera[0]
            if self._scene.camera[0].orthographic:
                raise CloudError(f"camera #{cid} is orthographic; only perspective cameras are supported")
            near, top, bottom = float(cam.frustum_near), float(cam.frustum_top), float(cam.frustum_bottom)
            half = 0.5 * width / height * (top - bottom)
            left = float(cam.frustum_center) - half
            u = (left + (np.arange(width) + 0.5) / width * 2.0 * half) / near
            v = (top - (np.arange(height) + 0.5) / height * (top - bottom)) / near
            rays = np.empty((height, width, 3))
            rays[..., 0], rays[..., 1], rays[..., 2] = u[None, :], v[:, None], -1.0
            self._rays[key] = rays
        return self._rays[key]

    def render_view(
        self,
        data: mujoco.MjData,
        camera: str,
        width: int = 320,
        height: int = 240,
        keep_unlabelled: bool = False,
    ) -> CameraView:
        """Render one camera's depth and label images (``data`` must be forwarded: cam_xpos set)."""
        import mujoco

        cid = self._camera_id(camera)
        rect = self._draw(data, cid, width, height, segment=True)
        rgb = np.empty((height, width, 3), np.uint8)
        zbuf = np.empty((height, width), np.float32)
        mujoco.mjr_readPixels(rgb, zbuf, rect, self._ctx)
        ngeom = self._scene.ngeom
        seg_to_geom = np.full(ngeom + 1, -1, np.int64)
        for i in range(ngeom):
            g = self._scene.geoms[i]
            if g.segid >= 0 and g.objtype == mujoco.mjtObj.mjOBJ_GEOM:
                seg_to_geom[g.segid + 1] = g.objid
        segid = rgb[::-1].astype(np.int64)
        segid = segid[..., 0] + (segid[..., 1] << 8) + (segid[..., 2] << 16)
        geom = seg_to_geom[np.minimum(segid, ngeom)]
        if keep_unlabelled not in self._geom_label:
            self._geom_label[keep_unlabelled] = geom_labels(self._model, self._labels, keep_unlabelled)
        lut = self._geom_label[keep_unlabelled]
        label = np.where(geom >= 0, lut[np.maximum(geom, 0)], NO_GEOM).astype(np.int32)
        extent = float(self._model.stat.extent)
        znear = np.float32(self._model.vis.map.znear * extent)
        zfar = np.float32(self._model.vis.map.zfar * extent)
        c_coef = np.float32(-0.5) * (-(zfar + znear) / (zfar - znear)) - np.float32(0.5)
        d_coef = np.float32(-0.5) * (-(np.float32(2) * zfar * znear) / (zfar - znear))
        depth = (d_coef / (zbuf[::-1].astype(np.float64) + c_coef)).astype(np.float32)
        depth[label == NO_GEOM] = np.inf
        return CameraView(
            camera,
            depth,
            label,
            self._rays_for(cid, width, height),
            np.array(data.cam_xpos[cid], dtype=np.float64),
            np.array(data.cam_xmat[cid], dtype=np.float64).reshape(3, 3),
        )

    def render_cloud(self, data: mujoco.MjData, config: CloudConfig | None = None) -> LabelledCloud:
        """Fused, voxel-downsampled labelled cloud from ``config.cameras`` (default: all cameras)."""
        config = config or CloudConfig()
        cameras = config.cameras or tuple(self.camera_names())
        if not cameras:
            raise CloudError("the model has no cameras; add <camera> elements or name cameras in CloudConfig")
        parts = [
            self.render_view(data, cam, config.width, config.height, config.keep_unlabelled).points(
                config.min_depth, config.max_depth
            )
            for cam in cameras
        ]
        fused = LabelledCloud(
            np.concatenate([p.points for p in parts]),
            np.concatenate([p.labels for p in parts]),
            self._label_names,
            self._label_classes,
        )
        return voxel_downsample(fused, config.voxel_size) if config.voxel_size > 0 else fused

    def render_rgb(
        self, data: mujoco.MjData, camera: str, width: int = 320, height: int = 240
    ) -> NDArray[np.uint8]:
        """(H, W, 3) uint8 colour image of one camera, top row first."""
        import mujoco

        rect = self._draw(data, self._camera_id(camera), width, height, segment=False)
        rgb = np.empty((height, width, 3), np.uint8)
        mujoco.mjr_readPixels(rgb, None, rect, self._ctx)
        return np.ascontiguousarray(rgb[::-1])


def render_cloud(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    config: CloudConfig | None = None,
    *,
    labels: Mapping[str, int] | None = None,
    label_names: Mapping[int, str] | None = None,
    label_classes: Mapping[int, str] | None = None,
) -> LabelledCloud:
    """One-shot :meth:`CloudRenderer.render_cloud` (creates and frees a renderer: slow; reuse one instead)."""
    config = config or CloudConfig()
    with CloudRenderer(
        model,
        labels,
        label_names=label_names,
        label_classes=label_classes,
        keep_unlabelled=config.keep_unlabelled,
    ) as renderer:
        return renderer.render_cloud(data, config)


def render_rgb(
    model: mujoco.MjModel, data: mujoco.MjData, camera: str, width: int = 320, height: int = 240
) -> NDArray[np.uint8]:
    """(H, W, 3) uint8 colour image of ``camera`` (one-shot; for repeated images keep a CloudRenderer)."""
    with CloudRenderer(model) as renderer:
        return renderer.render_rgb(data, camera, width, height)


def scene_renderer(spec: SceneSpec) -> tuple[mujoco.MjModel, mujoco.MjData, CloudRenderer]:
    """Build ``spec``'s model, settle the kinematics (``mj_forward``), open a renderer labelled by the
    scene's label table. The caller closes the renderer."""
    import mujoco

    from hsi_planning.scene import build_mjcf, scene_labels

    model = mujoco.MjModel.from_xml_string(build_mjcf(spec))
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    ids, names, classes = label_maps(scene_labels(spec))
    return model, data, CloudRenderer(model, ids, label_names=names, label_classes=classes)


def scene_cloud(spec: SceneSpec, config: CloudConfig | None = None) -> LabelledCloud:
    """Labelled cloud of a scene spec at rest, label names and classes from its label table."""
    config = config or CloudConfig()
    _, data, renderer = scene_renderer(spec)
    with renderer:
        return renderer.render_cloud(data, config)
