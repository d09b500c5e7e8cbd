"""Camera paths designed as a walk through the *world*, converted to the path the real systems replay.

A :class:`systems.camera_path.CameraPath` is replayed as local moves at
perceived speed: inside an aberration the camera covers ``s`` times the
distance (docs/semantics.md, "The camera's walk") and after a portal it carries on relative to
its new pose. So a path written in world coordinates would drift off course
after the first aberration or portal. :func:`route` takes the stops of the
intended walk in world coordinates (on whichever side of a portal the camera
is by then) and builds the path in *perceived* coordinates: each straight leg
is split at the box faces it crosses and every piece is divided by its box's
scale; a leg marked ``via`` a portal is split where it passes through the
quad, and the rest of the walk turns with the portal's rotation. The walk the
systems then make passes through the stops (exactly on straight legs, within
the rounding of the spline at corners).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from engine.errors import AberrantError
from engine.scene import Scene
from systems.camera_movement import SpeedBox, active_box, first_face_crossing, speed_boxes
from systems.camera_path import CameraPath, Keyframe
from systems.portal_teleport import PortalLink, portal_links, segment_crossing

#: Walking pace (perceived units per second) and turning rate (degrees per second) of the stops' timing.
PACE = 2.0
TURN_RATE = 50.0
#: Length of a leg's straight lead-in and lead-out (see :func:`route`).
LEAD = 0.8


@dataclass(frozen=True)
class Stop:
    """A point of the walk (world coordinates), the point looked at there, and the portal walked through to it."""

    position: Sequence[float]
    look_at: Sequence[float]
    via: str | None = None
    pace: float = PACE


def perceived(boxes: Sequence[SpeedBox], start: np.ndarray, end: np.ndarray) -> np.ndarray:
    """The perceived displacement that walks the straight world segment ``start``..``end`` (world frame)."""
    out = np.zeros(3)
    position = np.asarray(start, dtype=np.float64)
    end = np.asarray(end, dtype=np.float64)
    for _ in range(256):
        t = first_face_crossing(boxes, position, end - position)
        stop = end if t is None else position + t * (end - position)
        box = active_box(boxes, 0.5 * (position + stop))
        delta = stop - position
        out += delta if box is None else box.axes @ ((box.axes.T @ delta) / box.scale)
        if t is None:
            return out
        position = stop
    raise AberrantError("a route leg crosses too many aberration faces")


def walk_leg(
    boxes: Sequence[SpeedBox], frame: np.ndarray, start: np.ndarray, end: np.ndarray, via: PortalLink | None = None
) -> tuple[np.ndarray, np.ndarray] | None:
    """The path step (path frame) that walks straight from world ``start`` to ``end``, and the frame after it.

    ``frame`` turns world deltas into path deltas. With ``via``, ``end`` lies beyond that portal: the walk
    goes to ``end`` as seen from this side, through the quad, and the frame turns with the portal's
    rotation; ``None`` when that straight walk misses the quad.
    """
    if via is None:
        return frame @ perceived(boxes, start, end), frame
    inverse = np.linalg.inv(via.transfer)
    virtual = inverse[:3, :3] @ end + inverse[:3, 3]  # ``end`` as seen from this side of the portal
    t = segment_crossing(via, start, virtual)
    if t is None:
        return None
    crossing = start + t * (virtual - start)
    step = frame @ perceived(boxes, start, crossing)
    frame = frame @ via.rotation.T
    return step + frame @ perceived(boxes, via.map_point(crossing), end), frame


def _angle_deg(a: np.ndarray, b: np.ndarray) -> float:
    cos = float(np.dot(a, b) / (np.linalg.norm(a) * np.linalg.norm(b)))
    return math.degrees(math.acos(min(1.0, max(-1.0, cos))))


def route(scene: Scene, stops: Sequence[Stop], *, hold: float = 0.6) -> CameraPath:
    """The camera path that walks ``stops`` through ``scene``'s aberrations and portals.

    ``hold``: seconds to stand still at the start, so a flythrough opens on the level's own view.
    """
    if len(stops) < 2:
        raise AberrantError("a route needs at least two stops")
    boxes = speed_boxes(scene)
    links = {link.entity: link for link in portal_links(scene)}
    frame = np.eye(3)  # world deltas (where the camera is now) -> path deltas
    first = stops[0]
    position = np.asarray(first.position, dtype=np.float64)
    look = frame @ (np.asarray(first.look_at, dtype=np.float64) - position)
    keys = [Keyframe(0.0, tuple(position), look_at=tuple(position + look))]
    time = 0.0
    if hold > 0.0:
        time = hold
        keys.append(Keyframe(time, tuple(position), look_at=tuple(position + look)))
    previous = position
    for index, stop in enumerate(stops[1:], start=1):
        here = np.asarray(stop.position, dtype=np.float64)
        link = None
        if stop.via is not None:
            link = links.get(scene.entity(stop.via))
            if link is None:
                raise AberrantError(f"route stop {index}: {stop.via!r} is not a linked portal")
        leg = walk_leg(boxes, frame, previous, here, link)
        if leg is None:
            raise AberrantError(f"route stop {index}: the straight walk to it does not pass through {stop.via!r}")
        step, frame = leg
        new_look = frame @ (np.asarray(stop.look_at, dtype=np.float64) - here)
        distance = float(np.linalg.norm(step))
        duration = max(distance / stop.pace, _angle_deg(look, new_look) / TURN_RATE, 0.25)
        if distance > 1e-9:
            # Keys just after the start and just before the end of the leg hold the spline on the straight
            # line: it only rounds the corners (within LEAD of a stop), never bulges sideways out of a tunnel.
            f = min(0.25, LEAD / distance)
            lead = position + f * step
            keys.append(Keyframe(time + f * duration, tuple(lead), look_at=tuple(lead + look)))
            end = position + (1.0 - f) * step
            keys.append(Keyframe(time + (1.0 - f) * duration, tuple(end), look_at=tuple(end + new_look)))
        time += duration
        position = position + step
        look = new_look
        keys.append(Keyframe(time, tuple(position), look_at=tuple(position + look)))
        previous = here
    return CameraPath(keys)


def with_scene(build: Callable[[], Scene], stops: Sequence[Stop], *, hold: float = 0.6) -> CameraPath:
    """:func:`route` on a freshly built scene (closed afterwards): what a demo's ``camera_path()`` returns."""
    scene = build()
    try:
        return route(scene, stops, hold=hold)
    finally:
        scene.close()
