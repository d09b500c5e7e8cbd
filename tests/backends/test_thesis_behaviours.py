"""What the thesis says the bending modes and exit rules look like, measured on frames.

The thesis this project grew from, "Deforming Space", describes, with figures:

* additive ("unidirectional aberration", Figure 27): adding D to the ray direction
  "moves the elements of the scene" -- the view inside the box is the plain view
  translated, against D (a ray bent towards +x meets what lies to the right, so a
  marker is seen further left);
* radial (Figure 29): "compressing the space in the x axis, making the cube look
  slim" -- a positive D_k spreads rays away from the centre ray along k, so a
  marker looks narrower and off-centre markers move in towards the centre; a
  negative one stretches (wider, moved out); along the view axis (D_z) a positive
  D makes things look nearer (bigger), a negative one "really far away";
* the exit rules (Figures 31-33), for a camera inside a box walking out of it:
  ``repeat`` and ``invert`` make objects beyond the exit jump when the camera
  leaves the box ("the illusion that the user was teleported", "a sudden
  change"); ``restore`` "makes the aberration effect diminish as the camera gets
  closer to the exit ... a smooth transition".

Each behaviour is measured on every backend's frame (marker centroids and
extents from the instance AOV, in pixels), and every fast backend's frame agrees
with the reference's within the parity thresholds: the images are compared with
the reference, not with screenshots.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator

import numpy as np
import pytest
from scenes import EVERY, ReferenceFrames, assert_agrees, centroid, extent, pixels_of, render_scene

from backends.base import Backend, Frame
from engine.scene import Scene

SIZE = (112, 84)
WIDTH, HEIGHT = SIZE
FOV_DEG = 55.0
#: The camera looks along -z at height EYE; the tiles' wall is at z = -10.
EYE = 1.5
CAMERA_Z = 6.0
#: Tiles on the wall: columns -6..6 and rows -4..4, 1.5 apart; (0, 0) is straight ahead.
COLUMNS, ROWS = range(-6, 7), range(-4, 5)


def tiles(box: dict | None = None, camera_z: float = CAMERA_Z) -> Scene:
    """A wall of 13 x 9 coloured tiles (each its own entity) facing the camera, and optionally one box."""
    scene = Scene("tiles")
    scene.add_mesh("wall", "box", position=(0.0, EYE, -10.5), scale=(80.0, 60.0, 1.0), color=(0.9, 0.9, 0.9))
    for i in COLUMNS:
        for j in ROWS:
            colour = ((i + 6) / 12, (j + 4) / 8, 0.5)
            scene.add_mesh(f"tile{i}_{j}", "box", position=(1.5 * i, EYE + 1.5 * j, -9.9), scale=(1.4, 1.4, 0.2),
                           color=colour)  # fmt: skip
    if box is not None:
        scene.add_aberration("box", **box)
    scene.set_camera((0.0, EYE, camera_z), look_at=(0.0, EYE, camera_z - 16.0), fov_deg=FOV_DEG)
    return scene


def tile(scene: Scene, i: int, j: int) -> int:
    return scene.entity(f"tile{i}_{j}")


def tile_ids() -> dict[tuple[int, int], int]:
    """Entity ids of the tiles (the same in every build: the scenes are built identically)."""
    scene = tiles()
    try:
        return {(i, j): tile(scene, i, j) for i in COLUMNS for j in ROWS}
    finally:
        scene.close()


def whole_in_view(frame: Frame, entity: int) -> bool:
    """The entity is seen and touches no border of the frame (so its centroid and extent are whole)."""
    rows, columns = np.nonzero(frame.instance == entity)
    return (
        rows.size > 0 and rows.min() > 0 and columns.min() > 0 and rows.max() < HEIGHT - 1 and columns.max() < WIDTH - 1
    )


#: A box around the tiles (and through the wall), in front of the camera: rays bend on entry and stay bent.
AROUND = {"position": (0.0, EYE, -4.5), "scale": (60.0, 40.0, 13.0)}
ADDITIVE_D = (0.08, 0.05, 0.0)
RADIAL = 0.3
#: The exit rules: a box z in [-2, 8] with the camera inside it, walking towards its exit face z = -2.
EXIT_D = (0.6, 0.0, 0.0)
EXIT_BOX = {"position": (0.0, EYE, 3.0), "scale": (60.0, 40.0, 10.0)}
EXIT_FACE_Z = -2.0
#: The tiles' front faces.
TILE_Z = -9.8
#: Distances of the camera before the exit face (negative: just past it).
APPROACH = (4.0, 2.0, 1.0, 0.05, -0.05)
RULES = ("restore", "repeat", "invert")


def exit_scene(rule: str | None, distance: float) -> Scene:
    """The exit box with ``rule`` (``None``: no box), the camera ``distance`` before its exit face."""
    box = None if rule is None else {"deformation": EXIT_D, "mode": "additive", "exit": rule, **EXIT_BOX}
    return tiles(box, camera_z=EXIT_FACE_Z + distance)


def _builders() -> dict[str, Callable[[], Scene]]:
    builders: dict[str, Callable[[], Scene]] = {
        "plain": tiles,
        "additive": lambda: tiles({"deformation": ADDITIVE_D, "mode": "additive", **AROUND}),
    }
    for axis, k in (("x", 0), ("z", 2)):
        for sign, label in ((1.0, "+"), (-1.0, "-")):
            d = [0.0, 0.0, 0.0]
            d[k] = sign * RADIAL
            builders[f"radial{label}{axis}"] = lambda d=tuple(d): tiles({"deformation": d, "mode": "radial", **AROUND})
    for distance in APPROACH:
        for rule in (None, *RULES):
            builders[f"exit-{rule or 'plain'}@{distance}"] = lambda r=rule, x=distance: exit_scene(r, x)
    return builders


BUILDERS = _builders()


@pytest.fixture(scope="module")
def reference_frames() -> Iterator[ReferenceFrames]:
    frames = ReferenceFrames(BUILDERS, SIZE)
    yield frames
    frames.release()


@pytest.fixture(scope="module")
def ids() -> dict[tuple[int, int], int]:
    return tile_ids()


def frame_of(backend: Backend, reference_frames: ReferenceFrames, name: str, precision: str) -> Frame:
    """``name`` rendered by ``backend``, checked against the reference's frame (the reference's own frame for it)."""
    if backend.name == "reference":
        return reference_frames(name)
    frame = render_scene(backend, BUILDERS[name], SIZE)
    assert_agrees(frame, reference_frames(name), precision)
    return frame


# --- additive: a translation -------------------------------------------------------------------------------


def expected_additive_pixel(target: np.ndarray) -> np.ndarray:
    """Where a point on the tiles' plane is seen through the additive box (float64, by Newton on the slopes).

    A ray of camera-space slopes (u, v) reaches the box's near face (z = 2) straight, then goes on along
    normalize(w + D) to the plane of the point: solved here independently of the tracers.
    """
    camera = np.array([0.0, EYE, CAMERA_Z])
    near_z = AROUND["position"][2] + 0.5 * AROUND["scale"][2]
    d = np.asarray(ADDITIVE_D)

    def lands(slopes: np.ndarray) -> np.ndarray:
        w = np.array([slopes[0], slopes[1], -1.0])
        w /= np.linalg.norm(w)
        entry = camera + (camera[2] - near_z) / -w[2] * w
        bent = (w + d) / np.linalg.norm(w + d)
        return (entry + (entry[2] - target[2]) / -bent[2] * bent)[:2]

    slopes = (target[:2] - camera[:2]) / (camera[2] - target[2])
    for _ in range(20):
        error = lands(slopes) - target[:2]
        jacobian = np.column_stack([(lands(slopes + h) - lands(slopes)) / 1e-7 for h in np.eye(2) * 1e-7])
        slopes = slopes - np.linalg.solve(jacobian, error)
    t = np.tan(np.radians(FOV_DEG) / 2.0)
    column = (slopes[0] / (t * WIDTH / HEIGHT) + 1.0) * WIDTH / 2.0 - 0.5
    row = (1.0 - slopes[1] / t) * HEIGHT / 2.0 - 0.5
    return np.array([column, row])


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_additive_translates_the_view_against_d(backend_factory, reference_frames, ids, backend_name, precision):
    """Every tile moves by (nearly) the same vector, left and down for D = (+x, +y), where the formula says,
    and keeps its size: the view is translated, not distorted."""
    backend = backend_factory(backend_name, precision)
    plain = frame_of(backend, reference_frames, "plain", precision)
    bent = frame_of(backend, reference_frames, "additive", precision)
    shifts = []
    for (i, j), entity in ids.items():
        if not (whole_in_view(plain, entity) and whole_in_view(bent, entity)):
            continue
        shift = centroid(bent, entity) - centroid(plain, entity)
        shifts.append(shift)
        assert shift[0] < -3.0 and shift[1] > 2.0, ((i, j), shift)  # left (against +x), down (against +y)
        target = np.array([1.5 * i, EYE + 1.5 * j, -9.8])  # the tile's front face
        np.testing.assert_allclose(centroid(bent, entity), expected_additive_pixel(target), atol=0.75)
        np.testing.assert_allclose(extent(bent, entity), extent(plain, entity), atol=1.0)
    shifts = np.array(shifts)
    assert len(shifts) >= 20
    assert np.ptp(shifts, axis=0).max() <= 2.0, "a translation moves every tile alike (to a pixel or two)"


# --- radial: compress and stretch ----------------------------------------------------------------------------


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_radial_compresses_and_stretches_across_the_view(
    backend_factory, reference_frames, ids, backend_name, precision
):
    """D_x > 0: tiles narrower and pulled in towards the centre column; D_x < 0: wider and pushed out.
    Heights and rows do not change (D_y = 0 leaves every ray's y/z slope as it is)."""
    backend = backend_factory(backend_name, precision)
    plain = frame_of(backend, reference_frames, "plain", precision)
    centre_column = (WIDTH - 1) / 2.0
    for name, sign in (("radial+x", 1.0), ("radial-x", -1.0)):
        frame = frame_of(backend, reference_frames, name, precision)
        seen = 0
        for (i, j), entity in ids.items():
            if not (whole_in_view(plain, entity) and whole_in_view(frame, entity)):
                continue
            seen += 1
            before, after = extent(plain, entity), extent(frame, entity)
            assert sign * (after[0] - before[0]) < 0, (name, i, j, before, after)
            assert after[1] == pytest.approx(before[1], abs=1.0)
            a, b = centroid(plain, entity), centroid(frame, entity)
            assert b[1] == pytest.approx(a[1], abs=0.5)
            if i != 0:  # off-centre tiles move in (compress) or out (stretch)
                assert sign * (abs(b[0] - centre_column) - abs(a[0] - centre_column)) < -1.0, (name, i, j)
        assert seen >= 6
    # The tile straight ahead: narrower with D_x > 0, wider with D_x < 0, the same height.
    ahead = ids[(0, 0)]
    narrow = frame_of(backend, reference_frames, "radial+x", precision)
    wide = frame_of(backend, reference_frames, "radial-x", precision)
    assert extent(narrow, ahead)[0] < extent(plain, ahead)[0] < extent(wide, ahead)[0]


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_radial_along_the_view_axis_brings_things_near_or_far(
    backend_factory, reference_frames, ids, backend_name, precision
):
    """D_z > 0 draws rays together (tiles bigger, out from the centre: "nearer"); D_z < 0 spreads them
    (smaller, drawn in: "really far away", the thesis's Figure 29)."""
    backend = backend_factory(backend_name, precision)
    plain = frame_of(backend, reference_frames, "plain", precision)
    near = frame_of(backend, reference_frames, "radial+z", precision)
    far = frame_of(backend, reference_frames, "radial-z", precision)
    centre = np.array([(WIDTH - 1) / 2.0, (HEIGHT - 1) / 2.0])
    for key in ((0, 0), (2, 1), (-2, -1), (3, 2)):
        entity = ids[key]
        assert np.all(extent(near, entity) >= extent(plain, entity)), key
        assert np.all(extent(far, entity) <= extent(plain, entity)), key
        area = [int(pixels_of(frame, entity).sum()) for frame in (near, plain, far)]
        if key == (0, 0):  # centred on the pixel grid: its edges move by less than a pixel with D_z = +0.3
            assert area[0] >= area[1] > area[2], (key, area)
        else:
            assert area[0] > area[1] > area[2], (key, area)
        if key != (0, 0):
            out = np.linalg.norm(centroid(near, entity) - centre)
            middle = np.linalg.norm(centroid(plain, entity) - centre)
            assert out > middle + 1.0 > np.linalg.norm(centroid(far, entity) - centre) + 2.0, key


# --- exit rules: walking out of the box -------------------------------------------------------------------------


def changed(a: Frame, b: Frame) -> float:
    """Fraction of pixels that show another entity."""
    return float(np.mean(a.instance != b.instance))


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_exit_rules_restore_fades_repeat_and_invert_jump(
    backend_factory, reference_frames, ids, backend_name, precision
):
    """The camera walks out of an additive box towards the tiles beyond its exit face.

    ``restore``: the tile ahead is displaced in proportion to the distance left to the exit, and
    stepping out of the box changes the view no more than the same step without any box.
    ``repeat`` and ``invert``: just before the exit the view is still bent (further, or back the
    other way), so stepping out of the box makes the view jump.
    """
    backend = backend_factory(backend_name, precision)
    ahead = ids[(0, 0)]
    frames = {
        (rule, distance): frame_of(backend, reference_frames, f"exit-{rule}@{distance}", precision)
        for rule in ("plain", *RULES)
        for distance in APPROACH
    }
    inside, outside = APPROACH[-2], APPROACH[-1]
    step = changed(frames["plain", inside], frames["plain", outside])  # the step itself, without a box
    # Restore: the tile ahead is seen displaced by the sideways travel inside the box, 0.6 per unit of
    # distance left to the exit (the bent ray's slope), which shrinks to nothing at the exit.
    pixel = 2.0 * np.tan(np.radians(FOV_DEG) / 2.0) / HEIGHT  # a pixel's size per unit of distance
    for x in APPROACH[:-1]:
        shift = centroid(frames["restore", x], ahead)[0] - centroid(frames["plain", x], ahead)[0]
        expected = -EXIT_D[0] * x / ((x + EXIT_FACE_Z - TILE_Z) * pixel)
        assert shift == pytest.approx(expected, abs=1.0), (x, shift, expected)
    assert changed(frames["restore", inside], frames["restore", outside]) <= step + 0.02
    # Inside, beyond the exit, the three rules show three different views.
    for a, b in (("restore", "repeat"), ("restore", "invert"), ("repeat", "invert")):
        assert changed(frames[a, 2.0], frames[b, 2.0]) > 0.2, (a, b)
    # Outside the box nothing bends: the three rules give the plain frame.
    for rule in RULES:
        assert np.array_equal(frames[rule, outside].instance, frames["plain", outside].instance)
    # Repeat and invert: still bent at the exit -- further (the tile ahead is out of view or far left),
    # or back the other way (invert over-corrects: it is seen to the right) -- so stepping out jumps.
    for rule in ("repeat", "invert"):
        assert changed(frames[rule, inside], frames[rule, outside]) > step + 0.2, rule
    plain_x = centroid(frames["plain", inside], ahead)[0]
    repeat = frames["repeat", inside]
    assert not (repeat.instance == ahead).any() or centroid(repeat, ahead)[0] < plain_x - 10.0
    assert centroid(frames["invert", inside], ahead)[0] > plain_x + 5.0
