"""Each portal quad's gap to every other quad (engine/packing_space.py, the rows' meta.z): a leg that comes out
of a portal walks the portal tree only from that gap on (LEFT_PORTAL_GAP, backends/shared/portals.h).

The gap is a lower bound of the distance (a quad is the boxes' solid, thickened a little), zero where quads
touch or cross, kept in step when a portal moves, and rounded down to float32; the frames are bit-identical
with the bound on and off in every fast backend, f32 and f64.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from scenes import render_scene
from test_hard_portals import facing_corridor
from test_parity_portals import portal_in_aberrations, portal_through_portal
from test_space_tables import move

from aberrant.bench.space import space_scene
from backends.base import AOVS, Frame
from demos import hotel
from engine.packing import ScenePacker
from engine.scene import Scene

FAST = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("glsl", "f64", id="glsl-f64"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]


def packer_of(scene: Scene, precision: str = "f32") -> ScenePacker:
    if scene.camera_entity is None:
        scene.set_camera((0.0, 1.0, 9.0), look_at=(0.0, 1.0, 0.0))
    packer = ScenePacker(precision)
    packer.sync(scene)
    return packer


def gaps(packer: ScenePacker) -> np.ndarray:
    """The packed gaps, as the kernels read them."""
    packed = packer.packed
    assert packed is not None
    return packed.tables["portals"]["meta"][: packed.counts["portals"], 2].copy().view(np.float32)


def quad_points(scene: Scene, name: str, n: int = 25) -> np.ndarray:
    """An n x n grid of points on a portal's quad ([-1, 1]^2 at z = 0 of its transform), world space."""
    from components import Transform
    from engine.maths import quat_to_matrix

    t = scene.get(scene.entity(name), Transform)
    u = np.linspace(-1.0, 1.0, n)
    local = np.stack(np.meshgrid(u, u), axis=-1).reshape(-1, 2) * np.asarray(t.scale[:2])
    axes = quat_to_matrix(t.rotation)
    return np.asarray(t.position) + local @ axes[:, :2].T


def test_facing_quads_are_their_distance_apart_less_the_slack():
    scene = Scene("facing")
    scene.add_portal_pair("a", "b", a={"position": (0.0, 1.0, 0.0)}, b={"position": (0.0, 1.0, -5.0)})
    g = gaps(packer_of(scene))
    assert np.all(g <= 5.0) and np.all(g > 5.0 - 1e-2), g
    scene.close()


def test_touching_and_crossing_quads_have_no_gap():
    scene = Scene("crossing")
    scene.add_portal_pair("a", "b", a={"position": (0.0, 1.0, 0.0)}, b={"position": (0.0, 1.0, -5.0)})
    scene.add_portal("cross", target="a", position=(0.0, 1.0, 0.5), euler_deg=(0.0, 90.0, 0.0))  # crosses a
    scene.add_portal("edge", target="b", position=(2.0, 1.0, -5.0))  # shares b's edge at x = 1
    g = gaps(packer_of(scene))
    assert g.tolist() == [0.0, 0.0, 0.0, 0.0]
    scene.close()


@pytest.mark.parametrize("seed", range(4))
def test_gaps_stay_below_every_sampled_distance(seed):
    """Turned and scaled quads: no pair of their points lies nearer than either quad's gap."""
    rng = np.random.default_rng(seed)
    scene = Scene("scattered")
    names = [f"p{k}" for k in range(12)]
    for k in range(0, len(names), 2):
        pose = [
            {
                "position": tuple(rng.uniform(-4.0, 4.0, 3)),
                "euler_deg": tuple(rng.uniform(-180.0, 180.0, 3)),
                "scale": (float(rng.uniform(0.3, 2.0)), float(rng.uniform(0.3, 2.0)), 1.0),
            }
            for _ in range(2)
        ]
        scene.add_portal_pair(names[k], names[k + 1], a=pose[0], b=pose[1])
    packer = packer_of(scene)
    g = gaps(packer)
    assert packer.space.portals.entities == [scene.entity(n) for n in names]
    points = [quad_points(scene, n) for n in names]
    nearest = np.full(len(names), np.inf)
    for i in range(len(names)):
        for j in range(i + 1, len(names)):
            d = float(np.sqrt(((points[i][:, None] - points[j][None]) ** 2).sum(axis=2)).min())
            nearest[i], nearest[j] = min(nearest[i], d), min(nearest[j], d)
    assert np.all(g >= 0.0) and np.all(g <= nearest), (g, nearest)
    assert np.any(g > 0.0)
    scene.close()


def test_a_moved_portal_keeps_every_gap_a_fresh_packs():
    """Moving one portal among many re-computes the gaps it changed (its own, its neighbours'), uploads their
    rows, and leaves the table a fresh packer's to the byte."""
    scene = space_scene("portals", "in", 256)
    packer = packer_of(scene)
    before = gaps(packer)
    move(scene, "portal40", (0.0, 0.0, 0.02))  # off the grid's plane, a little nearer its neighbours' partners
    updates = packer.sync(scene)
    changed = np.flatnonzero(gaps(packer) != before)
    uploaded = {r for u in updates if u.table == "portals" and u.rows is not None for r in u.rows}
    assert changed.size and set(changed.tolist()) <= uploaded
    assert len(uploaded) < 40
    fresh = packer_of(scene)
    assert packer.packed.tables["portals"].tobytes() == fresh.packed.tables["portals"].tobytes()
    scene.close()


def hotel_scene(folder: Path) -> Scene:
    return hotel.build()


#: Scenes whose legs come out of portals walking the portal tree (forced on where a scene has few doors: the
#: corridor's two facing ones, doors inside metric and radial boxes, a door seen through a door), and the
#: defines both frames get.
CASES: dict[str, tuple[Callable[[Path], Scene], dict[str, int]]] = {
    "facing-corridor": (lambda folder: facing_corridor(max_events=8, turn_deg=7.0), {"PORTAL_TREE": 1}),
    "portal-in-aberrations": (lambda folder: portal_in_aberrations(), {"PORTAL_TREE": 1}),
    "portal-through-portal": (lambda folder: portal_through_portal(), {"PORTAL_TREE": 1}),
    "portals-in-view": (lambda folder: space_scene("portals", "in", 64), {}),
    "hotel": (hotel_scene, {}),
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_the_gap_bound_is_bit_identical(tmp_path, backend_factory, backend_name, precision, case):
    build, defines = CASES[case]
    backend = backend_factory(backend_name, precision)
    frames: list[Frame] = []
    try:
        for gap in (1, 0):
            backend.extra_defines = {**defines, "LEFT_PORTAL_GAP": gap}
            frames.append(render_scene(backend, lambda: build(tmp_path), (64, 48)))
    finally:
        backend.extra_defines = {}
    assert int(np.asarray(frames[0].events).max()) >= 1
    for name in AOVS:
        assert np.array_equal(frames[0].aov(name), frames[1].aov(name), equal_nan=True), name
