"""MJCF additions of the execution check: a TCP probe sphere per hand and the inactive grasp welds.

Per hand, an invisible sphere without collisions sits at the TCP site (``<hand>_tcp_probe``, for distance
queries), and one inactive ``equality weld`` joins the hand's gripper link to every graspable body (free
objects, doors, drawers), named ``grasp:<hand>:<body>``; :mod:`hsi_retarget.sim_check.grasp` sets its
relative pose and switches it on. For the doors and drawers named as ``pivots`` there are also two inactive
``equality connect`` constraints per hand (``grasp:<hand>:<body>:pivot<k>``), which together hold the
handle bar in the gripper but let it turn about its own axis (:mod:`hsi_retarget.sim_check.handle_grip`).
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from collections.abc import Sequence

from hsi_planning.errors import SceneError
from hsi_retarget.robots import RobotModel

HANDS = ("left", "right")
_PROBE_RADIUS = 0.002  #: TCP probe sphere radius [m]


def weld_name(hand: str, body: str) -> str:
    """Name of the grasp weld between ``hand``'s gripper and scene body ``body``."""
    return f"grasp:{hand}:{body}"


def pivot_name(hand: str, body: str, k: int) -> str:
    """Name of the ``k``-th (0 or 1) handle pivot constraint between ``hand``'s gripper and part ``body``."""
    return f"{weld_name(hand, body)}:pivot{k}"


def add_probes_and_welds(
    xml: str,
    robot: RobotModel,
    targets: list[str],
    solref: tuple[float, float],
    pivots: Sequence[str] = (),
) -> str:
    """``xml`` (a scene with ``robot`` attached, no prefix) plus TCP probes and grasp welds to ``targets``
    (body names), and handle pivot pairs to the ``pivots`` (part body names); ``solref``: their time
    constant [s] and damping ratio [-].

    Raises:
        SceneError: the TCP sites are missing.
    """
    root = ET.fromstring(xml)
    parents = {child: parent for parent in root.iter() for child in parent}
    sites = {el.get("name"): el for el in root.iter("site")}
    for hand in HANDS:
        site = sites.get(robot.tcp_frames[hand])
        if site is None:
            raise SceneError(f"merged MJCF has no TCP site {robot.tcp_frames[hand]!r}")
        probe = ET.SubElement(parents[site], "geom")
        probe.attrib.update(
            name=f"{hand}_tcp_probe",
            type="sphere",
            size=str(_PROBE_RADIUS),
            pos=site.get("pos", "0 0 0"),
            contype="0",
            conaffinity="0",
            group="5",
            density="0",
            rgba="0 0 0 0",
        )
    equality = root.find("equality")
    if equality is None:
        equality = ET.SubElement(root, "equality")
    frame_links = {f.name: f.link for f in robot.description.frames}
    for hand in HANDS:
        for body in targets:
            weld = ET.SubElement(equality, "weld")
            weld.attrib.update(
                name=weld_name(hand, body),
                body1=frame_links[robot.tcp_frames[hand]],
                body2=body,
                active="false",
                solref=f"{solref[0]} {solref[1]}",
            )
        for body in pivots:
            for k in (0, 1):
                pin = ET.SubElement(equality, "connect")
                pin.attrib.update(
                    name=pivot_name(hand, body, k),
                    body1=frame_links[robot.tcp_frames[hand]],
                    body2=body,
                    anchor="0 0 0",
                    active="false",
                    solref=f"{solref[0]} {solref[1]}",
                )
    return ET.tostring(root, encoding="unicode")
