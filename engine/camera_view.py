"""The camera a frame is rendered from: float64 pose, primary rays, radial bounds, its packed row.

Kept apart from the table packer: the camera changes every frame and is sent
as its own small record, while the packer follows the scene's change journal.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from components import Camera, Transform
from engine import layout
from engine.box_clearance import camera_clearance
from engine.maths import quat_to_matrix
from engine.records import Precision
from engine.scene import Scene
from engine.tlas import rows_at
from engine.tlas_wide import TlasLanes


@dataclass(frozen=True)
class CameraView:
    """The float64 camera a frame is rendered from."""

    position: np.ndarray  # (3,)
    rotation: np.ndarray  # (3, 3): columns are right, up, back
    fov_deg: float
    #: Where in its pixel each primary ray starts, (x right, y down) in [0, 1): the centre for one sample a
    #: pixel, another point for each further sample (``backends.samples``).
    subpixel: tuple[float, float] = (0.5, 0.5)

    @staticmethod
    def from_components(transform: Transform, camera: Camera) -> CameraView:
        return CameraView(
            np.array(transform.position, dtype=np.float64), quat_to_matrix(transform.rotation), camera.fov_deg
        )

    def corner_directions(self, aspect: float) -> np.ndarray:
        """World directions of the rays through NDC (-1, -1) and (+1, +1) (rows)."""
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        local = np.array([[-aspect * t, -t, -1.0], [aspect * t, t, -1.0]])
        local /= np.linalg.norm(local, axis=1, keepdims=True)
        return local @ self.rotation.T

    def sigma_bounds(self, aspect: float) -> tuple[np.ndarray, np.ndarray]:
        """The radial mode's ``m_k`` and ``M_k`` (docs/semantics.md rule 8)."""
        corners = self.corner_directions(aspect)
        return corners.min(axis=0), corners.max(axis=0)

    def primary_directions(self, width: int, height: int, rows: tuple[int, int] | None = None) -> np.ndarray:
        """Unit world directions (H, W, 3), float64, exactly as docs/semantics.md, "Primary rays", says.

        ``rows`` (first, end): only those rows of the image, the same numbers as in the whole (a tracer
        working through a big frame a band at a time).
        """
        aspect = width / height
        t = math.tan(math.radians(self.fov_deg) / 2.0)
        sx, sy = self.subpixel
        x = (2.0 * (np.arange(width) + sx) / width - 1.0) * aspect * t
        y = (1.0 - 2.0 * (np.arange(height) + sy) / height) * t
        if rows is not None:
            y = y[rows[0] : rows[1]]
        local = np.empty((len(y), width, 3))
        local[..., 0] = x[None, :]
        local[..., 1] = y[:, None]
        local[..., 2] = -1.0
        local /= np.linalg.norm(local, axis=2, keepdims=True)
        return local @ self.rotation.T


def scene_camera(scene: Scene) -> CameraView:
    """The scene's active camera."""
    if scene.camera_entity is None:
        scene.validate()  # raises the "no camera" error
    assert scene.camera_entity is not None
    return CameraView.from_components(scene.get(scene.camera_entity, Transform), scene.get(scene.camera_entity, Camera))


#: A camera closer than this (relative to the size of its coordinates, in a box's local units) to a box face
#: has its box looked up per ray: far above the kernels' nudge (5e-5 in float32) and rounding.
CAMERA_FACE_MARGIN = 1e-3
#: ``size.z`` of the camera row when the camera's box must be looked up per ray (docs/semantics.md section 14).
CAMERA_BOX_PER_RAY = -2


def camera_box(position: np.ndarray, aberrations: np.ndarray | None, tree: tuple[np.ndarray, int] | None = None) -> int:
    """The active box of every primary ray, or CAMERA_BOX_PER_RAY when rays may disagree.

    ``position`` is camera-relative, ``aberrations`` the packed rows in use (rule 5: the last row containing
    the point). Each ray looks its box up just past the camera along its own direction; that is the same
    box for all rays when the camera is further than the nudge (plus the kernel's rounding) from every face,
    which this demands with a wide margin. Near a face (a camera standing on one, touching boxes) each ray
    keeps its own look-up. ``tree``: the ``space_nodes`` table and the boxes' root; then only the boxes
    whose leaves hold the camera (grown by the margin) are looked at, as only they can hold a ray's point.
    """
    if aberrations is None:
        return CAMERA_BOX_PER_RAY
    p = np.asarray(position, dtype=np.float64)
    size = max(1.0, float(np.linalg.norm(p)))
    found = -1
    candidates = range(len(aberrations)) if tree is None else rows_at(*tree, p, CAMERA_FACE_MARGIN * size)
    for b in candidates:
        row = aberrations[b]
        m = np.asarray(row["world_to_local"], dtype=np.float64)
        q = m[:, :3] @ p + m[:, 3]
        # Local units per world unit along each axis, and the size of the terms q is computed from.
        scale = np.linalg.norm(m[:, :3], axis=1)
        margin = CAMERA_FACE_MARGIN * (scale * size + np.abs(m[:, 3]) + 1.0)
        gap = np.abs(np.abs(q) - 0.5)
        if not (np.all(np.isfinite(q)) and np.all(gap > margin)):
            return CAMERA_BOX_PER_RAY
        if np.all(np.abs(q) < 0.5):
            found = b
    return found


#: A box counts as seen when it is within this angle (radians, about) of the corner rays' pyramid: far above
#: the rounding of the kernels' primary rays.
VIEW_MARGIN = 1e-4


def view_planes(view: CameraView, aspect: float) -> np.ndarray:
    """Unit inward normals (4, 3) of the pyramid of the corner rays: every primary ray is inside it."""
    t = math.tan(math.radians(view.fov_deg) / 2.0)
    local = np.array([[-aspect * t, -t, -1.0], [aspect * t, -t, -1.0], [aspect * t, t, -1.0], [-aspect * t, t, -1.0]])
    corners = local @ view.rotation.T
    normals = np.cross(corners, np.roll(corners, -1, axis=0))
    normals /= np.linalg.norm(normals, axis=1, keepdims=True)
    forward = -view.rotation[:, 2]
    return np.where((normals @ forward)[:, None] < 0.0, -normals, normals)


def boxes_seen(planes: np.ndarray, apex: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Which boxes lo/hi (n, 3) are not wholly outside one of the pyramid's planes (apex: the camera)."""
    # Twice each box's corner furthest along each normal, relative to the apex, as centre and half extent:
    # (lo + hi) . n + (hi - lo) . |n|, two small products (half the time of the corners picked per plane).
    # The extremes over the 3 axes and 4 planes taken column by column: elementwise over the boxes, not a
    # short row per box.
    lo, hi = lo - apex, hi - apex
    size = np.maximum(np.abs(lo), np.abs(hi))
    reach = np.maximum(np.maximum(size[:, 0], size[:, 1]), size[:, 2])
    far = (lo + hi) @ planes.T + (hi - lo) @ np.abs(planes).T
    nearest = np.minimum(np.minimum(far[:, 0], far[:, 1]), np.minimum(far[:, 2], far[:, 3]))
    return nearest >= (-2.0 * VIEW_MARGIN) * np.maximum(1.0, reach)


def seen_leaves(view: CameraView, aspect: float, origin: np.ndarray, nodes: np.ndarray, root: int) -> np.ndarray:
    """The leaves (rows of ``nodes``) of the tree from ``root`` whose boxes meet the pyramid of the corner rays
    (camera-relative bounds, ``origin`` the packed origin): a walk through the nodes seen, so its cost follows
    what the camera sees. A primary ray can meet only these leaves' portals or boxes.

    Each step tests the grandchildren of the inner nodes seen (a leaf child as it is), not their children: a
    node holds its children's boxes, so a child unseen has no box seen below it and the leaves found are the
    level-by-level walk's, in half the steps (each a few array operations, whatever their size)."""
    apex = np.asarray(view.position, dtype=np.float64) - origin
    planes = view_planes(view, aspect)
    frontier = np.array([root], np.int64)
    leaves = []
    for _ in range(len(nodes)):
        if not frontier.size:
            break
        lo, hi = nodes["bounds_min"][frontier].astype(np.float64), nodes["bounds_max"][frontier].astype(np.float64)
        frontier = frontier[boxes_seen(planes, apex, lo, hi)]
        leaf = nodes["count"][frontier] > 0
        leaves.append(frontier[leaf])
        first = nodes["first"][frontier[~leaf]].astype(np.int64)
        children = np.concatenate([first, first + 1])
        inner = nodes["count"][children] == 0
        first = nodes["first"][children[inner]].astype(np.int64)
        frontier = np.concatenate([children[~inner], first, first + 1])
    return np.concatenate(leaves) if leaves else np.zeros(0, np.int64)


def seen_instances(view: CameraView, aspect: float, origin: np.ndarray, lanes: TlasLanes) -> np.ndarray:
    """The instance rows of the leaves of the top-level tree (``tlas_nodes`` as lanes, binary or wide) whose
    boxes meet the pyramid of the corner rays, as :func:`seen_leaves`: a walk level by level through the nodes
    seen. A primary ray can meet only these instances."""
    apex = np.asarray(view.position, dtype=np.float64) - origin
    planes = view_planes(view, aspect)
    frontier = np.array([0], np.int64)
    rows = []
    lane = np.arange(lanes.width)
    for _ in range(len(lanes.kind)):
        if not frontier.size:
            break
        live = (frontier[:, None] * lanes.width + lane).ravel()
        live = live[lanes.kind[live] >= 0]
        live = live[boxes_seen(planes, apex, lanes.lo[live], lanes.hi[live])]
        kind, child = lanes.kind[live], lanes.child[live]
        rows.append(child[kind == 1])
        frontier = child[kind == 0]
    return np.concatenate(rows) if rows else np.zeros(0, np.int64)


def view_reaches(view: CameraView, aspect: float, origin: np.ndarray, nodes: np.ndarray, root: int) -> bool:
    """Whether a primary ray can meet a leaf of the tree in ``nodes`` from ``root`` (as :func:`seen_leaves`,
    depth first, ending at the first leaf seen). False proves that every primary ray misses every portal
    quad or box the tree holds."""
    apex = np.asarray(view.position, dtype=np.float64) - origin
    planes = view_planes(view, aspect)
    stack = [root]
    while stack:
        node = stack.pop()
        lo, hi = nodes["bounds_min"][node : node + 1].astype(np.float64), nodes["bounds_max"][node : node + 1]
        if not boxes_seen(planes, apex, lo, hi.astype(np.float64))[0]:
            continue
        if nodes["count"][node] > 0:
            return True
        first = int(nodes["first"][node])
        stack += [first, first + 1]
    return False


def pack_camera(
    view: CameraView,
    origin: np.ndarray,
    precision: Precision,
    width: int,
    height: int,
    aberrations: np.ndarray | None = None,
    bounds: tuple[np.ndarray, np.ndarray] | None = None,
    tree: tuple[np.ndarray, int] | None = None,
) -> np.ndarray:
    """One row of the camera table, relative to the packed origin.

    ``aberrations``: the packed rows in use, for the camera's box (``size.z``, camera_box); without them
    every ray looks its box up. ``bounds``: the instances' packed bounds, for the camera's clearance
    (``lens.z``, box_clearance.camera_clearance); without them every first mesh search runs. ``tree``: the
    ``space_nodes`` table and the boxes' root, to find the camera's box among many (camera_box).
    """
    row = np.zeros(1, dtype=layout.camera_dtype(precision))
    aspect = width / height
    row["position"][0, :3] = view.position - origin
    row["right"][0, :3] = view.rotation[:, 0]
    row["up"][0, :3] = view.rotation[:, 1]
    row["back"][0, :3] = view.rotation[:, 2]
    row["origin"][0, :3] = origin
    lo, hi = view.sigma_bounds(aspect)
    row["sigma_min"][0, :3] = lo
    row["sigma_max"][0, :3] = hi
    row["lens"][0, :3] = (
        math.tan(math.radians(view.fov_deg) / 2.0),
        aspect,
        camera_clearance(view.position - origin, bounds),
    )
    row["size"][0, :3] = (width, height, camera_box(view.position - origin, aberrations, tree))
    row["subpixel"][0, :2] = view.subpixel
    return row
