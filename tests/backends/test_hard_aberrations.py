"""Hard aberration cases with rays aimed exactly: grazing faces, edges, corners, extreme D, mirrors.

An aimed camera (``scenes.aim``: no rotation, a field of view that gives the
97 x 97 image pixel slopes of k/48) looks at four boxes with integer corners:
a metric box whose corner (1, 1, -4) is met by pixel (36, 60), whose front-left
edge is entered by the whole of column 60 and whose back edges and corner
are only touched by other pixels; a radial and an additive box mirrored into
the other quadrants; and a metric box whose edge x = y = 0 lies on the centre
ray, so the centre row and column graze its faces. Exact in every backend:
the slopes are dyadic and zero components stay zero, in float32 as in float64.

The rules are docs/semantics.md's: a ray in a face's plane is inside that slab
(closed box); an edge or corner crossing is one event; a ray that only touches
an edge or corner is outside just past it; a camera on a face belongs, ray by
ray, to the box the ray goes into. Each backend must give defined output (no
NaN, an answer for every pixel) and agree with the reference: instance
mismatch <= 0.2 %, and the event count may differ only where a primary ray
meets a box's edge, corner or face plane exactly (where counting an empty
crossing or not is decided by rounding) -- elsewhere on <= 0.2 % of pixels.

Measured (glsl and opencl, f32 and f64): instance mismatch 0 to 0.011 %;
event counts differ on 0.5 % (f64) to 1.6 % (f32) of the pixels, all but a
handful of them on the ~700 aimed pixels.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest
from scenes import (
    EVERY,
    FAST,
    ReferenceFrames,
    aberration_boxes,
    aim,
    aimed_pixel,
    assert_agrees,
    render_scene,
    singular_pixels,
)
from test_parity import assert_clean

from backends.reference.backend import ReferenceBackend
from engine.packing import scene_camera
from engine.scene import Scene
from engine.settings import Settings

#: The aimed image: pixel (row j, column i) looks along ((i - 48)/48, (48 - j)/48, -1).
Vec3 = tuple[float, float, float]
N = 97
SIZE = (N, N)
#: Deformations of the four boxes in the ordinary aimed scene.
METRIC_D = (0.6, -0.4, 0.8)
RADIAL_D = (0.5, 0.4, -0.3)
ADDITIVE_D = (0.2, -0.15, 0.1)
EDGE_D = (0.8, -0.4, 0.6)


# --- scenes ----------------------------------------------------------------------------------------------


def aimed_boxes(
    metric: Vec3 = METRIC_D,
    radial: Vec3 = RADIAL_D,
    additive: Vec3 = ADDITIVE_D,
    edge: Vec3 = EDGE_D,
    camera: tuple[float, float, float] = (0.0, 0.0, 0.0),
    without: str | None = None,
) -> Scene:
    """A wall, a 5 x 5 grid of cubes and four boxes with integer faces; ``without`` leaves one box out."""
    scene = Scene("aimed-boxes", settings=Settings(max_events=16))
    scene.add_mesh("wall", "box", position=(0.0, 0.0, -12.5), scale=(60.0, 60.0, 1.0), checker=0.5)
    for k, (x, y) in enumerate((x, y) for x in (-4, -2, 0, 2, 4) for y in (-4, -2, 0, 2, 4)):
        colour = ((k * 37 % 100) / 100, (k * 53 % 100) / 100, 0.6)
        scene.add_mesh(f"cube{k}", "box", position=(x + 0.5, y + 0.5, -9.0), scale=0.9, color=colour)
    boxes = {
        # x in [1, 3], y in [1, 3], z in [-6, -4]
        "metric": dict(deformation=metric, position=(2.0, 2.0, -5.0), scale=2.0),
        # x in [-3, -1], y in [1, 3]
        "radial": dict(deformation=radial, mode="radial", exit="repeat", position=(-2.0, 2.0, -5.0), scale=2.0),
        # x in [-3, -1], y in [-3, -1]
        "additive": dict(deformation=additive, mode="additive", exit="invert", position=(-2.0, -2.0, -5.0), scale=2.0),
        # x in [0, 2], y in [-2, 0], z in [-8, -3]: its edge x = y = 0 is the centre ray
        "edge": dict(deformation=edge, position=(1.0, -1.0, -5.5), scale=(2.0, 2.0, 5.0)),
    }
    for name, box in boxes.items():
        if name != without:
            scene.add_aberration(name, **box)
    aim(scene, camera, N)
    return scene


def uniform(d: float) -> Callable[[], Scene]:
    """Every box deformed by ``d`` on every axis."""
    return lambda: aimed_boxes((d,) * 3, (d,) * 3, (d,) * 3, (d,) * 3)


#: The camera exactly on a face, an edge or a corner of one box: (box, camera, which pixel slopes go into
#: the box). Slopes on the boundary (zero: the ray runs in the face's plane) go in too (closed box).
ON_A_BOX: dict[str, tuple[str, tuple[float, float, float], Callable[[np.ndarray, np.ndarray], np.ndarray]]] = {
    "camera-on-metric-face": ("metric", (2.0, 2.0, -4.0), lambda sx, sy: np.ones_like(sx, dtype=bool)),
    "camera-on-metric-back-face": ("metric", (2.0, 2.0, -6.0), lambda sx, sy: np.zeros_like(sx, dtype=bool)),
    "camera-on-metric-edge": ("metric", (1.0, 2.0, -4.0), lambda sx, sy: sx >= 0),
    "camera-at-metric-corner": ("metric", (1.0, 1.0, -4.0), lambda sx, sy: (sx >= 0) & (sy >= 0)),
    "camera-at-radial-corner": ("radial", (-1.0, 1.0, -4.0), lambda sx, sy: (sx <= 0) & (sy >= 0)),
    "camera-on-additive-edge": ("additive", (-1.0, -2.0, -4.0), lambda sx, sy: sx <= 0),
}

#: Aimed scenes: the ordinary deformations, extreme ones, and the camera exactly on faces, edges, corners.
AIMED: dict[str, Callable[[], Scene]] = {
    "edges-and-corners": aimed_boxes,
    "D=-0.99": uniform(-0.99),
    "D=100": uniform(100.0),
    "mixed-extreme": lambda: aimed_boxes(
        (-0.99, 100.0, 0.5), (30.0, -40.0, 50.0), (5.0, -8.0, 3.0), (100.0, 0.0, -0.99)
    ),
    **{name: (lambda camera=camera: aimed_boxes(camera=camera)) for name, (_, camera, _) in ON_A_BOX.items()},
    "camera-on-the-edge-ray": lambda: aimed_boxes(camera=(0.0, 0.0, -3.0)),
}


def tunnel(box: dict | None) -> Scene:
    """The thesis's mirror problem: a white tunnel, an aberration at its mouth, coloured walls behind the camera."""
    scene = Scene("mirror-tunnel", settings=Settings(background=(0.3, 0.5, 0.8)))
    scene.add_mesh("ground", "box", position=(0.0, -0.5, 0.0), scale=(60.0, 1.0, 60.0), color=(0.5, 0.6, 0.4),
                   checker=0.5)  # fmt: skip
    white = (0.95, 0.95, 0.95)
    for name, position, scale in (
        ("tunnel_floor", (0.0, 0.05, -10.0), (4.0, 0.1, 20.0)),
        ("tunnel_left", (-2.25, 1.5, -10.0), (0.5, 3.0, 20.0)),
        ("tunnel_right", (2.25, 1.5, -10.0), (0.5, 3.0, 20.0)),
        ("tunnel_roof", (0.0, 3.25, -10.0), (5.0, 0.5, 20.0)),
        ("tunnel_end", (0.0, 1.5, -20.25), (4.0, 3.0, 0.5)),
    ):
        scene.add_mesh(name, "box", position=position, scale=scale, color=white, checker=0.25)
    for k, (x, colour) in enumerate(((-3.0, (0.9, 0.2, 0.2)), (0.0, (0.2, 0.9, 0.2)), (3.0, (0.2, 0.2, 0.9)))):
        scene.add_mesh(f"behind{k}", "box", position=(x, 1.5, 14.0), scale=(2.5, 3.0, 1.0), color=colour)
    if box is not None:
        scene.add_aberration("mouth", position=(0.0, 1.5, -1.0), scale=(4.0, 3.0, 2.0), **box)
    scene.set_camera((0.3, 1.6, 6.0), look_at=(0.0, 1.4, -10.0), fov_deg=50.0)
    return scene


#: Mirror cases: bends large enough to turn rays back out of the face they came in by.
MIRRORS: dict[str, dict] = {
    "radial-mirror": dict(deformation=(0.5, 0.5, -3.0), mode="radial"),
    "radial-mirror-repeat": dict(deformation=(0.8, -0.6, -2.5), mode="radial", exit="repeat"),
    "additive-mirror": dict(deformation=(0.3, 0.2, 2.5), mode="additive", exit="invert"),
}
MIRROR_SIZE = (112, 84)


@pytest.fixture(scope="module")
def aimed_reference() -> Iterator[ReferenceFrames]:
    frames = ReferenceFrames(AIMED, SIZE)
    yield frames
    frames.release()


@pytest.fixture(scope="module")
def mirror_reference() -> Iterator[ReferenceFrames]:
    builders: dict[str, Callable[[], Scene]] = {name: (lambda box=box: tunnel(box)) for name, box in MIRRORS.items()}
    builders["plain"] = lambda: tunnel(None)
    frames = ReferenceFrames(builders, MIRROR_SIZE)
    yield frames
    frames.release()


# --- tests -----------------------------------------------------------------------------------------------------


def test_the_aim_is_exact(aimed_reference):
    """The aimed pixels do meet the boxes where the module docstring says (checked in float64, then traced)."""
    scene = aimed_boxes()
    try:
        singular = singular_pixels(scene, N, N, aberration_boxes(scene))
        d = scene_camera(scene).primary_directions(N, N)
    finally:
        scene.close()
    assert singular.sum() > 300, "the scene should aim hundreds of rays at edges, corners and face planes"
    corner = aimed_pixel(N, 0.25, 0.25)  # through (1, 1, -4) into the metric box
    touch = aimed_pixel(N, 1 / 6, 1 / 6)  # only touches its corner (1, 1, -6)
    assert corner == (36, 60) and touch == (40, 56)
    np.testing.assert_allclose(d[corner] / -d[corner][2] * 4.0, (1.0, 1.0, -4.0), rtol=0, atol=1e-14)
    assert singular[corner] and singular[touch]
    assert singular[48, 48] and np.all(singular[48, 49:80]) and np.all(singular[49:80, 48])  # along the edge box
    ref = aimed_reference("edges-and-corners")
    assert_clean(ref)
    assert (ref.events > 0).mean() > 0.25


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_edges_corners_and_grazing_rays_follow_the_rules(backend_factory, backend_name, precision):
    """Defined outcomes of the exactly aimed rays, the same in every backend (docs/semantics.md rule 12)."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, aimed_boxes, SIZE)
    plain = render_scene(backend, lambda: aimed_boxes(without="metric"), SIZE)
    assert_clean(frame)
    # Through a corner into the box: one event in (three faces meet there), one out.
    assert frame.events[36, 60] == 2
    assert frame.depth[36, 60] != pytest.approx(plain.depth[36, 60], rel=1e-3)  # and bent inside
    # Only touching a corner: outside just past it, so the ray goes on as if the box were not there.
    assert frame.instance[40, 56] == plain.instance[40, 56]
    assert frame.depth[40, 56] == pytest.approx(plain.depth[40, 56], rel=1e-6)
    # The centre ray runs along the edge box's edge, the centre row and column in its top and side faces:
    # inside (closed box), so in and out, two events each.
    assert frame.events[48, 48] == 2
    assert np.all(frame.events[48, 49:80] == 2) and np.all(frame.events[49:80, 48] == 2)


@pytest.mark.parametrize("case", list(AIMED))
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_aimed_cases_agree_with_the_reference(backend_factory, aimed_reference, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    ref = aimed_reference(case)
    scene = AIMED[case]()
    try:
        singular = singular_pixels(scene, N, N, aberration_boxes(scene))
    finally:
        scene.close()
    fast = render_scene(backend, AIMED[case], SIZE)
    assert_agrees(fast, ref, precision, events_ignore=singular)


@pytest.mark.parametrize("case", list(ON_A_BOX))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_camera_on_a_face_edge_or_corner(backend_factory, backend_name, precision, case):
    """Each primary ray belongs to the box it goes into: the others see exactly what they would see
    without the box. A metric box keeps the side of every face a ray is on, so its rays leave it
    through a face (an event); a bending box's pre-deformation may turn a ray straight back out
    through the face it starts on (no event: the mirror case at the camera)."""
    box, camera, goes_in = ON_A_BOX[case]
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, AIMED[case], SIZE)
    without = render_scene(backend, lambda: aimed_boxes(camera=camera, without=box), SIZE)
    assert_clean(frame)
    slope = (np.arange(N) - (N - 1) / 2) / ((N - 1) / 2)
    sx, sy = np.meshgrid(slope, -slope)
    inside = goes_in(sx, sy)
    if box == "metric":
        assert np.all(frame.events[inside] >= 1), "a ray starting in a metric box leaves it: an event"
    outside = ~inside
    assert np.array_equal(frame.instance[outside], without.instance[outside])
    np.testing.assert_allclose(frame.depth[outside], without.depth[outside], rtol=1e-6)
    if inside.any():
        bent = np.abs(frame.depth[inside] / without.depth[inside] - 1.0) > 1e-4
        assert bent.mean() > 0.5, "the box should change what most of its rays see"


def cancelling_additive() -> Scene:
    """An additive box with D = (0, 0, 1) across the view: the centre ray's w + D is exactly zero; every other
    ray is turned back (w_z + 1 > 0) and leaves through the face it came in by (a mirror of the empty sky)."""
    scene = Scene("cancelling-additive")
    scene.add_mesh("wall", "box", position=(0.0, 0.0, -12.5), scale=(60.0, 60.0, 1.0), checker=0.5)
    scene.add_mesh("target", "box", position=(0.0, 0.0, -9.0), scale=2.0, color=(0.3, 0.6, 0.9))
    scene.add_aberration("cancel", (0.0, 0.0, 1.0), mode="additive", position=(0.0, 0.0, -4.0), scale=(40, 40, 4))
    aim(scene, (0.0, 0.0, 0.0), N)
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_a_bend_that_cancels_the_direction_keeps_it(backend_factory, backend_name, precision):
    """w + D = 0 exactly (the centre ray): normalisation would divide by zero, so w is kept (rule 11) and
    the ray goes straight on, in and out of the box, to the target's face at z = -8."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, cancelling_additive, SIZE)
    assert_clean(frame)
    assert frame.events[48, 48] == 2
    assert frame.depth[48, 48] == pytest.approx(8.0, rel=1e-6)
    assert frame.instance[48, 48] >= 0
    assert np.sum(frame.instance >= 0) == 1 and np.all(frame.events[frame.instance < 0] == 1)
    if backend_name != "reference":
        assert_agrees(frame, render_scene(ReferenceBackend(), cancelling_additive, SIZE), precision)


@pytest.mark.parametrize("case", list(MIRRORS))
@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_mirror_problem_is_defined_and_agrees(backend_factory, mirror_reference, backend_name, precision, case):
    """Bends that turn rays back out of the tunnel's mouth show what is behind the camera (the thesis's
    "mirror problem"): one event (the entry; no exit is made up), no NaN, the same in every backend."""
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: tunnel(MIRRORS[case]), MIRROR_SIZE)
    scene = tunnel(None)
    try:
        behind = [scene.entity(f"behind{k}") for k in range(3)]
    finally:
        scene.close()
    assert not np.isin(mirror_reference("plain").instance, behind).any(), "nothing behind the camera is in view"
    mirrored = np.isin(frame.instance, behind)
    assert mirrored.mean() > 0.02, "the mouth should mirror what is behind the camera"
    assert np.all(frame.events[mirrored] == 1)
    assert_clean(frame)
    if backend_name != "reference":
        assert_agrees(frame, mirror_reference(case), precision)
