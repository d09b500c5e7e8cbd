"""The preview's debug lines: boxes, portal quads, light glyphs, the scene camera and the selection as world
segments, and the screen-space quads that draw them a few pixels wide.

Aberration boxes (12 edges) and portal quads (4 edges) are drawn in their
own colour where ``debug_draw`` is on, the selection in white, the scene
camera as a small frustum, a point light as a six-pointed star and a sun as
an arrow along the way it shines, in the light's colour. Lines are straight in undeformed space: they
show where an entity *is*, whatever the tracer makes it look like. Plain
NumPy, tested without a GL context (:mod:`editor.preview` draws them).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from components import Aberration, Camera, Light, Mesh, Portal, Transform
from engine.errors import AberrantError
from engine.maths import trs_matrix
from engine.scene import Scene
from engine.space_index import SpaceIndex

#: Line width in pixels.
LINE_WIDTH = 2.0
SELECTION_COLOR = (1.0, 1.0, 1.0)
CAMERA_COLOR = (0.85, 0.85, 0.85)
#: Inert portals (no target) are drawn at this fraction of their colour.
INERT_DIM = 0.45

_BOX_CORNERS = np.array([[x, y, z] for x in (-0.5, 0.5) for y in (-0.5, 0.5) for z in (-0.5, 0.5)])
_BOX_EDGES = [(a, b) for a in range(8) for b in range(a + 1, 8) if bin(a ^ b).count("1") == 1]
_QUAD_CORNERS = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])


def _edges(corners: np.ndarray, pairs: list[tuple[int, int]]) -> np.ndarray:
    return np.array([[corners[a], corners[b]] for a, b in pairs])


def _placed(transform: Transform, local: np.ndarray) -> np.ndarray:
    m = trs_matrix(transform.position, transform.rotation, transform.scale)
    return local @ m[:3, :3].T + m[:3, 3]


def box_edges(transform: Transform, lo: np.ndarray | None = None, hi: np.ndarray | None = None) -> np.ndarray:
    """The 12 world edges (12, 2, 3) of the unit box, or of the local box ``[lo, hi]``, placed by ``transform``."""
    corners = _BOX_CORNERS
    if lo is not None and hi is not None:
        corners = (corners + 0.5) * (hi - lo) + lo
    return _placed(transform, _edges(corners, _BOX_EDGES).reshape(-1, 3)).reshape(-1, 2, 3)


def quad_edges(transform: Transform) -> np.ndarray:
    """The 4 world edges (4, 2, 3) of a portal quad."""
    pairs = [(0, 1), (1, 2), (2, 3), (3, 0)]
    return _placed(transform, _edges(_QUAD_CORNERS, pairs).reshape(-1, 3)).reshape(-1, 2, 3)


def camera_edges(transform: Transform, camera: Camera, aspect: float = 4 / 3, depth: float = 0.6) -> np.ndarray:
    """A small frustum (8 edges) showing where the scene camera stands and looks."""
    t = math.tan(math.radians(camera.fov_deg) / 2.0) * depth
    far = np.array(
        [[-aspect * t, -t, -depth], [aspect * t, -t, -depth], [aspect * t, t, -depth], [-aspect * t, t, -depth]]
    )
    pts = np.vstack([np.zeros((1, 3)), far])
    pairs = [(0, 1), (0, 2), (0, 3), (0, 4), (1, 2), (2, 3), (3, 4), (4, 1)]
    rigid = Transform(transform.position, transform.rotation)
    return _placed(rigid, _edges(pts, pairs).reshape(-1, 3)).reshape(-1, 2, 3)


#: A point light's star: three axis segments and four diagonals through its position (local units).
_STAR = (
    np.array(
        [[[-1, 0, 0], [1, 0, 0]], [[0, -1, 0], [0, 1, 0]], [[0, 0, -1], [0, 0, 1]]]
        + [[[-0.6, -0.6 * b, -0.6 * c], [0.6, 0.6 * b, 0.6 * c]] for b in (1, -1) for c in (1, -1)],
        dtype=np.float64,
    )
    * 0.25
)
#: A sun's arrow: a shaft along -Z (the way it shines), a four-line head, and a square at its tail.
_HEAD = [[[0, 0, -1.0], [0.12 * x, 0.12 * y, -0.8]] for x, y in ((1, 0), (-1, 0), (0, 1), (0, -1))]
_SQUARE = [[[0.2 * x, 0.2 * y, 0], [-0.2 * y, 0.2 * x, 0]] for x, y in ((1, 1), (-1, 1), (-1, -1), (1, -1))]
_ARROW = np.array([[[0, 0, 0], [0, 0, -1.0]], *_HEAD, *_SQUARE], dtype=np.float64)


def light_edges(transform: Transform, light: Light) -> np.ndarray:
    """A light's glyph (N, 2, 3): a star at a point light, an arrow along a sun's -Z; unscaled."""
    glyph = _STAR if light.kind == "point" else _ARROW
    rigid = Transform(transform.position, transform.rotation)
    return _placed(rigid, glyph.reshape(-1, 3)).reshape(-1, 2, 3)


Lines = tuple[np.ndarray, np.ndarray]


def _box_outline(scene: Scene, entity: int) -> Lines | None:
    transform, aberration = scene.get(entity, Transform), scene.get(entity, Aberration)
    if not aberration.debug_draw:
        return None
    edges = box_edges(transform)
    return edges, np.tile(np.asarray(aberration.color, dtype=np.float64), (len(edges), 1))


def _portal_outline(scene: Scene, entity: int) -> Lines | None:
    transform, portal = scene.get(entity, Transform), scene.get(entity, Portal)
    if not portal.debug_draw:
        return None
    dim = 1.0 if portal.target is not None else INERT_DIM
    edges = quad_edges(transform)
    return edges, np.tile(np.asarray(portal.color, dtype=np.float64) * dim, (len(edges), 1))


def view_planes(view_proj: np.ndarray, size: tuple[int, int], width: float = LINE_WIDTH) -> np.ndarray:
    """The six planes ``(6, 4)`` of the frustum of ``view_proj`` (inside: ``a x + b y + c z + d >= 0``), its
    sides pushed out by a line's width so that an edge just outside still drawing a pixel is kept."""
    m = np.asarray(view_proj, np.float64)
    grow = 1.0 + 2.0 * width / max(1, min(size))
    return np.array(
        [grow * m[3] + m[0], grow * m[3] - m[0], grow * m[3] + m[1], grow * m[3] - m[1], m[3] + m[2], m[3] - m[2]]
    )


class Outlines:
    """The debug outlines of a scene's boxes and portals, each kept until its entity changes.

    With a view, only the entities whose box reaches into its frustum are looked at (found through a
    :class:`engine.space_index.SpaceIndex`), so a frame costs what the view shows, not the scene's count.
    """

    def __init__(self) -> None:
        self.space = SpaceIndex()
        self._cache: dict[int, tuple[tuple[int, int], Lines | None]] = {}
        #: Outlines computed so far, and entities looked at by the last call (tests: a frame touches few).
        self.built = 0
        self.visited = 0

    def _outline(self, scene: Scene, entity: int, make: Callable[[Scene, int], Lines | None]) -> Lines | None:
        version = self.space.version(entity)
        cached = self._cache.get(entity)
        if cached is None or cached[0] != version:
            self.built += 1
            cached = self._cache[entity] = (version, make(scene, entity))
        return cached[1]

    def lines(
        self,
        scene: Scene,
        selected: int | None = None,
        *,
        show_camera: bool = True,
        planes: np.ndarray | None = None,
    ) -> Lines:
        """World segments ``(N, 2, 3)`` and their colours ``(N, 3)`` for the debug overlay; only what may lie
        inside ``planes`` (:func:`view_planes`) when given."""
        space = self.space.sync(scene)
        if len(self._cache) > 2 * (space.portal_count + space.box_count) + 64:
            self._cache.clear()  # entities gone since: their outlines are never asked for again
        if planes is None:
            boxes = [e for e, _ in scene.query(Transform, Aberration)]
            portals = [e for e, _ in scene.query(Transform, Portal)]
        else:
            boxes, portals = space.boxes_in_planes(planes), space.portals_in_planes(planes)
        self.visited = len(boxes) + len(portals)
        segments: list[np.ndarray] = []
        colors: list[np.ndarray] = []
        for entities, make in ((boxes, _box_outline), (portals, _portal_outline)):
            for entity in entities:
                outline = None if entity == selected else self._outline(scene, entity, make)
                if outline is not None:
                    segments.append(outline[0])
                    colors.append(outline[1])
        for entity, (transform, light) in scene.query(Transform, Light):  # a few: no index needed
            if entity != selected:
                glyph = light_edges(transform, light)
                segments.append(glyph)
                colors.append(np.tile(np.asarray(light.color, dtype=np.float64), (len(glyph), 1)))
        camera = scene.camera_entity
        if show_camera and camera is not None and camera != selected:
            frustum = camera_edges(scene.get(camera, Transform), scene.get(camera, Camera))
            segments.append(frustum)
            colors.append(np.tile(CAMERA_COLOR, (len(frustum), 1)))
        if selected is not None:
            segments.extend(selection_edges(scene, selected))
            colors.extend(np.tile(SELECTION_COLOR, (len(e), 1)) for e in segments[len(colors) :])
        if not segments:
            return np.zeros((0, 2, 3)), np.zeros((0, 3))
        return np.concatenate(segments), np.concatenate(colors)


def preview_lines(scene: Scene, selected: int | None = None, *, show_camera: bool = True) -> Lines:
    """World segments ``(N, 2, 3)`` and their colours ``(N, 3)`` for the debug overlay: every entity's."""
    return Outlines().lines(scene, selected, show_camera=show_camera)


def selection_edges(scene: Scene, entity: int) -> list[np.ndarray]:
    """The outline of the selected entity: its box, quad, frustum, light glyph or mesh bounds."""
    transform = scene.try_get(entity, Transform)
    if transform is None:
        return []
    out = []
    if scene.has(entity, Aberration):
        out.append(box_edges(transform))
    if scene.has(entity, Portal):
        out.append(quad_edges(transform))
    camera = scene.try_get(entity, Camera)
    if camera is not None:
        out.append(camera_edges(transform, camera))
    light = scene.try_get(entity, Light)
    if light is not None:
        out.append(light_edges(transform, light))
    mesh = scene.try_get(entity, Mesh)
    if mesh is not None:
        try:
            lo, hi = scene.asset(mesh.asset).bounds()
        except AberrantError:
            return out
        pad = 0.01 * np.maximum(hi - lo, 1e-3)
        out.append(box_edges(transform, lo.astype(np.float64) - pad, hi.astype(np.float64) + pad))
    return out


def thick_lines(
    segments: np.ndarray, colors: np.ndarray, view_proj: np.ndarray, size: tuple[int, int], width: float = LINE_WIDTH
) -> np.ndarray:
    """Screen-space quads for the segments: ``(6 * N, 7)`` float32 rows of clip position and colour.

    Each segment is clipped against the near plane first (the view is often
    inside an aberration box), then widened by ``width`` pixels on screen.
    """
    if len(segments) == 0:
        return np.zeros((0, 7), np.float32)
    ones = np.ones((len(segments), 2, 1))
    clip = np.concatenate([segments, ones], axis=2) @ view_proj.T  # (N, 2, 4)
    d = clip[:, :, 2] + clip[:, :, 3]  # >= 0 in front of the near plane
    keep = (d[:, 0] > 0) | (d[:, 1] > 0)
    clip, d, colors = clip[keep], d[keep], colors[keep]
    for a, b in ((0, 1), (1, 0)):
        behind = d[:, a] <= 0
        t = d[behind, a] / (d[behind, a] - d[behind, b])
        clip[behind, a] = clip[behind, a] + t[:, None] * (clip[behind, b] - clip[behind, a])
    w = np.maximum(clip[:, :, 3], 1e-9)
    ndc = clip[:, :, :2] / w[:, :, None]
    px = np.array([size[0] / 2.0, size[1] / 2.0])
    direction = (ndc[:, 1] - ndc[:, 0]) * px
    length = np.linalg.norm(direction, axis=1)
    ok = length > 1e-9
    clip, colors, direction, length, w = clip[ok], colors[ok], direction[ok], length[ok], w[ok]
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1) / length[:, None]
    offset = normal * (width / 2.0) / px  # NDC units
    corners = []
    for end, side in ((0, -1), (0, 1), (1, 1), (0, -1), (1, 1), (1, -1)):
        c = clip[:, end].copy()
        c[:, :2] += side * offset * w[:, end, None]
        corners.append(np.concatenate([c, colors], axis=1))
    return np.stack(corners, axis=1).reshape(-1, 7).astype(np.float32)
