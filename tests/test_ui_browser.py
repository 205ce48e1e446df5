"""Browser test of ``hsi ui``: Playwright drives Debian's headless Chromium against the viser UI.

The page is loaded, the can on the counter is clicked in the 3D view (the canvas pixel where the camera
the browser reports sees it), then a free spot on the counter, then *Start task*; the test waits for
success in the report panel, checks the published ``/clicked_point`` and ``/hsi/goal`` messages, and
saves a screenshot that must not be blank; the minimum-jerk comparison (the real baseline, planned on the
learned segments' requests) is toggled on in the browser and must differ from the learned paths while
sharing their end points. Runs in the fast mode (reach-model planner).
"""

from __future__ import annotations

import io
import os
import socket
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from PIL import Image

from hsi_nodes.ui.app import SUCCESS_TEXT, UiApp, UiConfig
from hsi_nodes.ui.minjerk_overlay import minjerk_comparison
from hsi_nodes.ui.scene_view import project_to_screen
from hsi_nodes.ui.ui_node import CLICK_TYPE, GOAL_TYPE

CHROMIUM = "/usr/bin/chromium"
CHROMIUM_ARGS = [
    "--headless",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]
CAN = (0.9, 0.3, 1.02)  # [m] a point on can1 on the counter (the demo's test task)
PLACE = (0.75, -0.2, 0.9)  # [m] a free spot on the counter top


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def test_project_to_screen() -> None:
    # camera at the origin looking along +x (OpenCV: z forward = world x, y down = world -z)
    rot = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])  # columns: cam x, y, z in world
    w = 0.5 * np.sqrt(1.0 + np.trace(rot))
    wxyz = np.array(
        [
            w,
            (rot[2, 1] - rot[1, 2]) / (4 * w),
            (rot[0, 2] - rot[2, 0]) / (4 * w),
            (rot[1, 0] - rot[0, 1]) / (4 * w),
        ]
    )
    u, v = project_to_screen((2.0, 0.0, 0.0), np.zeros(3), wxyz, np.radians(60.0), 1.5)
    assert (u, v) == pytest.approx((0.5, 0.5))
    u, v = project_to_screen((2.0, -0.5, 0.5), np.zeros(3), wxyz, np.radians(60.0), 1.5)
    assert u > 0.5 and v < 0.5  # right of and above the centre


@pytest.fixture(scope="module")
def app() -> Iterator[UiApp]:
    ui = UiApp(UiConfig(scene="kitchen", robot="dual_arm", port=_free_port(), fast=True, frame_rate=5.0))
    yield ui
    ui.close()


def _click_at(page: Any, ui: UiApp, point: tuple[float, float, float]) -> None:
    box = page.locator("canvas").first.bounding_box()
    assert box is not None and box["width"] > 100
    u, v = ui.screen_position(point)
    assert 0.05 < u < 0.7 and 0.05 < v < 0.95, (u, v)  # the control panel covers the right side
    page.mouse.click(box["x"] + u * box["width"], box["y"] + v * box["height"])


def _wait(pred: Any, timeout_s: float, page: Any) -> None:
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if pred():
            return
        page.wait_for_timeout(100)
    raise AssertionError("timed out")


def test_browser_click_pick_place(app: UiApp, tmp_path: Path) -> None:
    from playwright.sync_api import sync_playwright

    received: list[tuple[str, Any]] = []
    app.transport.subscribe("/clicked_point", CLICK_TYPE, lambda m: received.append(("click", m)))
    app.transport.subscribe("/hsi/goal", GOAL_TYPE, lambda m: received.append(("goal", m)))
    with sync_playwright() as pw:
        browser = pw.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        page = browser.new_page(viewport={"width": 1024, "height": 660})
        page.goto(f"http://127.0.0.1:{app.port}/", wait_until="load")
        page.wait_for_selector("canvas", timeout=30_000)
        _wait(lambda: "Start task" in page.inner_text("body"), 30.0, page)
        _wait(lambda: bool(app.server.get_clients()), 20.0, page)
        client = next(iter(app.server.get_clients().values()))
        _wait(lambda: client.camera.update_timestamp > 0.0, 20.0, page)
        page.wait_for_timeout(500)  # the scene arrives

        _click_at(page, app, CAN)
        _wait(lambda: app.target != "", 15.0, page)
        assert app.target == "can1"
        _wait(lambda: "target: can1" in page.inner_text("body"), 10.0, page)

        _click_at(page, app, PLACE)
        _wait(lambda: app.place is not None, 15.0, page)
        assert app.place is not None and np.linalg.norm(app.place[:2] - np.array(PLACE[:2])) < 0.05

        page.get_by_role("button", name="Start task").click()
        _wait(lambda: app.busy or bool(app.outcomes), 10.0, page)
        assert app.outcomes or not app.start_task()  # one task at a time; the UI says so
        _wait(lambda: SUCCESS_TEXT in page.inner_text("body"), 60.0, page)
        assert app.wait(60.0)  # the min-jerk comparison is planned after the task
        assert not app.view.minjerk_handles[0].visible
        page.get_by_text("Min-jerk comparison", exact=True).click()
        _wait(lambda: bool(app.minjerk.value), 10.0, page)
        close = page.locator("button.mantine-Notification-closeButton")
        if close.count():  # the "software WebGL" notice of headless Chromium
            close.first.click()
        page.wait_for_timeout(500)
        png = page.screenshot()
        browser.close()

    outcome = app.outcomes[-1]
    assert outcome.report.success and outcome.report.placement_error_m is not None
    assert outcome.report.placement_error_m < 0.02
    _check_minjerk(app)
    for sub in app.transport.subscriptions():
        sub.dispatch(100)
    kinds = [k for k, _ in received]
    assert kinds.count("click") == 2 and kinds.count("goal") == 1
    goal = next(m for k, m in received if k == "goal")
    assert goal.object_name == "can1" and goal.has_place and goal.planner == "reach_model"
    image = np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=np.float64)
    assert image.shape[:2] == (660, 1024) and image.std() > 10.0
    shot = Path(os.environ.get("HSI_UI_SCREENSHOT", str(tmp_path / "ui.png")))
    shot.write_bytes(png)


def test_click_errors_and_config(app: UiApp) -> None:
    from hsi_planning.errors import ConfigError

    app.click(PLACE)  # a place with no object selected: an error in the status panel, nothing selected
    assert app.target == "" or app.place is not None
    app._clear()
    app.click(PLACE)
    assert "Error" in app.status.content and "no object is selected" in app.status.content
    assert app.target == "" and app.place is None
    app.click((0.0, 1.0, 0.0))  # the floor
    assert "Error" in app.status.content and "floor" in app.status.content
    assert not app.start_task() and "select an object and a place first" in app.status.content
    assert app.view.hit((-1.0, 0.3, 1.02), (1.0, 0.0, 0.0)) is not None  # the can's side
    assert app.view.hit((0.0, 0.0, 3.0), (0.0, 0.0, 1.0)) is None  # the sky
    with pytest.raises(ConfigError, match="available"):
        UiConfig(planner="teleport")
    with pytest.raises(ConfigError, match="port"):
        UiConfig(port=70000)
    assert UiConfig(fast=True, planner="implicit").planner == "reach_model"
    assert UiConfig(robot="dual_arm").robot == "dual_ur5e"


def test_cli_parser() -> None:
    import argparse

    from hsi_nodes.cli import ui as ui_cli

    parser = argparse.ArgumentParser()
    ui_cli.register(parser.add_subparsers())
    args = parser.parse_args(["ui", "--robot", "humanoid", "--port", "8123", "--fast"])
    assert (args.robot, args.port, args.fast, args.host, args.scene) == (
        "humanoid",
        8123,
        True,
        "127.0.0.1",
        "kitchen",
    )


def _resampled(path: np.ndarray, n: int = 100) -> np.ndarray:
    s = np.linspace(0.0, 1.0, path.shape[0])
    u = np.linspace(0.0, 1.0, n)
    return np.stack([np.interp(u, s, path[:, k]) for k in range(3)], axis=1)


def _check_minjerk(app: UiApp) -> None:
    schedule = app.outcomes[-1].schedule
    assert schedule is not None
    n_seg = len(schedule.segments)
    assert len(app.minjerk_paths) == n_seg >= 2 and f"min-jerk comparison: {n_seg} of {n_seg}" in (
        app.report.content
    )
    handles = app.view.minjerk_handles
    assert len(handles) == n_seg and all(h.visible for h in handles)  # toggled on in the browser
    deviations = []
    for path in app.minjerk_paths:
        learned = schedule.segments[path.index].trajectory.position
        assert np.array_equal(path.learned, learned)
        # same end poses (the learned contact and retreat), a different path in between
        assert np.linalg.norm(path.position[0] - learned[0]) < 1e-3
        assert np.linalg.norm(path.position[-1] - learned[-1]) < 1e-3
        gap = np.linalg.norm(_resampled(path.position) - _resampled(learned), axis=1)
        deviations.append(float(gap.max()))
    assert max(deviations) > 0.005, deviations
    paths, errors = minjerk_comparison(schedule, [])  # nothing recorded: every segment is an error
    assert paths == [] and len(errors) == n_seg and "no recorded learned plan" in errors[0]
