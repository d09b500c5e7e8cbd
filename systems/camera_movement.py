"""Camera movement: input to perceived velocity, mouse look, and a walk scaled by aberrations.

The first system of a tick (docs/design.md section 6). The camera's perceived velocity ``v`` becomes the
world displacement ``R (s ⊙ (Rᵀ v))·dt`` inside the aberration active at the
camera (``s = 1 + D``), the same rule rays follow, so what you see is where
you go. The walk is split into sub-steps at every box face it crosses, so a
box thinner than one tick's step still scales exactly the part of the tick
spent inside it. Each step looks only at the boxes whose bounds hold its point
or meet its segment (:class:`SpeedBoxes`, through
:class:`engine.space_index.SpaceIndex`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import esper
import numpy as np

from components import Aberration, Camera, Transform
from engine.input import InputSource, InputState
from engine.maths import ArrayLike, quat_from_axis_angle, quat_multiply, quat_normalize, quat_to_matrix, trs_inverse
from engine.scene import Scene
from engine.space_index import SpaceIndex
from systems.state import MotionRecord

#: Speed factor while the sprint input is held.
SPRINT_MULTIPLIER = 2.0
#: Mouse look never tilts the view further than this from the horizon (degrees).
PITCH_LIMIT_DEG = 89.0
#: At most this many aberration-face sub-steps per tick; the rest of the tick moves without re-checking.
MAX_SUBSTEPS = 32
#: Radial/additive deformations are not limited to D > -1; their speed scale is floored here so the
#: camera never stops or walks backwards inside such a box.
MIN_SPEED_SCALE = 0.05
#: Relative tolerance (of the coordinate magnitude) for "on a face" and for stepping just past one.
FACE_EPS = 1e-11


@dataclass(frozen=True)
class SpeedBox:
    """An aberration box as the camera sees it: where it is and how it scales speed."""

    entity: int
    priority: int
    to_local: np.ndarray  # (4, 4): world -> the unit cube [-1/2, 1/2]^3
    axes: np.ndarray  # (3, 3): columns are the axes speed is scaled along
    scale: np.ndarray  # (3,): s, the per-axis speed factor

    def contains(self, point: np.ndarray) -> bool:
        local = self.to_local[:3, :3] @ point + self.to_local[:3, 3]
        return bool(np.all(np.abs(local) <= 0.5))

    def velocity(self, v: np.ndarray) -> np.ndarray:
        """World velocity for perceived velocity ``v`` inside this box."""
        return self.axes @ (self.scale * (self.axes.T @ v))


def speed_box(entity: int, transform: Transform, aberration: Aberration) -> SpeedBox:
    """The speed rule of one aberration entity.

    Metric boxes scale along their own rotated axes (scale ignored), as rays
    do. Radial and additive deformations are world-axis vectors (docs/semantics.md
    rule 8), so their boxes scale speed along the world axes.
    """
    s = 1.0 + np.asarray(aberration.deformation, dtype=np.float64)
    if aberration.mode == "metric":
        axes = quat_to_matrix(transform.rotation)
    else:
        axes = np.eye(3)
        s = np.maximum(s, MIN_SPEED_SCALE)
    to_local = trs_inverse(transform.position, transform.rotation, transform.scale)
    return SpeedBox(entity, aberration.priority, to_local, axes, s)


def speed_boxes(scene: Scene) -> list[SpeedBox]:
    """Every aberration box, lowest precedence first (priority, then creation order)."""
    boxes = [speed_box(entity, t, a) for entity, (t, a) in scene.query(Transform, Aberration)]
    return sorted(boxes, key=lambda b: (b.priority, b.entity))


class SpeedBoxes:
    """The scene's speed boxes near a point or a segment: those whose bounds hold or meet it (a
    :class:`engine.space_index.SpaceIndex` query), lowest precedence first as :func:`speed_boxes` has them.
    A box's speed rule is made again only when its entity changed."""

    def __init__(self, scene: Scene, index: SpaceIndex | None = None) -> None:
        self.scene = scene
        self.index = index or SpaceIndex()
        self._boxes: dict[int, tuple[object, SpeedBox]] = {}

    def sync(self) -> SpeedBoxes:
        self.index.sync(self.scene)
        return self

    def __len__(self) -> int:
        return self.index.box_count

    def at(self, point: np.ndarray) -> list[SpeedBox]:
        return self._rules(self.index.boxes_at(point))

    def on_segment(self, start: np.ndarray, end: np.ndarray) -> list[SpeedBox]:
        return self._rules(self.index.boxes_on_segment(start, end))

    def _rules(self, entities: list[int]) -> list[SpeedBox]:
        boxes = []
        for entity in entities:
            key = self.index.version(entity)
            cached = self._boxes.get(entity)
            if cached is None or cached[0] != key:
                scene = self.scene
                cached = (key, speed_box(entity, scene.get(entity, Transform), scene.get(entity, Aberration)))
                self._boxes[entity] = cached
            boxes.append(cached[1])
        return sorted(boxes, key=lambda b: (b.priority, b.entity))


Boxes = Sequence[SpeedBox] | SpeedBoxes


def active_box(boxes: Boxes, point: np.ndarray) -> SpeedBox | None:
    """The containing box with the highest priority (ties: the later entity), or ``None``."""
    near = boxes.at(point) if isinstance(boxes, SpeedBoxes) else boxes
    for box in reversed(near):
        if box.contains(point):
            return box
    return None


def _eps(point: np.ndarray) -> float:
    return FACE_EPS * (1.0 + float(np.max(np.abs(point))))


def first_face_crossing(boxes: Boxes, start: np.ndarray, delta: np.ndarray) -> float | None:
    """Smallest parameter ``t`` in (0, 1) where ``start + t·delta`` crosses any box face.

    Faces within a tolerance of ``start`` are ignored: that is the face the
    walk stopped on, already accounted for.
    """
    length = float(np.linalg.norm(delta))
    if length == 0.0:
        return None
    t_min = _eps(start) / length
    best: float | None = None
    near = boxes.on_segment(start, start + delta) if isinstance(boxes, SpeedBoxes) else boxes
    for box in near:
        a = box.to_local[:3, :3] @ start + box.to_local[:3, 3]
        b = box.to_local[:3, :3] @ delta
        t_near, t_far = -math.inf, math.inf
        for k in range(3):
            if b[k] == 0.0:
                if abs(a[k]) > 0.5:
                    t_near, t_far = math.inf, -math.inf
                    break
                continue
            t1 = (-0.5 - a[k]) / b[k]
            t2 = (0.5 - a[k]) / b[k]
            t_near = max(t_near, min(t1, t2))
            t_far = min(t_far, max(t1, t2))
        if t_near > t_far:
            continue
        for t in (t_near, t_far):
            if t_min < t < 1.0 and (best is None or t < best):
                best = t
    return best


def walk(
    boxes: Boxes, start: np.ndarray, v: np.ndarray, dt: float, max_substeps: int = MAX_SUBSTEPS
) -> list[np.ndarray]:
    """The camera's path for one tick: perceived velocity ``v`` for ``dt`` seconds of perceived time.

    Returns the polyline ``[start, face points..., end]``. At each face the
    active box is re-evaluated just past it (along the current direction) and
    the walk goes on with the remaining perceived time.
    """
    position = np.asarray(start, dtype=np.float64).copy()
    path = [position.copy()]
    if dt <= 0.0 or not np.any(v):
        return path
    if not boxes:
        path.append(position + v * dt)
        return path
    time_left = float(dt)
    heading = v / np.linalg.norm(v)
    for _ in range(max_substeps):
        box = active_box(boxes, position + heading * _eps(position))
        u = v if box is None else box.velocity(v)
        delta = u * time_left
        t = first_face_crossing(boxes, position, delta)
        if t is None:
            path.append(position + delta)
            return path
        position = position + delta * t
        path.append(position.copy())
        time_left *= 1.0 - t
        heading = u / np.linalg.norm(u)
    box = active_box(boxes, position + heading * _eps(position))
    path.append(position + (v if box is None else box.velocity(v)) * time_left)
    return path


def apply_look(rotation: Sequence[float], yaw_deg: float, pitch_deg: float) -> np.ndarray:
    """Mouse look: yaw about world +Y, pitch about the camera's local +X, pitch kept within ±89°.

    The pitch is measured in the plane the pitch rotation sweeps (forward and
    up), so the clamp is exact for an unrolled camera and still bounded for
    a rolled one; a camera already beyond the limit may only come back.
    """
    q = np.asarray(rotation, dtype=np.float64)
    if yaw_deg:
        q = quat_multiply(quat_from_axis_angle((0.0, 1.0, 0.0), math.radians(yaw_deg)), q)
    if pitch_deg:
        m = quat_to_matrix(q)
        forward_y, up_y = -m[1, 2], m[1, 1]
        current = math.degrees(math.atan2(forward_y, up_y))
        low, high = min(-PITCH_LIMIT_DEG, current), max(PITCH_LIMIT_DEG, current)
        delta = min(max(current + pitch_deg, low), high) - current
        if delta:
            q = quat_multiply(q, quat_from_axis_angle((1.0, 0.0, 0.0), math.radians(delta)))
    return quat_normalize(q)


def perceived_velocity(rotation: ArrayLike, move: Sequence[float], speed: float, multiplier: float) -> np.ndarray:
    """``speed × multiplier × R_cam · normalize(move)`` (zero when there is no move input)."""
    m = np.asarray(move, dtype=np.float64)
    n = float(np.linalg.norm(m))
    if n < 1e-12:
        return np.zeros(3)
    return speed * multiplier * (quat_to_matrix(rotation) @ (m / n))


class CameraMovementProcessor(esper.Processor):
    """Moves the scene's camera from one input state per tick, and records the path for teleport."""

    def __init__(
        self,
        scene: Scene,
        input_source: InputSource,
        motion: MotionRecord,
        sprint_multiplier: float = SPRINT_MULTIPLIER,
        max_substeps: int = MAX_SUBSTEPS,
        index: SpaceIndex | None = None,
    ) -> None:
        self.scene = scene
        self.boxes = SpeedBoxes(scene, index)
        self.input_source = input_source
        self.motion = motion
        self.sprint_multiplier = sprint_multiplier
        self.max_substeps = max_substeps
        self.last_input: InputState | None = None

    def process(self, dt: float) -> None:
        self.motion.begin_tick()
        state = self.input_source.poll(dt)
        self.last_input = state
        entity = self.scene.camera_entity
        if entity is None or state.idle:
            return
        transform = self.scene.get(entity, Transform)
        camera = self.scene.get(entity, Camera)
        rotation = apply_look(transform.rotation, *state.look)
        multiplier = self.sprint_multiplier if state.sprint else 1.0
        speed = camera.speed if state.speed is None else state.speed
        v = perceived_velocity(rotation, state.move, speed, multiplier)
        position = np.asarray(transform.position, dtype=np.float64)
        if np.any(v) and dt > 0.0:
            path = walk(self.boxes.sync(), position, v, dt, self.max_substeps)
            self.motion.path = path
            position = path[-1]
        self.scene.set(
            entity,
            Transform(
                tuple(float(c) for c in position),
                tuple(float(c) for c in rotation),
                transform.scale,
            ),
        )
