"""Numerical stability on hard cases, in every backend, the reference included.

Every case asserts: no NaN (``assert_clean``), termination (a frame comes back;
endless paths end at ``max_events``), and agreement with the reference within
the parity thresholds (instance mismatch <= 0.2 %, relative depth error median
<= 1e-5 in float32 and 99th percentile <= 1e-9 in float64) -- or, where a
backend is genuinely limited, the measured limit below, asserted with a margin.

Rays aimed exactly at a mesh's silhouette (tangent to a box, along a face's
plane) may rightly hit or miss: they are found in float64 (``singular_pixels``)
and left out of the instance comparison, never out of the NaN check.

Measured (96 x 72, or 97 x 97 for aimed rays; instance mismatch against the
reference's frame of the same view; relative depth error median / 99th
percentile where both hit the same instance; glsl and opencl agree to the
digits shown)::

    case                                   f32 (glsl, opencl)                f64 (glsl, opencl)
    boxes at 1e3 / 1e5 / 1e6               0 %, 9e-8 / <= 6e-7               0 %, 0 / 0
    aberrations at 1e3 / 1e5 / 1e6         0 %, 7e-8 / <= 4e-7               0 %, 0 / 0
    portals at 1e3 / 1e5 / 1e6             0 %, <= 1.3e-7 / <= 8e-7          0 %, 0 / 0
    all three at 1e9 / 1e10 / 1e12     the reference against the fast backends there: as above;
      the reference against the origin: 0 % / 0 % / <= 0.014 % (at 1e12 the scene's own float64
      positions are 1.2e-4 apart; every backend moves the same pixels). The reference traces
      camera-relative like the fast backends: in world coordinates its t_min (1e-9 |o|) was 10
      units at 1e10, and it hit 0.1 % of pixels there, none at 1e12
    every scene scaled 1e-2, 1e2, 1e4      0 %, 8e-8 / <= 4e-7               0 %, 0 / 1.2e-7 (float32 AOV)
    scaled 1e-3                            <= 0.072 %, p99 <= 1.9e-6         0 %
    scaled 1e-4: boxes                     0 %                               0 %
    scaled 1e-4: aberrations [LIMIT]       1.04 %, p99 5.9e-3                0 %
    scaled 1e-4: portals [LIMIT]           0 %, p99 3.4e-2                   0 %
    portal 0, 1e-9 before / 1e-6 behind    0 %                               0 %
    portal 1e-7 .. 1e-5 before [LIMIT]     100 % (the door is not seen)      0 %
    portal >= 3e-5 before                  0 %, 8e-8 / 5e-7                  0 %
    doors 1e-2 <-> 1e2 (L = 1e4, 1e-4)     0 %, 9e-8 / 4e-7                  0 %
    D = -0.999999, 1e6, mixed (aimed)      <= 0.085 %                        0 %
    12 overlapping boxes and twins         0 %                               0 %
    facing doors, turned, non-uniform      0 %                               0 %
    rays in faces' planes (aimed)          2.35 % all, 0 % off silhouettes   1.05 % all, 0 % off them
    1024 slivers round one vertex          0.043 %, no holes                 0 %, no holes
    inside closed meshes (aimed box, grid  0 %, no holes                     0 %, no holes
      cube turned at 1e3 and at 1e5,
      icosphere at 1e3)

The two float32 limits come from one rule (docs/semantics.md section 14): a
float32 ray skips surfaces closer than ``t_min = 1e-5 * max(1, |p|)`` to its
origin, ``p`` relative to the camera's 16-unit cell. So (1) in a level only a
few centimetres across (the 16-unit rooms scaled by 1e-3 and 1e-4), box faces
and portals closer than 1e-5 to an event are skipped (build levels at metre
scale, not smaller), and (2) a portal less than 1e-5 * max(1, |p|)
(at most 3e-4) in front of the camera is not seen -- the camera sees what is
behind it on its own side, as it does standing exactly on the quad -- while
the next step forward still teleports it. The float64 kernels and the
reference show neither. Far from the origin float32 loses nothing: the
tables are camera-relative (docs/semantics.md, "Primary rays").
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scenes import (
    EVERY,
    F32_DEPTH_MEDIAN_MAX,
    F64_DEPTH_P99_MAX,
    FAST,
    MISMATCH_MAX,
    ReferenceFrames,
    aberration_boxes,
    aim,
    assert_agrees,
    box_meshes,
    render_scene,
    singular_pixels,
)
from test_hard_aberrations import aimed_boxes
from test_hard_portals import facing_corridor
from test_parity import assert_clean, compare, random_boxes
from test_parity_aberrations import mixed_overlap, room
from test_parity_portals import portal_in_aberrations, rooms

from aberrant.bench.scenes import inside_grid_cube, inside_sphere, translated
from backends.base import Frame
from components import Transform
from components.validation import MAX_MAGNITUDE
from engine.maths import quat_from_euler_deg, quat_multiply, quat_to_matrix
from engine.scene import Scene

SIZE = (96, 72)
N = 97


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    return tmp_path_factory.mktemp("stability-assets")


@pytest.fixture(scope="module")
def reference() -> Iterator[ReferenceFrames]:
    """The reference's frame of each case, rendered once for all the backends compared with it."""
    frames = ReferenceFrames()
    yield frames
    frames.release()


def is_fast(backend_name: str) -> bool:
    return backend_name != "reference"


# --- closed meshes: rays through edges and vertices -------------------------------------------------------------


def inside_aimed_box(folder: Path) -> Scene:
    """The camera at the centre of a closed 12-triangle box of side 8: aimed rays meet its faces' diagonals
    (|sx| = |sy|), its edges (the border rows and columns) and its corners (the corner pixels) exactly."""
    scene = Scene("inside-aimed-box")
    scene.add_mesh("box", "box", scale=8.0, color=(0.8, 0.7, 0.5), checker=0.3)
    aim(scene, (0.0, 0.0, 0.0), N)
    return scene


def turned(scene: Scene, euler: tuple[float, float, float]) -> Scene:
    """Every transform (camera included) turned about the origin."""
    q = quat_from_euler_deg(euler)
    r = quat_to_matrix(q)
    for entity, transform in scene.query(Transform):
        position = tuple(float(c) for c in r @ np.asarray(transform.position))
        rotation = tuple(float(c) for c in quat_multiply(q, np.asarray(transform.rotation)))
        scene.set(entity, replace(transform, position=position, rotation=rotation))
    return scene


CLOSED: dict[str, tuple[Callable[[Path], Scene], tuple[int, int]]] = {
    "aimed-box": (inside_aimed_box, (N, N)),
    "grid-cube-turned-1e3": (
        lambda f: translated(turned(inside_grid_cube(f, "diagonals"), (17.0, -31.0, 7.0)), (1000.3, -999.7, 1000.1)),
        (64, 64),
    ),
    "grid-vertices-1e5": (lambda f: translated(inside_grid_cube(f, "vertices"), (1e5, 1e5, -1e5)), (65, 65)),
    "sphere-1e3": (lambda f: translated(inside_sphere(f), (-1000.0, 500.25, 1000.5)), SIZE),
}


@pytest.mark.parametrize("case", list(CLOSED))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_closed_meshes_have_no_holes(backend_factory, reference, folder, backend_name, precision, case):
    """The camera inside a closed mesh (turned, far from the origin): every ray hits it, none falls through
    a shared edge or vertex."""
    build, size = CLOSED[case]
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: build(folder), size)
    assert_clean(frame)
    holes = int(np.sum(frame.instance < 0))
    assert holes == 0, f"{holes} rays fell through"
    if is_fast(backend_name):  # rays through the edges between two faces of a cube may take either's shade
        assert_agrees(frame, reference(case, lambda: build(folder), size), precision, color_off_max=0.05)


# --- degenerate and sliver triangles ----------------------------------------------------------------------------


def fan_ply(folder: Path, n: int = 1024) -> Path:
    """A disc of radius 3 cut into ``n`` slivers around one shared centre vertex, each followed by two
    zero-area triangles (a repeated vertex, three collinear points)."""
    path = folder / f"fan{n}.ply"
    if not path.exists():
        angles = 2.0 * np.pi * np.arange(n) / n
        rim = np.column_stack([3.0 * np.cos(angles), 3.0 * np.sin(angles), np.zeros(n)])
        rim[np.abs(rim) < 1e-12] = 0.0  # exact axis spokes: the centre row and column run along shared edges
        vertices = np.vstack([[0.0, 0.0, 0.0], rim, 0.5 * rim])  # 0: centre, 1..n: rim, n+1..2n: half-way
        faces = []
        for k in range(n):
            a, b = 1 + k, 1 + (k + 1) % n
            faces += [(0, a, b), (a, a, b), (0, n + 1 + k, a)]  # a sliver; two zero-area triangles
        trimesh.Trimesh(vertices, np.array(faces), process=False).export(path)
    return path


def degenerate_ply(folder: Path) -> Path:
    """Only zero-area triangles: repeated vertices, collinear points, a point (exact in float32)."""
    path = folder / "degenerate.ply"
    if not path.exists():
        rng = np.random.default_rng(3)
        vertices, faces = [], []
        for _ in range(300):
            p = rng.integers(-64, 64, 3) / 16.0
            d = rng.integers(-8, 8, 3) / 8.0
            k = len(vertices)
            vertices += [p, p + d, p + 2.0 * d, p + 0.5 * d]
            faces += [(k, k + 1, k + 2), (k, k, k + 1), (k + 3, k + 3, k + 3), (k + 2, k + 3, k)]
        trimesh.Trimesh(np.array(vertices), np.array(faces), process=False).export(path)
    return path


def fan_scene(folder: Path) -> Scene:
    scene = Scene("sliver-fan")
    scene.add_asset("fan", path=fan_ply(folder))
    scene.add_mesh("fan", "fan", position=(0.0, 0.0, -4.0), color=(0.9, 0.6, 0.2), checker=0.2)
    aim(scene, (0.0, 0.0, 0.0), N)
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_sliver_triangles_leave_no_holes(backend_factory, reference, folder, backend_name, precision):
    """1024 slivers sharing one vertex (the centre ray meets it exactly; the centre row and column run along
    shared spokes), with zero-area triangles mixed in: every ray inside the disc hits it."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: fan_scene(folder), (N, N))
    assert_clean(frame)
    slope = (np.arange(N) - 48) / 48
    sx, sy = np.meshgrid(slope, -slope)
    inside = np.hypot(4.0 * sx, 4.0 * sy) < 3.0 - 0.05
    outside = np.hypot(4.0 * sx, 4.0 * sy) > 3.0 + 0.05
    assert inside[48, 48] and inside.sum() > 3000
    assert np.all(frame.instance[inside] >= 0), f"{int(np.sum(frame.instance[inside] < 0))} rays fell through"
    assert np.all(frame.instance[outside] == -1)
    if is_fast(backend_name):
        assert_agrees(frame, reference("fan", lambda: fan_scene(folder), (N, N)), precision)


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_zero_area_triangles_are_never_hit(backend_factory, folder, backend_name, precision):
    """A mesh made only of zero-area triangles, turned, scaled, filling the view: nothing is hit, nothing NaN."""
    backend = backend_factory(backend_name, precision)

    def build() -> Scene:
        scene = Scene("degenerate")
        scene.add_asset("bad", path=degenerate_ply(folder))
        scene.add_mesh("bad", "bad", position=(0.0, 0.0, -6.0), euler_deg=(10.0, 20.0, 30.0), scale=(2.0, 1.5, 3.0))
        scene.set_camera((0.0, 0.0, 3.0), look_at=(0.0, 0.0, -6.0), fov_deg=70.0)
        return scene

    frame = render_scene(backend, build, SIZE)
    assert_clean(frame)
    assert np.all(frame.instance == -1) and np.all(frame.events == 0)


# --- rays parallel to faces -----------------------------------------------------------------------------------------


def parallel_faces() -> Scene:
    """Aimed rays in faces' planes: the centre row in a floor's top face (y = 0), the centre column in a block's
    side (x = 0), rows 24 and 72 along a slab's faces (y = +-1), plus the silhouettes around them."""
    scene = Scene("parallel-faces")
    scene.add_mesh("wall", "box", position=(0.0, 0.0, -12.5), scale=(60.0, 60.0, 1.0), checker=0.5)
    scene.add_mesh("floor", "box", position=(0.0, -0.5, -6.5), scale=(40.0, 1.0, 11.0), color=(0.4, 0.8, 0.4))
    scene.add_mesh("block", "box", position=(1.0, 1.0, -5.5), scale=(2.0, 2.0, 5.0), color=(0.9, 0.6, 0.3))
    scene.add_mesh("slab", "box", position=(-3.0, 0.0, -6.0), scale=(2.0, 2.0, 4.0), color=(0.3, 0.5, 0.9))
    aim(scene, (0.0, 0.0, 0.0), N)
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_rays_parallel_to_faces(backend_factory, reference, backend_name, precision):
    """No NaN, and the reference's answer wherever a ray is not exactly tangent to a box."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, parallel_faces, (N, N))
    assert_clean(frame)
    scene = parallel_faces()
    try:
        singular = singular_pixels(scene, N, N, box_meshes(scene))
    finally:
        scene.close()
    assert singular[48].all() and singular.sum() > 150
    if is_fast(backend_name):
        ref = reference("parallel", parallel_faces, (N, N))
        assert_agrees(frame, ref, precision, ignore=singular)


# --- far from the origin ------------------------------------------------------------------------------------------

FAR_SCENES: dict[str, Callable[[], Scene]] = {
    "boxes": random_boxes,
    "aberrations": mixed_overlap,
    "portals": portal_in_aberrations,
}
#: About 1e3, 1e5 and 1e6 from the origin, with fractions so the 16-unit cells do not absorb the move.
OFFSETS = {f"{m:.0e}": (m * 1.0000037, -m * 0.9999961, m * 1.00000173) for m in (1e3, 1e5, 1e6)}


@pytest.fixture(scope="module")
def origin_frames() -> Iterator[ReferenceFrames]:
    """The reference's frame of each scene where it was built, near the origin."""
    frames = ReferenceFrames(FAR_SCENES, SIZE)
    yield frames
    frames.release()


def assert_as_at_the_origin(frame: Frame, truth: Frame, precision: str, mismatch_max: float = MISMATCH_MAX) -> None:
    assert_clean(frame)
    result = compare(frame, truth)
    assert result.mismatch <= mismatch_max, result
    if precision == "f64":
        assert result.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result


@pytest.mark.parametrize("offset", list(OFFSETS))
@pytest.mark.parametrize("case", list(FAR_SCENES))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_far_from_the_origin(backend_factory, origin_frames, backend_name, precision, case, offset):
    """Scene and camera moved by 1e3, 1e5, 1e6: the frame the reference renders at the origin."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: translated(FAR_SCENES[case](), OFFSETS[offset]), SIZE)
    assert_as_at_the_origin(frame, origin_frames(case), precision)


#: Far enough that the reference's tolerances (relative to |o|) used to swallow the scene in world coordinates.
FAR_OFFSETS = {f"{m:.0e}": (m * 1.0000037, -m * 0.9999961, m * 1.00000173) for m in (1e9, 1e10, 1e12)}


@pytest.fixture(scope="module")
def far_reference_frames() -> Iterator[ReferenceFrames]:
    """The reference's frame of each scene moved by each of :data:`FAR_OFFSETS`."""
    builders = {
        f"{case}@{offset}": (lambda case=case, offset=offset: translated(FAR_SCENES[case](), FAR_OFFSETS[offset]))
        for case in FAR_SCENES
        for offset in FAR_OFFSETS
    }
    frames = ReferenceFrames(builders, SIZE)
    yield frames
    frames.release()


@pytest.mark.parametrize("offset", list(FAR_OFFSETS))
@pytest.mark.parametrize("case", list(FAR_SCENES))
def test_the_reference_far_from_the_origin_is_the_frame_at_the_origin(
    origin_frames, far_reference_frames, case, offset
):
    """It traces camera-relative, as the fast backends do: 1e10 away it used to hit 0.1 % of pixels, 1e12 none.
    (At 1e12 the scene file's own float64 positions are 1.2e-4 apart: a few edge pixels move, in every backend.)"""
    result = compare(far_reference_frames(f"{case}@{offset}"), origin_frames(case))
    assert result.mismatch <= MISMATCH_MAX, result


@pytest.mark.parametrize("offset", list(FAR_OFFSETS))
@pytest.mark.parametrize("case", list(FAR_SCENES))
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_far_from_the_origin_the_fast_backends_agree_with_the_reference(
    backend_factory, far_reference_frames, backend_name, precision, case, offset
):
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: translated(FAR_SCENES[case](), FAR_OFFSETS[offset]), SIZE)
    assert_as_at_the_origin(frame, far_reference_frames(f"{case}@{offset}"), precision)


# --- object scales -------------------------------------------------------------------------------------------------

SCALES = (1e-4, 1e-2, 1e2, 1e4)


def scaled(scene: Scene, factor: float) -> Scene:
    """Every position and scale (camera included) multiplied by ``factor``: the same view, ``factor`` times bigger."""
    for entity, transform in scene.query(Transform):
        scene.set(
            entity,
            replace(
                transform,
                position=tuple(float(c * factor) for c in transform.position),
                scale=tuple(float(c * factor) for c in transform.scale),
            ),
        )
    return scene


def scale_limit(backend_name: str, precision: str, case: str, factor: float) -> tuple[float, float] | None:
    """(mismatch, depth p99) allowed where float32's absolute t_min floor bites (see the module docstring)."""
    if precision == "f32" and factor <= 1e-4 and case != "boxes":
        return 0.02, 0.1  # measured 1.04 % / 5.9e-3 (aberrations) and 0 % / 3.4e-2 (portals)
    return None


@pytest.mark.parametrize("factor", SCALES)
@pytest.mark.parametrize("case", list(FAR_SCENES))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_object_scales(backend_factory, origin_frames, backend_name, precision, case, factor):
    """Everything (camera distance too) scaled by 1e-4 .. 1e4: the same frame, depth scaled."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: scaled(FAR_SCENES[case](), factor), SIZE)
    truth = origin_frames(case)
    truth = replace(truth, depth=(truth.depth.astype(np.float64) * factor).astype(np.float32))
    assert_clean(frame)
    result = compare(frame, truth)
    limit = scale_limit(backend_name, precision, case, factor)
    if limit is not None:
        assert result.mismatch <= limit[0] and result.depth_p99 <= limit[1], result
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result
        return
    assert result.mismatch <= MISMATCH_MAX, result
    if precision == "f64":
        assert result.depth_p99 <= 3e-7, result  # the scaled float32 depth AOV itself rounds to ~1e-7
    else:
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result


def at_the_size_limit(kind: str) -> Scene:
    """A ball on a floor, and a box (a mesh around everything, or an aberration) scaled by MAX_MAGNITUDE."""
    scene = Scene(f"{kind} at the limit")
    scene.add_mesh("floor", "plane", scale=(10.0, 1.0, 10.0))
    scene.add_mesh("ball", "sphere", position=(0.5, 1.0, 0.0))
    if kind == "mesh":
        scene.add_mesh("huge", "box", position=(0.0, 1.0, -3.0), scale=MAX_MAGNITUDE)
    else:
        scene.add_aberration("huge", (1.0, 0.0, 0.0), position=(0.0, 1.0, 0.0), scale=(MAX_MAGNITUDE, 1.0, 1.0))
    scene.set_camera((0.0, 1.5, 5.0), look_at=(0.0, 1.0, 0.0))
    return scene


@pytest.mark.parametrize("kind", ["mesh", "aberration"])
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_sizes_up_to_the_validation_limit_agree_with_the_reference(
    backend_factory, reference, backend_name, precision, kind
):
    """Scales are refused beyond MAX_MAGNITUDE (1e36); up to it every backend renders what the reference does."""
    frame = render_scene(backend_factory(backend_name, precision), lambda: at_the_size_limit(kind), SIZE)
    assert_clean(frame)
    truth = reference(f"limit-{kind}", lambda: at_the_size_limit(kind), SIZE)
    assert compare(frame, truth).mismatch <= MISMATCH_MAX


# --- a portal at the camera ----------------------------------------------------------------------------------------


def door_ahead(distance: float) -> Scene:
    """Rooms A and B (tests/backends/test_parity_portals.py); the camera ``distance`` in front of door A (z = 0),
    looking straight through it (the door fills the view)."""
    scene = rooms("door-at-the-camera")
    scene.set_camera((0.3, 1.7, distance), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=60.0)
    return scene


#: Distance of the camera in front of the door (negative: just behind it) -> what every backend sees.
DOOR_DISTANCES = {0.0: "own side", 1e-9: "own side", -1e-6: "own side", 1e-4: "through", 1e-2: "through"}
#: Within float32's t_min (1e-5 * |p|, p = (0.3, 1.7, d): 1.7e-5) a float32 backend does not see the door.
F32_UNSEEN = (1e-7, 1e-6, 1e-5)


@pytest.mark.parametrize("distance", [*DOOR_DISTANCES, *F32_UNSEEN])
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_a_portal_at_the_camera(backend_factory, reference, backend_name, precision, distance):
    """On the quad (or within t_min of it) the camera sees its own side; further ahead, through the door."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: door_ahead(distance), SIZE)
    assert_clean(frame)
    expected = DOOR_DISTANCES.get(distance, "own side" if precision == "f32" else "through")
    if expected == "own side":
        assert np.all(frame.events == 0), "the door is not seen: its quad is at the rays' origin"
    else:
        assert np.all(frame.events == 1), "the whole view is through the door"
    if distance in F32_UNSEEN and precision == "f32":  # [LIMIT] the reference sees through the door here
        truth = reference("door@0", lambda: door_ahead(0.0), SIZE)  # the view from the quad, 1e-5 away at most
    else:
        truth = reference(f"door@{distance}", lambda: door_ahead(distance), SIZE)
    assert_as_at_the_origin(frame, truth, precision)


# --- facing portals, turned and scaled ---------------------------------------------------------------------------


def facing_turned_scaled() -> Scene:
    """The facing corridor with door B turned 33 degrees and scaled (1.25, 0.8, 1): every pass turns the ray
    and stretches its direction, until it drifts past a door into the corridor or, where door B reaches
    out through the corridor's walls, out of it (or loops to max_events)."""
    scene = facing_corridor(16, 33.0)
    door = scene.entity("b")
    transform = scene.get(door, Transform)
    scene.set(door, replace(transform, scale=(5.0, 3.2, 1.0)))
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_facing_portals_turned_and_scaled(backend_factory, reference, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, facing_turned_scaled, (N, N))
    assert_clean(frame)
    assert np.all(frame.events <= 16)
    if is_fast(backend_name):
        ref = reference("facing", facing_turned_scaled, (N, N))
        assert (ref.events >= 4).mean() > 0.05
        assert_agrees(frame, ref, precision)


# --- extreme and overlapping aberrations -------------------------------------------------------------------------

EXTREME_D: dict[str, Callable[[], Scene]] = {
    "D=-0.999999": lambda: aimed_boxes(*[(-0.999999,) * 3] * 4),
    "D=1e6": lambda: aimed_boxes(*[(1e6,) * 3] * 4),
    "D=mixed": lambda: aimed_boxes((1e6, -0.999999, 0.0), (1e6, -1e6, 0.5), (-1e6, 1e6, 1e6), (-0.999999, 1e6, 3.0)),
}


@pytest.mark.parametrize("case", list(EXTREME_D))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_extreme_deformations(backend_factory, reference, backend_name, precision, case):
    """D within 1e-6 of -1 and D = 1e6 on the aimed boxes (tests/backends/test_hard_aberrations.py)."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, EXTREME_D[case], (N, N))
    assert_clean(frame)
    if is_fast(backend_name):
        scene = EXTREME_D[case]()
        try:
            singular = singular_pixels(scene, N, N, aberration_boxes(scene))
        finally:
            scene.close()
        ref = reference(case, EXTREME_D[case], (N, N))
        assert_agrees(frame, ref, precision, events_ignore=singular)


def many_overlapping() -> Scene:
    """Twelve boxes of every mode piled on each other in the room, at several priorities, plus an exact
    duplicate of one (same transform and priority: the later wins) and two boxes sharing a face exactly."""
    scene = room("many-overlapping")
    rng = np.random.default_rng(11)
    modes = ("metric", "radial", "additive")
    for k in range(12):
        mode = modes[k % 3]
        d = rng.uniform(-0.6, 0.9, 3) if mode == "metric" else rng.uniform(-0.3, 0.3, 3)
        scene.add_aberration(
            f"pile{k}", tuple(d), mode=mode, exit=("restore", "repeat", "invert")[k % 3],
            position=tuple(rng.uniform([-2.0, 0.5, -3.0], [2.0, 2.0, 2.0])), euler_deg=tuple(rng.uniform(-40, 40, 3)),
            scale=tuple(rng.uniform(1.5, 4.0, 3)), priority=int(k % 4),
        )  # fmt: skip
    scene.add_aberration("twin", (0.0, 0.0, 1.5), position=(0.0, 1.0, -1.0), scale=2.0, priority=5)
    scene.add_aberration("twin_later", (1.5, 0.0, 0.0), position=(0.0, 1.0, -1.0), scale=2.0, priority=5)
    scene.add_aberration("left_half", (0.5, 0.5, 0.0), position=(-1.0, 1.2, 3.0), scale=2.0, priority=6)
    scene.add_aberration("right_half", (-0.4, 0.0, 0.6), position=(1.0, 1.2, 3.0), scale=2.0, priority=6)
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_overlapping_aberrations(backend_factory, reference, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, many_overlapping, SIZE)
    assert_clean(frame)
    if is_fast(backend_name):
        ref = reference("overlapping", many_overlapping, SIZE)
        assert (ref.events >= 4).mean() > 0.1, "most rays should cross several boxes"
        assert_agrees(frame, ref, precision)


# --- portal pairs of very different scale ------------------------------------------------------------------------


def box_room(
    scene: Scene, prefix: str, centre: tuple[float, float, float], k: float, tint: tuple[float, float, float]
) -> None:
    """A closed room 16 x 6 x 16 with a crate and a ball, everything ``k`` times bigger, floor at centre's y."""
    cx, cy, cz = centre
    parts = (
        ("floor", "box", (0, -0.5, 0), (16, 1, 16)), ("ceiling", "box", (0, 6.5, 0), (16, 1, 16)),
        ("north", "box", (0, 3, -8.5), (16, 6, 1)), ("south", "box", (0, 3, 8.5), (16, 6, 1)),
        ("west", "box", (-8.5, 3, 0), (1, 6, 16)), ("east", "box", (8.5, 3, 0), (1, 6, 16)),
        ("crate", "box", (-2.5, 0.6, -4), (1.2, 1.2, 1.2)), ("ball", "sphere", (2.5, 1.0, -5), (1.6, 1.6, 1.6)),
    )  # fmt: skip
    for name, asset, (x, y, z), scale in parts:
        colour = tuple(np.clip(np.asarray(tint) * (0.6 + 0.05 * len(name)), 0.05, 1.0))
        scene.add_mesh(f"{prefix}{name}", asset, position=(cx + k * x, cy + k * y, cz + k * z),
                       scale=tuple(k * c for c in scale), color=colour, checker=0.5 * k)  # fmt: skip


def doors_of_scale(near: float, far: float) -> Scene:
    """Door A (half-size ``near``) in a room of its scale, door B (half-size ``far``) in one of its own, 1e3
    apart; the camera 1.5 half-sizes before door A, which fills most of the view."""
    scene = Scene(f"doors-{near:g}-{far:g}")
    ka, kb = near / 0.01, far / 0.01  # room scale: a 1 cm door in a 16 m room
    box_room(scene, "a_", (0.0, 0.0, 0.0), ka, (1.0, 0.7, 0.7))
    box_room(scene, "b_", (3e5 if kb > ka else 1e3, 0.0, 0.0), kb, (0.7, 1.0, 0.7))
    b_centre = (3e5 if kb > ka else 1e3, 0.0, 0.0)
    scene.add_portal_pair(
        "door_a", "door_b", a={"position": (0.0, 1.8 * ka, 0.0), "scale": (near, near, 1.0)},
        b={"position": (b_centre[0], 1.8 * kb, 3.0 * kb), "scale": (far, far, 1.0)},
    )  # fmt: skip
    scene.set_camera((0.0, 1.8 * ka, 1.5 * near), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=60.0)
    return scene


DOOR_SCALES = {"1e-2 to 1e2": (1e-2, 1e2), "1e2 to 1e-2": (1e2, 1e-2)}


@pytest.mark.parametrize("case", list(DOOR_SCALES))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_portal_pairs_of_very_different_scale(backend_factory, reference, backend_name, precision, case):
    """A 2 cm door onto a 200 m one (L = 1e4) and back: through either, a room like the first, the same
    in every backend; depth stays the world path length."""
    backend = backend_factory(backend_name, precision)
    build = lambda: doors_of_scale(*DOOR_SCALES[case])  # noqa: E731
    frame = render_scene(backend, build, SIZE)
    assert_clean(frame)
    through = frame.events == 1
    assert through.mean() > 0.5 and np.all(frame.instance[through] >= 0)
    if is_fast(backend_name):
        assert_agrees(frame, reference(case, build, SIZE), precision)
    near, far = DOOR_SCALES[case]
    if far > near:  # the far room is 1e4 times bigger: depths through the door are huge
        assert np.median(frame.depth[through]) > 1e4 * near
    assert math.isfinite(float(frame.depth[through].max()))
