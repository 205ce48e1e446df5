"""The web UI (viser): click an object, click a place, start the task, watch the robot do it.

:class:`UiApp` serves the scene (:class:`~hsi_nodes.ui.scene_view.SceneView`) and a control panel. A
click in the 3D view is hit-tested against the scene, published on ``/clicked_point`` and resolved like
an RViz click (:func:`~hsi_planning.scheduler.resolve_click`): a click on an object selects it as the
target (highlighted), a click on a free support surface (with a target selected) is the placement. The
*Start task* button publishes the ``/hsi/goal`` and runs the task through the demo pipeline
(:func:`~hsi_nodes.demo.pipeline.run_task`: scheduler + planner -> retargeting -> MuJoCo) in a worker
thread, so the UI stays live; the robot and objects are re-posed from the simulation while it runs.
Afterwards the keyframes, the planned wrist paths, the robot's TCP paths, the task report and the speed
profiles are shown; then the minimum-jerk baseline is planned on the learned segments' own requests
(:mod:`~hsi_nodes.ui.minjerk_overlay`, still in the worker) and drawn when its toggle is on. Every error
(a click on nothing, unknown object, unreachable place, planner or execution failure, a baseline that
fails) appears in the panel.
"""

from __future__ import annotations

import dataclasses
import logging
import threading
import time
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from hsi_nodes.ui.report_panel import SUCCESS_TEXT, report_markdown, speed_image
from hsi_nodes.ui.ui_config import UiConfig
from hsi_planning.errors import HsiError, PlanningError

if TYPE_CHECKING:
    from hsi_nodes.demo.pipeline import TaskOutcome
    from hsi_nodes.ui.minjerk_overlay import MinJerkPath
    from hsi_planning.planning import PlanRequest, PlanResult
    from hsi_planning.scheduler import Schedule
    from hsi_retarget.sim_check import SimWorld

__all__ = ["SUCCESS_TEXT", "UiApp", "UiConfig"]

_log = logging.getLogger(__name__)

F64 = NDArray[np.float64]


class UiApp:
    """The viser server, its control panel and the task worker (see the module docstring)."""

    def __init__(self, config: UiConfig) -> None:
        import viser

        from hsi_nodes.demo.pipeline import DEMO_PLANNERS, PipelineConfig
        from hsi_nodes.demo.runner import scene_cloud
        from hsi_nodes.transport.inproc import InprocTransport
        from hsi_nodes.ui.scene_view import SceneView
        from hsi_nodes.ui.ui_node import UiNode
        from hsi_planning.perception import CloudConfig
        from hsi_planning.scene_paths import load_scene
        from hsi_planning.scheduler import SceneWorld
        from hsi_retarget.sim_check import WorldConfig, build_world

        self.config = config
        self.spec = load_scene(config.scene)
        self.cloud = scene_cloud(config.scene, config.cloud_voxel)
        self._pipeline = PipelineConfig(
            robot=config.robot, planner=config.planner, checkpoint=config.checkpoint
        )
        self._world = SceneWorld(self.spec, self.cloud, CloudConfig(voxel_size=self._pipeline.voxel_size))
        self._sched = self._pipeline.scheduler_config()
        self.transport = InprocTransport()
        self.node = UiNode(self.transport)
        self.server = viser.ViserServer(host=config.host, port=config.port, label="HSI pick-and-place")
        self.port = int(self.server.get_port())
        idle = build_world(WorldConfig(scene=config.scene, robot=config.robot), self.spec)
        self.view = SceneView(self.server, idle, self.spec, self.cloud, config.max_cloud_points)
        self.server.initial_camera.position = (-0.9, -1.3, 2.3)
        self.server.initial_camera.look_at = (0.8, 0.1, 0.9)
        self.server.initial_camera.fov = float(np.radians(60.0))
        self._lock = threading.Lock()
        self._worker: threading.Thread | None = None
        self.target, self.pick_point, self.place = "", None, None  # type: tuple[str, F64 | None, F64 | None]
        self.outcomes: list[TaskOutcome] = []
        #: The last task's minimum-jerk comparison paths (empty until it is planned).
        self.minjerk_paths: list[MinJerkPath] = []
        self._frames: list[tuple[F64, F64]] = []
        self._build_gui(DEMO_PLANNERS)
        self.server.scene.on_click()(self._on_click)
        _log.info(
            "hsi ui: http://%s:%d (scene %s, robot %s)", config.host, self.port, config.scene, config.robot
        )

    # -------------------------------------------------------------------------------------- GUI

    def _build_gui(self, planners: Sequence[str]) -> None:
        gui = self.server.gui
        gui.add_markdown("**HSI** — click an object, then a place, then *Start task*.")
        self.status = gui.add_markdown("Click an object to pick.")
        self.selection = gui.add_markdown("target: —  \nplace: —")
        self.planner = gui.add_dropdown("Planner", tuple(planners), initial_value=self.config.planner)
        self.minjerk = gui.add_checkbox("Min-jerk comparison", initial_value=False)
        self.show_cloud = gui.add_checkbox("Show scene cloud", initial_value=True)
        self.start = gui.add_button("Start task")
        self.clear = gui.add_button("Clear selection")
        self.replay = gui.add_button("Replay motion")
        self.speeds = gui.add_image(np.full((8, 8, 3), 255, dtype=np.uint8), label="speed profiles")
        self.report = gui.add_markdown("No task run yet.")
        self.minjerk.on_update(lambda _: self.view.show_minjerk(self.minjerk.value))
        self.show_cloud.on_update(lambda _: setattr(self.view.cloud, "visible", self.show_cloud.value))
        self.start.on_click(self._on_start)
        self.clear.on_click(lambda _: self._clear())
        self.replay.on_click(self._on_replay)

    def _on_start(self, _: Any) -> None:
        self.start_task()

    def _on_replay(self, _: Any) -> None:
        self._start_thread(self._replay)

    def _say(self, text: str, error: bool = False) -> None:
        self.status.content = f"**Error:** {text}" if error else text
        (_log.warning if error else _log.info)("ui: %s", text)

    def _show_selection(self) -> None:
        place = "—" if self.place is None else ", ".join(f"{v:.2f}" for v in self.place)
        self.selection.content = f"target: {self.target or '—'}  \nplace: {place}"
        self.view.highlight(self.target)
        self.view.mark_place(self.place)

    def _clear(self) -> None:
        with self._lock:
            self.target, self.pick_point, self.place = "", None, None
        self._show_selection()
        self._say("Click an object to pick.")

    # ----------------------------------------------------------------------------------- clicks

    def _on_click(self, event: Any) -> None:
        point = self.view.hit(event.ray_origin, event.ray_direction)
        if point is None:
            self._say("the click hit nothing in the scene; click an object or a support surface", True)
            return
        self.click(point)

    def click(self, point: ArrayLike) -> None:
        """Handle a click on the scene surface at ``point`` (3,) [m]: publish it, then select the target or
        the placement (errors go to the status panel)."""
        from hsi_nodes.demo.pipeline import resolve_task
        from hsi_nodes.demo.tasks import DemoTask
        from hsi_planning.scheduler import PickGoal, resolve_click

        p = np.array(point, dtype=np.float64, copy=True)
        self.node.publish_click(p)
        try:
            goal = resolve_click(p, self.cloud, self.spec, self._sched.goals)
            if isinstance(goal, PickGoal):
                with self._lock:
                    self.target, self.pick_point, self.place = goal.object_name, p, None
                self._say(f"target **{goal.object_name}** selected; now click a free place on a surface")
            elif self.pick_point is None:
                raise PlanningError(
                    f"the click is on {goal.support!r} but no object is selected: click one first"
                )
            else:
                pick = tuple(float(v) for v in self.pick_point)
                probe = DemoTask("ui_probe", self.config.scene, place_click=(p[0], p[1], p[2]), click=pick)  # type: ignore[arg-type]
                request = resolve_task(probe, self._world, self._sched)
                assert request.place is not None
                with self._lock:
                    self.place = np.array(request.place, dtype=np.float64, copy=True)
                self._say(f"place on **{request.place_support}** selected; press *Start task*")
        except HsiError as exc:
            self._say(str(exc), True)
        if not self.busy:  # back to the rest state for the next task (unless one is being drawn live)
            self.view.reset()
        self._show_selection()

    # ------------------------------------------------------------------------------------ tasks

    @property
    def busy(self) -> bool:
        """True while a task (or a replay) runs."""
        return self._worker is not None and self._worker.is_alive()

    def _start_thread(self, fn: Any) -> bool:
        with self._lock:
            if self._worker is not None and self._worker.is_alive():
                self._say("a task is running; wait for it to finish", True)
                return False
            self._worker = threading.Thread(target=fn, name="hsi-ui-task", daemon=True)
            self._worker.start()
            return True

    def start_task(self) -> bool:
        """Start the selected task in the worker thread; False (with an error shown) when it cannot."""
        if self.pick_point is None or self.place is None:
            self._say("select an object and a place first", True)
            return False
        return self._start_thread(self._run)

    def _run(self) -> None:
        from hsi_nodes.demo.pipeline import make_demo_planner, run_task
        from hsi_nodes.demo.plots import tcp_paths
        from hsi_nodes.demo.tasks import DemoTask
        from hsi_nodes.ui.minjerk_overlay import RecordingPlanner

        assert self.pick_point is not None and self.place is not None
        planner_name = str(self.planner.value)
        self.start.disabled = True
        try:
            n = len(self.outcomes) + 1
            pick, place = self.pick_point.copy(), self.place.copy()
            self.node.publish_goal(f"ui_{n}", self.target, pick, place, planner=planner_name)
            self._say(f"task {n}: planning and executing **{self.target}** with `{planner_name}` ...")
            self.view.clear_plan()
            self.minjerk_paths = []
            planner = RecordingPlanner(make_demo_planner(planner_name, self.config.checkpoint))
            task = DemoTask(
                f"ui_{n}",
                self.config.scene,
                tuple(place),
                click=tuple(pick),
                description="clicked in the UI",  # type: ignore[arg-type]
            )
            cfg = dataclasses.replace(self._pipeline, planner=planner_name)
            self._frames = []
            outcome = run_task(
                task,
                self.spec,
                self.cloud,
                planner,
                cfg,
                on_world=self._on_world,
                on_schedule=self.view.draw_schedule,
            )
            self.outcomes.append(outcome)
            tcp_t, tcp = tcp_paths(outcome)
            self.view.draw_robot_paths(tcp)
            image = speed_image(outcome, tcp_t, tcp)
            if image is not None:
                self.speeds.image = image
            self.report.content = report_markdown(outcome)
            ok = outcome.report.success
            done = f"task {n} done: success" if ok else f"task {n} failed: {outcome.error or 'see report'}"
            self._say(done, not ok)
            if outcome.schedule is not None:
                self._compare(outcome.schedule, planner.calls, done, ok)
        except Exception as exc:  # any failure is shown in the UI, which keeps running
            _log.exception("ui task failed")
            self.report.content = f"**Task failed**: {type(exc).__name__}: {exc}"
            self._say(f"{type(exc).__name__}: {exc}", True)
        finally:
            self.start.disabled = False

    def _compare(
        self, schedule: Schedule, calls: list[tuple[PlanRequest, PlanResult]], done: str, ok: bool
    ) -> None:
        """Plan the minimum-jerk baseline of ``schedule``'s learned segments and draw it (shown when the
        toggle is on); its failures go to the report panel."""
        from hsi_nodes.ui.minjerk_overlay import minjerk_comparison

        self._say(f"{done}; planning the minimum-jerk comparison ...", not ok)
        paths, errors = minjerk_comparison(schedule, calls)
        self.minjerk_paths = paths
        self.view.draw_minjerk(paths, bool(self.minjerk.value))
        lines = [f"- min-jerk comparison: {len(paths)} of {len(schedule.segments)} segments"]
        lines += [f"- min-jerk failure: {e}" for e in errors[:4]]
        self.report.content = self.report.content + "\n" + "\n".join(lines)
        note = f"{len(errors)} failed, see report" if errors else "toggle it to compare"
        self._say(f"{done}; min-jerk comparison ready ({note})", not ok or bool(errors))

    def _on_world(self, world: SimWorld, target: str) -> Any:
        period, last = 1.0 / self.config.frame_rate, [0.0]

        def hook(w: SimWorld) -> None:
            now = time.perf_counter()
            if now - last[0] >= period:
                last[0] = now
                pos, mat = np.array(w.data.geom_xpos, copy=True), np.array(w.data.geom_xmat, copy=True)
                self._frames.append((pos, mat))
                self.view.update(pos, mat)

        return hook

    def _replay(self) -> None:
        frames = list(self._frames)
        if not frames:
            self._say("nothing to replay yet: run a task first", True)
            return
        for pos, mat in frames:
            self.view.update(pos, mat)
            time.sleep(1.0 / self.config.frame_rate)

    def wait(self, timeout_s: float) -> bool:
        """Wait for the running task; True when none is running afterwards."""
        worker = self._worker
        if worker is not None:
            worker.join(timeout_s)
        return not self.busy

    def screen_position(self, point: ArrayLike) -> tuple[float, float]:
        """(u, v) in [0, 1] where world ``point`` [m] appears in the first client's 3D view (test hook).

        Raises:
            HsiError: no browser is connected yet.
        """
        from hsi_nodes.ui.scene_view import project_to_screen

        clients = list(self.server.get_clients().values())
        if not clients:
            raise HsiError("no browser is connected to the UI")
        cam = clients[0].camera
        return project_to_screen(point, cam.position, cam.wxyz, cam.fov, cam.aspect)

    def close(self) -> None:
        """Stop the web server and the node."""
        self.server.stop()
        self.node.destroy()
