"""Helpers shared by the hard-case, thesis and stability tests: backend lists, aimed cameras, comparisons.

Rendering and the parity comparison themselves live in ``test_parity`` (``render``,
``compare``, ``assert_clean``); this module adds what several of the newer files
need on top: the list of every backend, a camera whose pixel rays have exact
slopes (so rays can be aimed along a face, an edge or through a corner), a
cache of reference frames, and small measurements on frames (where a marker is).
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import pytest
from test_parity import Comparison, assert_clean, compare, render

from backends import shared
from backends.base import AOVS, Backend, Frame
from backends.reference.backend import ReferenceBackend
from backends.upload import SceneUploader
from components import Aberration, Mesh, Transform
from engine.maths import trs_inverse
from engine.packing import ScenePacker, scene_camera
from engine.scene import Scene

#: Every fast backend and precision, measured against the reference.
FAST = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("glsl", "f64", id="glsl-f64"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]
#: The reference too: for properties every backend must have on its own (no NaN, termination, closed forms).
EVERY = [pytest.param("reference", "f64", id="reference"), *FAST]

#: The aberration and portal parity sets: every fast pair but GLSL at f64 (llvmpipe's doubles are slow;
#: GLSL f64 still runs those modules' closed forms, through EVERY).
SPACE_PARITY = [param for param in FAST if param.id != "glsl-f64"]

#: The parity thresholds of the aberration and portal parity tests.
MISMATCH_MAX = 2e-3
F32_DEPTH_MEDIAN_MAX = 1e-5
F64_DEPTH_P99_MAX = 1e-9


# --- an aimed camera ------------------------------------------------------------------------------------


def aimed_fov(n: int) -> float:
    """The vertical field of view (degrees) that gives an ``n`` x ``n`` image pixel slopes of (i - c) / c.

    With ``c = (n - 1) / 2`` the ray of pixel (i, j) points along ``((i - c)/c, (c - j)/c, -1)``
    in camera space (docs/semantics.md, "Primary rays", with ``tan(fov/2) = n / (n - 1)``): dyadic slopes for
    ``n - 1`` a power of two, so rays can be aimed exactly at integer points.
    """
    return 2.0 * math.degrees(math.atan(n / (n - 1)))


def aim(scene: Scene, position: tuple[float, float, float], n: int) -> None:
    """The scene's camera at ``position``, looking along -z with no rotation at all, an aimed fov."""
    scene.set_camera(position, rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=aimed_fov(n))


def aimed_pixel(n: int, slope_x: float, slope_y: float) -> tuple[int, int]:
    """(row, column) of the pixel whose ray has camera-space slopes (x/-z, y/-z) in an aimed n x n image."""
    c = (n - 1) / 2
    column, row = c + slope_x * c, c - slope_y * c
    assert column == int(column) and row == int(row), "that slope is not a pixel centre"
    return int(row), int(column)


# --- rendering and comparing -------------------------------------------------------------------------------


class ReferenceFrames:
    """The reference's frame of each named scene, rendered once (scenes are built, rendered and closed).

    Named builders and a size are given up front, or a builder and size with the first call for a name.
    """

    def __init__(self, builders: dict[str, Callable[[], Scene]] | None = None, size: tuple[int, int] = (0, 0)) -> None:
        self.builders = builders or {}
        self.size = size
        self.backend = ReferenceBackend()
        self.cache: dict[str, Frame] = {}

    def __call__(
        self, name: str, build: Callable[[], Scene] | None = None, size: tuple[int, int] | None = None
    ) -> Frame:
        if name not in self.cache:
            self.cache[name] = render_scene(self.backend, build or self.builders[name], size or self.size)
        return self.cache[name]

    def release(self) -> None:
        self.backend.release()


def render_scene(backend: Backend, build: Callable[[], Scene], size: tuple[int, int]) -> Frame:
    """Build a scene, render every AOV with ``backend``, close the scene."""
    scene = build()
    try:
        return render(backend, scene, size)
    finally:
        scene.close()


@dataclass(frozen=True)
class Agreement:
    """A fast frame against the reference: the parity comparison and the event-count mismatch."""

    comparison: Comparison
    events_off: float

    def __str__(self) -> str:
        return f"{self.comparison}, events off {self.events_off:.4%}"


def assert_agrees(
    fast: Frame,
    ref: Frame,
    precision: str,
    mismatch_max: float = MISMATCH_MAX,
    events_ignore: np.ndarray | None = None,
    ignore: np.ndarray | None = None,
    color_off_max: float = 0.02,
) -> Agreement:
    """No NaN in either frame, and ``fast`` within the parity thresholds of ``ref`` (returned for reports).

    ``events_ignore``: pixels whose event count may differ (rays aimed exactly at a box's edge,
    where counting an empty crossing is decided by rounding); ``ignore``: pixels that may differ in
    every AOV (rays aimed exactly at a mesh's silhouette, which may hit or miss). Both frames must
    still be clean there. ``color_off_max``: fraction of same-instance pixels whose colour may differ
    by more than 2 levels (a ray exactly through an edge between two faces may take either's normal).
    """
    assert_clean(fast)
    assert_clean(ref)
    if ignore is not None:
        fast = replace(
            fast, **{name: np.where(ignore if name != "color" else ignore[..., None], ref.aov(name), fast.aov(name))
                     for name in fast.present()}
        )  # fmt: skip
    events_off = fast.events != ref.events
    if events_ignore is not None:
        events_off &= ~events_ignore
    result = Agreement(compare(fast, ref), float(np.mean(events_off)))
    assert result.comparison.mismatch <= mismatch_max, result
    assert result.events_off <= mismatch_max, result
    assert result.comparison.color_off <= color_off_max, result
    if precision == "f64":
        assert result.comparison.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.comparison.depth_median <= F32_DEPTH_MEDIAN_MAX, result
    return result


# --- measuring frames -----------------------------------------------------------------------------------


def pixels_of(frame: Frame, entity: int) -> np.ndarray:
    """Mask of the pixels showing ``entity``."""
    return frame.instance == entity


def centroid(frame: Frame, entity: int) -> np.ndarray:
    """(x, y) in pixels (column, row) of the centre of the pixels showing ``entity``."""
    rows, columns = np.nonzero(pixels_of(frame, entity))
    assert rows.size > 0, f"entity {entity} is not in view"
    return np.array([columns.mean(), rows.mean()])


def extent(frame: Frame, entity: int) -> np.ndarray:
    """(width, height) in pixels of the box around the pixels showing ``entity``."""
    rows, columns = np.nonzero(pixels_of(frame, entity))
    assert rows.size > 0, f"entity {entity} is not in view"
    return np.array([columns.max() - columns.min() + 1, rows.max() - rows.min() + 1], dtype=np.float64)


# --- rays aimed exactly at the boundary of a box -----------------------------------------------------------------


def aberration_boxes(scene: Scene) -> list[Transform]:
    """The transforms of the scene's aberration boxes."""
    return [transform for _, (transform, _) in scene.query(Transform, Aberration)]


def box_meshes(scene: Scene) -> list[Transform]:
    """The transforms of the scene's ``box`` primitive meshes (the unit cube, like an aberration box)."""
    return [transform for _, (transform, mesh) in scene.query(Transform, Mesh) if mesh.asset == "box"]


def singular_pixels(scene: Scene, width: int, height: int, boxes: list[Transform], tol: float = 1e-6) -> np.ndarray:
    """Pixels whose primary ray meets one of ``boxes`` exactly at an edge, a corner or along a face's plane.

    A float64 slab test per unit box: the ray only touches the box (entry = exit), enters or leaves
    through an edge (two axes' entries or exits equal; a start on a face is not an entry) or runs in
    a face's plane. On these rays, whether an empty crossing is counted (aberrations) or whether the
    silhouette is hit (meshes) is decided by rounding, so backends may rightly differ there.
    """
    camera = scene_camera(scene)
    d = camera.primary_directions(width, height).reshape(-1, 3)
    out = np.zeros(len(d), dtype=bool)
    for transform in boxes:
        m = trs_inverse(transform.position, transform.rotation, transform.scale)
        a = m[:3, :3] @ camera.position + m[:3, 3]
        v = d @ m[:3, :3].T
        inside = np.abs(a) <= 0.5
        parallel = v == 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (-0.5 - a) / v, (0.5 - a) / v
        lo = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        hi = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        lo, hi = np.sort(lo, axis=1), np.sort(hi, axis=1)
        near, far = lo[:, -1], hi[:, 0]
        size = np.maximum(np.where(np.isfinite(near), np.abs(near), 0.0), np.where(np.isfinite(far), np.abs(far), 0.0))
        eps = tol * np.maximum(1.0, size)
        with np.errstate(invalid="ignore"):
            meets = (near <= far + eps) & (far > eps)
            touches = np.abs(far - near) <= eps
            edge_in = (np.abs(lo[:, -1] - lo[:, -2]) <= eps) & (near > eps)
            edge_out = np.abs(hi[:, 1] - hi[:, 0]) <= eps
        grazes = np.any((np.abs(v) <= tol) & (np.abs(np.abs(a) - 0.5) <= tol), axis=1)
        out |= meets & (touches | edge_in | edge_out | grazes)
    return out.reshape(height, width)


def upload_to_reference(scene: Scene) -> ReferenceBackend:
    """A reference backend holding ``scene`` (packed as the reference wants it)."""
    backend = ReferenceBackend()
    upload(backend, scene)
    return backend


# --- one backend's tables and frames (the backend-contract tests and the per-backend files) -------------


def upload(backend: Backend, scene: Scene) -> ScenePacker:
    """Pack ``scene`` as ``backend`` wants it and upload it; the packer is kept for later syncs (tests that
    drive ``backend.upload`` by hand)."""
    uploader = SceneUploader(backend)
    uploader.sync(scene)
    return uploader.packer


def render_aovs(backend: Backend, scene: Scene, width: int = 48, height: int = 36, aovs=AOVS) -> Frame:
    """Upload ``scene`` and render it from its own camera (the scene stays open)."""
    upload(backend, scene)
    return backend.render(scene_camera(scene), width, height, aovs)


def boxes_scene() -> Scene:
    """A floor, two boxes and a sphere in view: sky and hits, several instances."""
    scene = Scene("boxes")
    scene.add_mesh("floor", "plane", scale=(20.0, 1.0, 20.0), checker=0.5)
    scene.add_mesh("a", "box", position=(-1.5, 0.5, 0.0), color=(0.9, 0.2, 0.2))
    scene.add_mesh("b", "box", position=(0.0, 0.5, -1.0), euler_deg=(0.0, 30.0, 0.0), color=(0.2, 0.9, 0.2))
    scene.add_mesh("c", "sphere", position=(1.5, 0.5, 0.0), color=(0.2, 0.2, 0.9))
    scene.set_camera((0.0, 2.0, 5.0), look_at=(0.0, 0.3, 0.0), fov_deg=60.0)
    return scene


def crowded(kind: str, n: int, seed: int = 0, in_view: bool = True) -> Scene:
    """A floor and a few meshes with ``n`` portals or ``n`` aberration boxes (``kind``), of random place, size
    and turn, in front of the camera (``in_view``) or behind it. Portals come in pairs: one of each in the
    view space, its target in a far room of other meshes. Boxes mix the three modes and overlap, with
    random priorities."""
    rng = np.random.default_rng(seed)
    scene = Scene(f"crowded-{kind}-{n}-{seed}")
    for room, x0 in (("", 0.0), ("far_", 60.0)):
        scene.add_mesh(f"{room}floor", "plane", position=(x0, 0.0, 0.0), scale=(30.0, 1.0, 30.0), checker=0.5)
        for k in range(6):
            scene.add_mesh(
                f"{room}m{k}", ("box", "sphere", "cylinder")[k % 3],
                position=(x0 + rng.uniform(-4.0, 4.0), rng.uniform(0.3, 2.0), rng.uniform(-8.0, -2.0)),
                euler_deg=tuple(rng.uniform(-180.0, 180.0, 3)), scale=tuple(rng.uniform(0.4, 1.2, 3)),
                color=tuple(rng.uniform(0.2, 1.0, 3)),
            )  # fmt: skip

    def place() -> dict:
        z = rng.uniform(-7.0, 0.5) if in_view else rng.uniform(9.0, 14.0)
        return dict(
            position=(rng.uniform(-4.0, 4.0), rng.uniform(0.2, 3.0), z),
            euler_deg=tuple(rng.uniform(-180.0, 180.0, 3)),
            scale=tuple(rng.uniform(0.15, 0.8, 3)),
        )

    if kind == "portals":
        for k in range(0, n - 1, 2):
            target = place()
            target["position"] = (60.0 + target["position"][0], *target["position"][1:])
            scene.add_portal_pair(f"p{k}", f"p{k + 1}", a=place(), b=target)
    else:
        modes = ("metric", "radial", "additive")
        for k in range(n):
            scene.add_aberration(
                f"a{k}", tuple(rng.uniform(-0.5, 0.5, 3)), mode=modes[k % 3], priority=int(rng.integers(0, 4)),
                exit=("restore", "repeat", "invert")[k % 3], **place(),
            )  # fmt: skip
    scene.set_camera((0.0, 1.8, 6.0), look_at=(0.0, 1.0, -3.0), fov_deg=70.0)
    return scene


def write_obj(path: Path, vertices, faces) -> Path:
    """A minimal OBJ file (0-based ``faces``), for meshes no primitive makes."""
    lines = [f"v {float(x)!r} {float(y)!r} {float(z)!r}" for x, y, z in vertices]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


#: layout.h's record for each packed table, as both fast backends' layout tests read them.
TABLE_STRUCTS = {
    "settings": "Settings",
    "triangles": "Triangle",
    "triangle_uvs": "TriangleUv",
    "bvh_nodes": "BvhNode",
    "instances": "Instance",
    "materials": "Material",
    "aberrations": "Aberration",
    "portals": "Portal",
    "triangle_blocks": "TriangleBlock",
    "camera": "Camera",
    "tlas_nodes": "TlasNode",
    "bvh4_nodes": "Bvh4Node",  # bvh_nodes packed with bvh_width=4
    "bvh_compact_nodes": "BvhCompactNode",  # bvh_nodes packed with bvh_compact=True
}


def layout_members(struct: str) -> list[tuple[str, str]]:
    """(type, name) of a record's members, parsed from the shared layout.h (as the kernels get it)."""
    text = shared.read("layout.h")
    body = re.search(rf"STRUCT_BEGIN\({struct}\)(.*?)STRUCT_END\({struct}\)", text, re.S)
    assert body is not None, struct
    return re.findall(r"^\s*(\w+)\s+(\w+);", body.group(1), re.M)


def random_rows(dtype: np.dtype, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` rows of ``dtype`` with every field random: a misread offset shows as a wrong word."""
    rows = np.zeros(n, dtype)
    for name in dtype.names:
        field = rows[name]
        if np.issubdtype(field.dtype, np.floating):
            rows[name] = rng.normal(size=field.shape) * 100.0
        else:
            rows[name] = rng.integers(-1000, 1000, size=field.shape)
    return rows


def many_instances(seed: int, n: int) -> Scene:
    """A floor and n meshes of random shape, place, size and turn, around and across the origin."""
    rng = np.random.default_rng(seed)
    scene = Scene(f"many-instances-{seed}")
    scene.add_mesh("floor", "plane", position=(0.0, 0.0, 0.0), scale=(30.0, 1.0, 30.0))
    for k in range(n):
        scene.add_mesh(
            f"m{k}", ("box", "sphere", "cylinder")[k % 3],
            position=tuple(rng.uniform([-8.0, 0.0, -8.0], [8.0, 4.0, 8.0])),
            euler_deg=tuple(rng.uniform(-180.0, 180.0, 3)), scale=tuple(rng.uniform(0.1, 3.0, 3)),
        )  # fmt: skip
    scene.set_camera((0.0, 1.8, 12.0), look_at=(0.0, 1.0, 0.0))
    return scene
