"""Suite-wide settings: headless rendering, shared paths, and no silent skips."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

os.environ.setdefault("MUJOCO_GL", "egl")

REPO = Path(__file__).resolve().parents[1]
HDM05 = REPO.parent / "shared" / "data" / "hdm05"


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo[None]):  # type: ignore[no-untyped-def]
    """A skipped test is not a pass: turn every skip into a failure that says why it skipped."""
    outcome = yield
    report = outcome.get_result()
    if report.skipped and not hasattr(report, "wasxfail"):
        report.outcome = "failed"
        reason = report.longrepr[2] if isinstance(report.longrepr, tuple) else report.longrepr
        report.longrepr = f"test skipped, which counts as a failure here: {reason}"


@pytest.fixture(scope="session")
def repo_root() -> Path:
    return REPO


@pytest.fixture(scope="session")
def hdm05_dir() -> Path:
    if not HDM05.is_dir():
        raise FileNotFoundError(f"HDM05 clips expected at {HDM05} (the shared data folder beside the repo)")
    return HDM05
