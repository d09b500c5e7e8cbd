"""Portals in the fast backends against the float64 reference (docs/semantics.md).

Room A is around the origin, room B around x = 100, room D around x = 200:
closed rooms far enough apart that one is seen from another only through a
portal. GLSL and OpenCL (float32, and OpenCL float64) render doors between
rooms (straight, turned 180 degrees, of different non-uniform scale), a
portal seen through a portal, portals inside aberrations and facing portals
that use up max_events, and must agree with the reference: instance mismatch
<= 0.2 %, no NaN. An unlinked portal is invisible: bit-identical AOVs to the
scene without it.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
import pytest
from scenes import EVERY, F32_DEPTH_MEDIAN_MAX, F64_DEPTH_P99_MAX, MISMATCH_MAX
from scenes import SPACE_PARITY as FAST
from test_parity import FAR, assert_clean, compare, render, translated

from backends.base import AOVS, Frame
from backends.reference.backend import ReferenceBackend
from backends.reference.shading import to_uint8
from engine.scene import Scene
from engine.settings import Settings

SIZE = (112, 84)
B = (100.0, 0.0, 0.0)
D = (200.0, 0.0, 0.0)


# --- scenes ----------------------------------------------------------------------------------------


def add_room(scene: Scene, prefix: str, centre, tint) -> None:
    """A closed room 16 x 6 x 16 around ``centre`` (floor at y = 0), with a few things in it."""
    cx, cy, cz = centre
    tint = np.asarray(tint, dtype=np.float64)

    def at(x: float, y: float, z: float) -> tuple[float, float, float]:
        return (cx + x, cy + y, cz + z)

    def colour(c) -> tuple[float, ...]:
        return tuple(np.clip(np.asarray(c) * tint, 0.05, 1.0))

    scene.add_mesh(f"{prefix}floor", "box", position=at(0, -0.5, 0), scale=(16, 1, 16), color=colour((0.9, 0.9, 0.9)),
                   checker=0.06)  # fmt: skip
    scene.add_mesh(f"{prefix}ceiling", "box", position=at(0, 6.5, 0), scale=(16, 1, 16), color=colour((0.7, 0.7, 0.7)))
    for name, pos, scale in (
        ("north", (0, 3, -8.5), (16, 6, 1)),
        ("south", (0, 3, 8.5), (16, 6, 1)),
        ("west", (-8.5, 3, 0), (1, 6, 16)),
        ("east", (8.5, 3, 0), (1, 6, 16)),
    ):
        scene.add_mesh(f"{prefix}{name}", "box", position=at(*pos), scale=scale, color=colour((0.8, 0.75, 0.6)),
                       checker=0.1)  # fmt: skip
    scene.add_mesh(f"{prefix}crate", "box", position=at(-2.5, 0.6, -4), euler_deg=(0, 30, 0), scale=1.2,
                   color=colour((0.9, 0.6, 0.2)), checker=0.3)  # fmt: skip
    scene.add_mesh(f"{prefix}ball", "sphere", position=at(2.5, 1.0, -5), scale=1.6, color=colour((0.3, 0.6, 0.9)))
    scene.add_mesh(f"{prefix}pillar", "cylinder", position=at(0.5, 1.5, -6.5), scale=(0.8, 3, 0.8),
                   color=colour((0.8, 0.3, 0.5)))  # fmt: skip


def rooms(name: str, doors: dict | None = None, *, room_d: bool = False, **settings) -> Scene:
    """Rooms A and B (D too if asked), the door pair A -> B (``doors``: per-door transforms), camera in A."""
    scene = Scene(name, settings=Settings(**settings))
    add_room(scene, "a_", (0.0, 0.0, 0.0), (1.0, 0.8, 0.8))
    add_room(scene, "b_", B, (0.8, 1.0, 0.8))
    if room_d:
        add_room(scene, "d_", D, (0.8, 0.8, 1.0))
    doors = doors or {}
    a = doors.get("a", {"position": (0.0, 1.8, 0.0), "scale": (1.6, 1.8, 1.0)})
    b = doors.get("b", {"position": (B[0], 1.8, 3.0), "scale": (1.6, 1.8, 1.0)})
    scene.add_portal_pair("door_a", "door_b", a=a, b=b)
    scene.set_camera((0.5, 1.9, 5.0), look_at=(0.0, 1.6, 0.0), fov_deg=70.0)
    return scene


def doors() -> Scene:
    return rooms("doors")


def rotated_180() -> Scene:
    """Door B turned half a turn about y (and a little about z): rays leave it mirrored, into room B's south half."""
    return rooms(
        "rotated-180",
        {"b": {"position": (B[0] + 1.0, 1.8, -2.0), "euler_deg": (0.0, 180.0, 10.0), "scale": (1.6, 1.8, 1)}},
    )


def non_uniform_scale() -> Scene:
    """Door B of another, non-uniform scale: L = diag(2.5, 2/3, 3) relative to door A."""
    return rooms("non-uniform", {"b": {"position": (B[0], 1.8, 3.0), "scale": (4.0, 1.2, 3.0)}})


def portal_through_portal() -> Scene:
    """Through door A into room B, where door C (seen through door A) leads into room D."""
    scene = rooms("portal-through-portal", room_d=True)
    scene.add_portal_pair(
        "door_c", "door_d",
        a={"position": (B[0] + 0.3, 1.8, -2.0), "euler_deg": (0.0, 15.0, 0.0), "scale": (1.5, 1.6, 1.0)},
        b={"position": (D[0], 1.8, 4.0), "euler_deg": (0.0, -20.0, 0.0), "scale": (1.5, 1.6, 1.0)},
    )  # fmt: skip
    return scene


def portal_in_aberrations() -> Scene:
    """Door A inside a metric box, door B inside a radial box: rays bend on both sides of the trip."""
    scene = rooms("portal-in-aberrations")
    scene.add_aberration("around_a", (0.3, 0.2, 1.5), position=(0.0, 1.8, 0.5), euler_deg=(0, 20, 0), scale=(6, 4, 3))
    scene.add_aberration("around_b", (0.2, -0.15, 0.1), mode="radial", position=(B[0], 1.8, 2.0), scale=(6, 4, 5))
    return scene


def facing(max_events: int) -> Callable[[], Scene]:
    """Two large portals facing each other around the camera: every ray ends at max_events."""

    def build() -> Scene:
        scene = Scene("facing", settings=Settings(max_events=max_events, event_limit_color=(1.0, 0.0, 1.0)))
        scene.add_portal_pair("a", "b", a={"scale": 50.0}, b={"position": (0.0, 0.0, 2.0), "scale": 50.0})
        scene.add_mesh("ball", "sphere", position=(0.0, 0.0, -3.0))  # behind door a: never reached
        scene.set_camera((0.0, 0.0, 1.0), look_at=(0.0, 0.0, 0.0))
        return scene

    return build


CASES: dict[str, Callable[[], Scene]] = {
    "doors": doors,
    "rotated-180": rotated_180,
    "non-uniform-scale": non_uniform_scale,
    "portal-through-portal": portal_through_portal,
    "portal-in-aberrations": portal_in_aberrations,
    "facing-portals": facing(8),
}


@pytest.fixture(scope="module")
def reference_frames():
    backend = ReferenceBackend()
    cache: dict[str, Frame] = {}

    def frame(name: str) -> Frame:
        if name not in cache:
            scene = CASES[name]()
            try:
                cache[name] = render(backend, scene, SIZE)
            finally:
                scene.close()
        return cache[name]

    yield frame
    backend.release()


# --- parity ------------------------------------------------------------------------------------------


@pytest.mark.parametrize("case", [c for c in CASES if c != "facing-portals"])
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_parity_with_the_reference(backend_factory, reference_frames, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    ref = reference_frames(case)
    scene = CASES[case]()
    try:
        fast = render(backend, scene, SIZE)
        assert backend._features.portals
    finally:
        scene.close()
    assert_clean(fast)
    assert_clean(ref)
    assert np.all(ref.instance >= 0), "closed rooms: every ray hits something"
    assert (ref.events > 0).mean() > 0.05, "the case should show a room through a door"
    result = compare(fast, ref)
    assert result.mismatch <= MISMATCH_MAX, result
    if precision == "f64":
        assert result.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result
    assert np.mean(fast.events != ref.events) <= MISMATCH_MAX


@pytest.mark.parametrize("case", ["portal-through-portal", "portal-in-aberrations"])
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_far_from_the_origin(backend_factory, reference_frames, backend_name, precision, case):
    """Rooms, doors and camera moved by 1e5: camera-relative portal tables keep float32 exact enough."""
    backend = backend_factory(backend_name, precision)
    scene = translated(CASES[case](), FAR)
    try:
        fast = render(backend, scene, SIZE)
    finally:
        scene.close()
    assert_clean(fast)
    result = compare(fast, reference_frames(case))
    assert result.mismatch <= MISMATCH_MAX and result.depth_median <= F32_DEPTH_MEDIAN_MAX, result


def test_the_cases_see_what_they_should(reference_frames):
    """Each case shows what it is about (so the parity above compares something)."""
    scene = doors()
    try:
        names = ("floor", "ceiling", "north", "south", "west", "east", "crate", "ball", "pillar")
        b_room = [scene.entity(f"b_{name}") for name in names]
    finally:
        scene.close()
    assert np.isin(reference_frames("doors").instance, b_room).mean() > 0.05
    through = reference_frames("portal-through-portal")
    assert (through.events == 2).mean() > 0.01  # room D through door C, through door A
    bent = reference_frames("portal-in-aberrations")
    assert (bent.events >= 3).mean() > 0.03  # a box face, the door, a box face ...


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_facing_portals_end_at_the_event_limit(backend_factory, reference_frames, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    scene = facing(8)()
    try:
        frame = render(backend, scene, (48, 36))
    finally:
        scene.close()
    assert np.all(frame.color[..., :3] == to_uint8(np.array([1.0, 0.0, 1.0])))
    assert np.all(frame.events == 8) and np.all(frame.instance == -1)
    assert np.all(np.isinf(frame.depth)) and np.all(np.isinf(frame.perceived))


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_unlinked_portal_is_invisible(backend_factory, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    frames = []
    for with_portal in (False, True):
        scene = rooms("unlinked")
        try:
            if with_portal:
                scene.add_portal("loose", position=(0.3, 1.5, 3.0), euler_deg=(10.0, 20.0, 0.0), scale=2.0)
            frames.append(render(backend, scene, (64, 48)))
        finally:
            scene.close()
    for name in AOVS:
        assert np.array_equal(frames[0].aov(name), frames[1].aov(name)), name
