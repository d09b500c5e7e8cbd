"""The trees over portals and aberration boxes in the fast backends (``space_nodes``, PORTAL_TREE, BOX_TREE).

A ray finds the portal it passes, the box face it crosses and the box that holds a point through the
trees, nearest first, ties to the lower row: the order the tree finds candidates in is unseen, so the
frames are bit-identical to the loops over every portal and box. With many portals and boxes, in view
and out of it, the frames agree with the reference; the device holds the host's trees after moves; a
frame whose camera sees no portal or box takes the Euclidean variant, with the same pixels.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scenes import F32_DEPTH_MEDIAN_MAX, F64_DEPTH_P99_MAX, MISMATCH_MAX, ReferenceFrames, crowded, render_scene
from test_parity import assert_clean, compare, render
from test_parity_aberrations import grazing_and_touching, mixed_overlap
from test_parity_portals import doors, portal_in_aberrations

from aberrant.bench.space import space_scene
from backends.base import AOVS
from components import Transform
from engine.camera_view import pack_camera, scene_camera
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.settings import Settings

TREES_AND_LOOPS = [
    pytest.param("glsl", "f32", id="glsl-f32"),
    pytest.param("opencl", "f32", id="opencl-f32"),
    pytest.param("opencl", "f64", id="opencl-f64"),
]
LOOPS = {"PORTAL_TREE": 0, "BOX_TREE": 0}
TREES = {"PORTAL_TREE": 1, "BOX_TREE": 1}
BINARY = {**TREES, "SPACE_WIDE": 0}  # OpenCL's trees walked as binary ones (its own: 4-wide)
SIZE = (72, 54)

CASES = {
    "doors": doors,
    "portal-in-aberrations": portal_in_aberrations,
    "mixed-overlap": mixed_overlap,
    "grazing-and-touching": grazing_and_touching,
    "portals-40": lambda: crowded("portals", 40, seed=1),
    "boxes-40": lambda: crowded("boxes", 40, seed=2),
    # Deep trees (256 leaves) whose every in-view ray descends to a leaf of the grid and pops back.
    "portals-grid-256": lambda: space_scene("portals", "in", 256),
    "boxes-grid-256": lambda: space_scene("boxes", "in", 256),
}


def same_frames(a, b) -> None:
    for name in AOVS:
        assert np.array_equal(a.aov(name), b.aov(name), equal_nan=True), name


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_the_trees_and_the_loops_give_identical_frames(backend_factory, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    frames = []
    try:
        for defines in (LOOPS, TREES, BINARY):
            backend.extra_defines = dict(defines)
            frames.append(render_scene(backend, CASES[case], SIZE))
    finally:
        backend.extra_defines = {}
    same_frames(frames[0], frames[1])
    same_frames(frames[0], frames[2])
    assert (frames[0].events > 0).any()  # the space is seen


@pytest.fixture(scope="module")
def reference():
    frames = ReferenceFrames(size=SIZE)
    yield frames
    frames.release()


CROWDED = {
    "portals-300-in-view": lambda: crowded("portals", 300, seed=3),
    "boxes-300-in-view": lambda: crowded("boxes", 300, seed=4),
    "portals-300-out-of-view": lambda: crowded("portals", 300, seed=5, in_view=False),
    "boxes-300-out-of-view": lambda: crowded("boxes", 300, seed=6, in_view=False),
}


@pytest.mark.parametrize("case", list(CROWDED))
@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_many_portals_and_boxes_agree_with_the_reference(backend_factory, reference, backend_name, precision, case):
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, CROWDED[case], SIZE)
    truth = reference(case, CROWDED[case])
    assert_clean(frame)
    result = compare(frame, truth)
    assert result.mismatch <= MISMATCH_MAX, result
    if precision == "f64":
        assert result.depth_p99 <= F64_DEPTH_P99_MAX, result
    else:
        assert result.depth_median <= F32_DEPTH_MEDIAN_MAX, result
    seen = (truth.events > 0).mean()
    assert seen > 0.05 if "in-view" in case else seen == 0.0


def move(scene: Scene, name: str, by: tuple[float, float, float]) -> None:
    entity = scene.entity(name)
    t = scene.get(entity, Transform)
    scene.set(entity, replace(t, position=tuple(np.add(t.position, by))))


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_moved_portals_and_boxes_upload_the_hosts_trees(backend_factory, backend_name, precision):
    """Portals and boxes moved a little (inside their fat leaves) and far (refits), uploaded row by row: the
    device's tables are the host's, and the frame is the one a fresh upload of the moved scene gives."""
    backend = backend_factory(backend_name, precision)
    scenes = [crowded("portals", 60, seed=7), crowded("boxes", 60, seed=8)]
    try:
        for scene, names in zip(scenes, (("p3", "p10", "p21"), ("a3", "a10", "a21")), strict=True):
            packer = ScenePacker(
                precision=backend.precision, camera_relative=backend.camera_relative, bvh_width=backend.bvh_width,
                bvh_compact=backend.bvh_compact,
            )  # fmt: skip
            updates = packer.sync(scene)
            backend.upload(packer.packed, updates)
            for name, by in zip(names, ((0.001, 0.0, 0.0), (2.0, 0.5, -1.0), (-3.0, 0.0, 2.0)), strict=True):
                move(scene, name, by)
                updates = packer.sync(scene)
                assert all(u.rows is not None for u in updates if u.table in ("portals", "aberrations"))
                backend.upload(packer.packed, updates)
            for table in ("portals", "aberrations", "space_nodes", "settings"):
                host = packer.packed.tables[table]
                assert backend.read_table(table)[: host.nbytes] == host.tobytes(), table
            moved = backend.render(scene_camera(scene), *SIZE, AOVS)
            fresh = render(backend, scene, SIZE)
            same_frames(moved, fresh)
    finally:
        for scene in scenes:
            scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_a_frame_that_sees_no_portal_or_box_takes_the_euclidean_variant(backend_factory, backend_name, precision):
    """Portals and boxes behind the camera: the host proves no primary ray meets them, and the frame is the
    one of the scene without them (the same kernel); turned towards them, the space's variant runs."""
    backend = backend_factory(backend_name, precision)
    for kind in ("portals", "boxes"):
        scene, plain = crowded(kind, 80, seed=9, in_view=False), crowded(kind, 0, seed=9)
        try:
            render(backend, scene, SIZE)
            features = backend._frame_features(scene_camera(scene), *SIZE)
            assert not features.portals and not features.aberration_modes
            away = render(backend, scene, SIZE)
            same_frames(away, render(backend, plain, SIZE))
            scene.set_camera((0.0, 1.8, 6.0), look_at=(0.0, 1.8, 12.0), fov_deg=70.0)
            render(backend, scene, SIZE)
            features = backend._frame_features(scene_camera(scene), *SIZE)
            assert features.portals or features.aberration_modes
        finally:
            scene.close()
            plain.close()


@pytest.mark.parametrize("case", ["portals-300-in-view", "boxes-300-in-view"])
def test_the_references_trees_give_its_loops_frames(monkeypatch, case):
    """The reference tests each portal and box only with the rays (points) that can reach it: the frame is
    the one of its loops over every row with every ray, to the bit."""
    from backends.reference import space_tree
    from backends.reference.backend import ReferenceBackend

    frames = []
    for tree_min in (space_tree.TREE_MIN, 10**9):
        monkeypatch.setattr(space_tree, "TREE_MIN", tree_min)
        frames.append(render_scene(ReferenceBackend(), CROWDED[case], (40, 30)))
    same_frames(*frames)


def facing_among_many(pairs: int) -> Scene:
    """Two large portals facing each other around the camera (every ray ends at the 16-event limit), among
    ``pairs`` more linked pairs far away. Looping over every portal at every event, GLSL on llvmpipe ran out
    of the driver's loop iterations (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS: 65,535 per invocation, every loop
    of the shader together) from about 2,200 pairs, and its rays stopped after 7 events."""
    scene = Scene("facing-among-many", settings=Settings(max_events=16, event_limit_color=(1.0, 0.0, 1.0)))
    scene.add_portal_pair("a", "b", a={"scale": 50.0}, b={"position": (0.0, 0.0, 2.0), "scale": 50.0})
    for k in range(pairs):
        x, y = 1000.0 + 3.0 * (k % 50), 3.0 * (k // 50)
        scene.add_portal_pair(f"x{k}", f"y{k}", a={"position": (x, y, 0.0)}, b={"position": (x, y, 500.0)})
    scene.add_mesh("ball", "sphere", position=(0.0, 0.0, -3.0))
    scene.set_camera((0.0, 0.0, 1.0), look_at=(0.0, 0.0, 0.0))
    return scene


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_every_ray_takes_all_its_events_among_five_thousand_portals(backend_factory, backend_name, precision):
    backend = backend_factory(backend_name, precision)
    frame = render_scene(backend, lambda: facing_among_many(2500), (32, 24))
    assert np.all(frame.events == 16)
    assert np.all(frame.color[..., :3] == (255, 0, 255))


@pytest.mark.parametrize(("backend_name", "precision"), TREES_AND_LOOPS)
def test_view_tiles_give_the_trees_frames(backend_factory, backend_name, precision):
    """The first legs of camera rays take their portals from the view tiles' lists (engine/view_tiles.py): the
    frames are the tree's, to the bit, from cameras looking into the crowd, standing in a portal's leaf and
    turned at random; with a box holding the camera the tiles are not used."""
    backend = backend_factory(backend_name, precision)
    rng = np.random.default_rng(11)
    scene = crowded("portals", 60, seed=10)
    scene.add_aberration("held", (0.2, 0.0, 0.0), position=(30.0, 1.0, 30.0), scale=(4.0, 4.0, 4.0))
    cameras = [((0.0, 1.8, 6.0), (0.0, 1.0, -3.0)), ((30.0, 1.0, 30.0), (0.0, 1.0, -3.0))]
    for name in ("p4", "p12", "p30"):
        at = np.asarray(scene.get(scene.entity(name), Transform).position)
        cameras.append((tuple(at + rng.uniform(-0.3, 0.3, 3)), tuple(at + rng.uniform(-3.0, 3.0, 3))))
    try:
        tiled = []
        for position, look_at in cameras:
            scene.set_camera(position, look_at=look_at, fov_deg=float(rng.uniform(40.0, 100.0)))
            frames = []
            for defines in ({}, {"VIEW_TILES": 0}):
                backend.extra_defines = dict(defines)
                frames.append(render(backend, scene, SIZE))
            same_frames(*frames)
            backend.extra_defines = {}
            view = scene_camera(scene)
            row = pack_camera(
                view, backend._origin, precision, *SIZE, backend._boxes, backend._bounds, backend._box_tree
            )
            features = backend._frame_features(view, *SIZE)
            tiles = backend._frame_view_tiles(view, *SIZE, features, row)
            tiled.append(tiles is not None and tiles.portals)
        assert tiled[0] and not tiled[1] and sum(tiled) >= 3
    finally:
        backend.extra_defines = {}
        scene.close()
