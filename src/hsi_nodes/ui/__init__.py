"""The web UI for clicked goals (``hsi ui``): a viser view of the scene and robot where a person clicks an
object and a place and watches the robot do the task (:mod:`.app`, :mod:`.ui_config`, :mod:`.scene_view`,
:mod:`.minjerk_overlay`, :mod:`.report_panel`, :mod:`.ui_node`).

Importing the package selects a headless MuJoCo OpenGL backend (the UI renders the scene cloud) before
:mod:`.scene_view` imports ``mujoco``.
"""

from hsi_planning.gl import ensure_headless_gl

ensure_headless_gl()
