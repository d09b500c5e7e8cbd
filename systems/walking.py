"""Walking: gravity, eye height and collision for the scene's camera, probed by rays through the scene as seen.

The player's walk mode. Every probe is a short ray traced from the eye by the
reference tracer on the packed scene, so it bends in aberrations and passes
through portals exactly as the camera's own rays do: a wall seen through a
portal stops you, and a compressed corridor is as short to walk as it looks.
Distances are perceived lengths (``Λ``), the unit the camera moves in
(docs/semantics.md section 4), and every move goes through the camera's own
:func:`systems.camera_movement.walk` and :func:`systems.portal_teleport.teleport_path`.

A tick: turn (mouse or arrow keys), then move horizontally as far as the
body probes allow (rays from the eye to points ``radius`` beyond the step, at
heights from ``step_height`` over the feet up to the eye: a lower obstacle is
a step, not a wall; blocked, it slides along the world axes), then fall
under gravity or stand: the ray straight down from the eye puts the feet on
whatever is below, up a step or down one of at most ``step_height``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.reference.backend import ReferenceBackend
from backends.upload import SceneUploader
from components import Camera, Transform
from engine.input import InputState
from engine.maths import quat_from_matrix, quat_to_matrix
from engine.scene import Scene
from systems.camera_movement import SPRINT_MULTIPLIER, apply_look, speed_boxes, walk
from systems.portal_teleport import portal_links, teleport_path

#: World "down" (gravity stays world -Y after a portal turns the camera).
DOWN = np.array([0.0, -1.0, 0.0])


@dataclass(frozen=True)
class Body:
    """The walker's size and physics, in perceived units (metres, seconds)."""

    eye_height: float = 1.6
    radius: float = 0.3
    #: Obstacles up to this high over the feet are stepped onto; drops up to this are stepped down.
    step_height: float = 0.4
    gravity: float = 9.81
    #: Fastest fall (a long drop does not tunnel through a floor in one tick).
    max_fall_speed: float = 40.0
    #: Probe rays per horizontal move, from ``step_height`` over the feet up to the eye.
    probes: int = 4


class Probe:
    """Perceived distances to the nearest mesh along rays from one point, through the scene as it is now."""

    def __init__(self, scene: Scene) -> None:
        self.scene = scene
        self.backend = ReferenceBackend()
        self.uploader = SceneUploader(self.backend)
        #: Rays traced so far (tests read how much probing a tick costs).
        self.rays = 0

    def distances(self, origin: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """``Λ`` to the first mesh along each unit direction (``inf`` where none is hit)."""
        self.uploader.sync(self.scene, origin)
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        result = self.backend.trace_rays(origin, d / np.linalg.norm(d, axis=1, keepdims=True))
        self.rays += len(d)
        return np.where(result.instance >= 0, result.perceived, np.inf)

    def close(self) -> None:
        self.backend.release()


@dataclass
class Walker:
    """The camera's walking state between ticks; :meth:`step` runs one tick."""

    scene: Scene
    body: Body
    probe: Probe
    vertical_speed: float = 0.0
    on_ground: bool = False

    @classmethod
    def of(cls, scene: Scene, body: Body | None = None) -> Walker:
        return cls(scene, body or Body(), Probe(scene))

    def ground_below(self) -> bool:
        """Whether the ray straight down from the eye meets a mesh (else walking would fall for ever)."""
        entity = self.scene.camera_entity
        if entity is None:
            return False
        eye = np.asarray(self.scene.get(entity, Transform).position, dtype=np.float64)
        return bool(np.isfinite(self.probe.distances(eye, DOWN[None])[0]))

    def step(self, dt: float, state: InputState) -> None:
        """Turn, walk and fall for ``dt`` seconds of ``state``'s input."""
        entity = self.scene.camera_entity
        if entity is None or dt <= 0.0:
            return
        transform = self.scene.get(entity, Transform)
        rotation = quat_to_matrix(apply_look(transform.rotation, *state.look))
        position = np.asarray(transform.position, dtype=np.float64)
        speed = self.scene.get(entity, Camera).speed if state.speed is None else state.speed
        along = horizontal(rotation, state.move) * speed * (SPRINT_MULTIPLIER if state.sprint else 1.0) * dt
        if np.any(along):
            position, rotation = self._move(position, rotation, self._allowed(position, along))
        position, rotation = self._fall(position, rotation, dt)
        quat = quat_from_matrix(rotation)
        self.scene.set(
            entity, Transform(tuple(float(c) for c in position), tuple(float(c) for c in quat), transform.scale)
        )

    # --- horizontal -------------------------------------------------------------------------

    def _allowed(self, eye: np.ndarray, along: np.ndarray) -> np.ndarray:
        """The longest part of the move ``along`` (or of its x or z part, sliding on a wall) the probes allow."""
        candidates = [along, along * (1.0, 0.0, 0.0), along * (0.0, 0.0, 1.0)]
        candidates = [c for c in candidates if np.linalg.norm(c) > 1e-12]
        body = self.body
        drops = np.linspace(body.eye_height - body.step_height, 0.0, body.probes)
        rays, reach = [], []
        for c in candidates:
            length = float(np.linalg.norm(c))
            u = c / length
            for drop in drops:
                ray = u * (length + body.radius) + DOWN * drop
                rays.append(ray)
                reach.append(length + body.radius)
        rays_arr = np.array(rays)
        lengths = np.linalg.norm(rays_arr, axis=1)
        hits = self.probe.distances(eye, rays_arr)
        # Blocked at perceived distance Λ along a slanted ray: the body may go that far forward, less its radius.
        forward = np.where(hits < lengths, hits * np.array(reach) / lengths - body.radius, np.inf)
        best, best_length = np.zeros(3), 0.0
        for i, c in enumerate(candidates):
            length = float(np.linalg.norm(c))
            free = float(np.min(forward[i * len(drops) : (i + 1) * len(drops)]))
            go = max(0.0, min(length, free))
            if go >= length:
                return c
            if go > best_length + 1e-9:
                best, best_length = c * (go / length), go
        return best

    def _move(self, position: np.ndarray, rotation: np.ndarray, delta: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Walk the perceived displacement ``delta`` through aberrations and portals, as the camera walks."""
        if not np.any(delta):
            return position, rotation
        path = walk(speed_boxes(self.scene), position, delta, 1.0)
        links = portal_links(self.scene)
        if not links:
            return path[-1], rotation
        result = teleport_path(links, path)
        return result.position, result.rotation @ rotation

    # --- vertical ---------------------------------------------------------------------------

    def _fall(self, eye: np.ndarray, rotation: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
        body = self.body
        below = float(self.probe.distances(eye, DOWN[None])[0])
        gap = below - body.eye_height  # feet above the floor (negative: the floor rose, a step up)
        standing = self.vertical_speed <= 0.0 and (gap < 0.0 or (self.on_ground and gap <= body.step_height))
        if standing and gap >= -body.step_height:
            self.vertical_speed, self.on_ground = 0.0, True
            return self._move(eye, rotation, DOWN * gap)
        self.vertical_speed = max(self.vertical_speed - body.gravity * dt, -body.max_fall_speed)
        fall = -self.vertical_speed * dt
        if fall >= gap:  # lands this tick
            self.vertical_speed, self.on_ground = 0.0, True
            return self._move(eye, rotation, DOWN * max(gap, 0.0))
        self.on_ground = False
        return self._move(eye, rotation, DOWN * fall)

    def close(self) -> None:
        self.probe.close()


def horizontal(rotation: np.ndarray, move: tuple[float, float, float]) -> np.ndarray:
    """The unit-or-zero world direction of the move input on the ground plane (the camera's yaw only)."""
    forward = -rotation[:, 2] * (1.0, 0.0, 1.0)
    right = rotation[:, 0] * (1.0, 0.0, 1.0)
    n_f, n_r = float(np.linalg.norm(forward)), float(np.linalg.norm(right))
    if n_f < 1e-9:  # looking straight up or down: forward is where the camera's top points
        forward = rotation[:, 1] * (1.0, 0.0, 1.0) * (1.0 if rotation[1, 2] > 0 else -1.0)
        n_f = max(float(np.linalg.norm(forward)), 1e-12)
    v = right / max(n_r, 1e-12) * move[0] - forward / n_f * move[2]
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else np.zeros(3)
