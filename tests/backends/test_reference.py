"""The float64 reference tracer: closed forms, coverage, culling, shading, AOVs, BVH against brute force."""

from __future__ import annotations

import math
import warnings
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scenes import upload as upload_packed

from backends.base import AOVS, backend_class
from backends.reference.backend import ReferenceBackend
from backends.reference.intersect import intersect_triangles, shear_rays
from backends.reference.trace import to_uint8
from backends.reference.traverse import Geometry, nearest_mesh_hits
from backends.upload import SceneUploader
from components import Transform
from engine.camera_view import CameraView, scene_camera
from engine.errors import AberrantError
from engine.layout import TLAS_NODE_DTYPE
from engine.packing import ScenePacker
from engine.scene import Scene
from engine.settings import Settings


def upload(scene: Scene) -> tuple[ReferenceBackend, ScenePacker]:
    """A fresh backend holding ``scene``, packed the way a driver would pack it."""
    backend = ReferenceBackend()
    return backend, upload_packed(backend, scene)


def render(scene: Scene, width: int, height: int):
    backend, _ = upload(scene)
    return backend.render(scene_camera(scene), width, height)


def write_obj(path: Path, vertices, faces, uvs=None) -> Path:
    """A minimal OBJ (1-based faces; ``vt`` lines when UVs are given)."""
    lines = [f"v {x!r} {y!r} {z!r}" for x, y, z in vertices]
    if uvs is not None:
        lines += [f"vt {u!r} {v!r}" for u, v in uvs]
        lines += [f"f {a + 1}/{a + 1} {b + 1}/{b + 1} {c + 1}/{c + 1}" for a, b, c in faces]
    else:
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    path.write_text("\n".join(lines) + "\n")
    return path


def face_camera(scene: Scene, z: float, fov: float = 60.0) -> None:
    """Camera on the z axis looking at the origin."""
    scene.set_camera((0.0, 0.0, z), look_at=(0.0, 0.0, 0.0), fov_deg=fov)


# --- the backend contract -------------------------------------------------------------


def test_backend_contract():
    assert backend_class("reference") is ReferenceBackend
    assert ReferenceBackend.name == "reference"
    assert ReferenceBackend.precisions == ("f64",)
    assert ReferenceBackend.camera_relative is True  # tolerances scale with |o|: trace near the camera
    assert ReferenceBackend.probe() is None
    backend = ReferenceBackend()
    with pytest.raises(AberrantError, match="upload"):
        backend.render(CameraView(np.zeros(3), np.eye(3), 60.0), 4, 4)
    scene = Scene()
    scene.add_mesh("box", "box")
    face_camera(scene, 5.0)
    uploader = SceneUploader(backend)
    sent = uploader.sync(scene)
    assert uploader.packed is not None
    assert sent.nbytes == uploader.packed.update_bytes(sent.updates) > 0
    with pytest.raises(AberrantError, match="AOV"):
        backend.render(scene_camera(scene), 4, 4, aovs=("colour",))


def test_incremental_upload_moves_the_entity():
    scene = Scene()
    box = scene.add_mesh("box", "box")
    face_camera(scene, 5.0)
    backend, packer = upload(scene)
    camera = scene_camera(scene)
    before = backend.render(camera, 32, 32, aovs=("instance",)).instance
    scene.set(box, Transform((1.0, 0.0, 0.0), (0.0, 0.0, 0.0, 1.0), (1.0, 1.0, 1.0)))
    updates = packer.sync(scene)
    assert packer.packed is not None
    row_bytes = packer.packed.tables["instances"].dtype.itemsize
    # A move of its whole size leaves its fat leaf in the top-level tree: that tree row goes up too.
    assert {u.table for u in updates} == {"instances", "tlas_nodes"} and all(u.rows is not None for u in updates)
    tree_rows = sum(len(u.rows) for u in updates if u.table == "tlas_nodes" and u.rows is not None)
    assert backend.upload(packer.packed, updates) == row_bytes + tree_rows * TLAS_NODE_DTYPE.itemsize
    after = backend.render(camera, 32, 32, aovs=("instance",)).instance
    fresh, _ = upload(scene)
    assert np.array_equal(after, fresh.render(camera, 32, 32, aovs=("instance",)).instance)
    assert not np.array_equal(before, after)
    cols = np.flatnonzero((after >= 0).any(axis=0))
    assert cols.min() > 16  # moved to the right of the view centre


# --- closed forms -------------------------------------------------------------------------


def test_box_front_face_depth_closed_form():
    scene = Scene()
    entity = scene.add_mesh("slab", "box", scale=(4.0, 4.0, 1.0))
    face_camera(scene, 5.0)
    backend, _ = upload(scene)
    camera = scene_camera(scene)
    w, h = 64, 48
    d = camera.primary_directions(w, h).reshape(-1, 3)
    result = backend.trace_rays(camera.position, d)
    frame = backend.render(camera, w, h)
    # Where the ray meets the plane z = 0.5 of the front face.
    s = (5.0 - 0.5) / -d[:, 2]
    x, y = s * d[:, 0], s * d[:, 1]
    inside = (np.abs(x) < 2.0 - 1e-9) & (np.abs(y) < 2.0 - 1e-9)
    outside = (np.abs(x) > 2.0 + 1e-9) | (np.abs(y) > 2.0 + 1e-9)
    assert inside.sum() > 100 and outside.sum() > 100
    np.testing.assert_allclose(result.depth[inside], s[inside], rtol=1e-12, atol=0)
    assert np.all(result.instance[inside] == entity)
    assert np.all(np.isinf(result.depth[outside])) and np.all(result.instance[outside] == -1)
    depth = frame.depth.reshape(-1)
    assert np.array_equal(depth[inside], s[inside].astype(np.float32))
    assert np.all(np.isinf(depth[outside])) and np.all(frame.instance.reshape(-1)[outside] == -1)


def _orient(a, b, p) -> Fraction:
    """Exact 2D orientation of p against the directed line a -> b."""
    ax, ay, bx, by, px, py = (Fraction(float(c)) for c in (*a, *b, *p))
    return (bx - ax) * (py - ay) - (by - ay) * (px - ax)


def test_single_triangle_pixel_coverage(tmp_path):
    tri = [(-1.5, -1.25, 0.0), (1.75, -0.5, 0.0), (0.25, 1.5, 0.0)]
    scene = Scene()
    scene.add_asset("tri", path=write_obj(tmp_path / "tri.obj", tri, [(0, 1, 2)]))
    scene.add_mesh("tri", "tri")
    face_camera(scene, 3.0)
    w, h = 48, 40
    frame = render(scene, w, h)
    camera = scene_camera(scene)
    d = camera.primary_directions(w, h).reshape(-1, 3)
    s = 3.0 / -d[:, 2]
    points = np.stack([s * d[:, 0], s * d[:, 1]], axis=1)
    corners = [np.array(v[:2]) for v in tri]
    hit = frame.instance.reshape(-1) >= 0
    mismatches = 0
    for k, p in enumerate(points):
        signs = [_orient(corners[i], corners[(i + 1) % 3], p) for i in range(3)]
        expected = all(o >= 0 for o in signs)
        if expected != hit[k]:
            distances = [abs(float(o)) / np.linalg.norm(corners[(i + 1) % 3] - corners[i]) for i, o in enumerate(signs)]
            assert min(distances) < 1e-9, f"pixel {k} at {p}: expected hit={expected}"
            mismatches += 1
    assert hit.sum() > 200 and mismatches == 0


def test_instance_transforms_agree():
    """A box scaled along x equals a box scaled along z and turned 90 degrees about y."""
    results = []
    for kwargs in ({"scale": (3.0, 1.0, 1.0)}, {"scale": (1.0, 1.0, 3.0), "euler_deg": (0.0, 90.0, 0.0)}):
        scene = Scene()
        scene.add_mesh("box", "box", position=(0.3, 0.2, -1.0), **kwargs)
        scene.set_camera((0.5, 1.5, 4.0), look_at=(0.0, 0.0, -1.0))
        backend, _ = upload(scene)
        camera = scene_camera(scene)
        results.append(backend.trace_rays(camera.position, camera.primary_directions(40, 30).reshape(-1, 3)))
    a, b = results
    hit = np.isfinite(a.depth)
    assert hit.sum() > 100
    assert np.array_equal(hit, np.isfinite(b.depth))
    np.testing.assert_allclose(a.depth[hit], b.depth[hit], rtol=1e-9)


def test_nearest_instance_wins():
    scene = Scene()
    near = scene.add_mesh("near", "box", position=(-0.5, 0.0, 1.0))
    far = scene.add_mesh("far", "box", position=(0.5, 0.0, -1.0), scale=2.0)
    face_camera(scene, 6.0)
    frame = render(scene, 64, 48)
    ids = set(np.unique(frame.instance).tolist())
    assert ids == {-1, near, far}
    # Every near-box pixel is nearer than any far-box pixel, so overlap resolves to the near box.
    assert frame.depth[frame.instance == near].max() < 4.7 < 6.0 <= frame.depth[frame.instance == far].min()


# --- culling and shading ----------------------------------------------------------------


def _quad_scene(camera_z: float, light, cull: bool, color=(0.5, 0.25, 1.0)) -> Scene:
    scene = Scene(settings=Settings(light_dir=light, ambient=0.35))
    scene.add_mesh("quad", "quad", color=color, cull_backfaces=cull)
    face_camera(scene, camera_z)
    return scene


def test_backface_culling():
    front_culled = render(_quad_scene(3.0, (0.3, 0.4, 0.8), cull=True), 24, 24)
    assert (front_culled.instance >= 0).sum() > 100
    back_culled = render(_quad_scene(-3.0, (0.3, 0.4, -0.8), cull=True), 24, 24)
    assert np.all(back_culled.instance == -1) and np.all(np.isinf(back_culled.depth))
    back = render(_quad_scene(-3.0, (0.3, 0.4, -0.8), cull=False), 24, 24)
    front = render(_quad_scene(3.0, (0.3, 0.4, 0.8), cull=False), 24, 24)
    hit = back.instance >= 0
    assert hit.sum() > 100
    # The normal is turned towards the viewer: the back lit from behind equals the front lit from the front.
    assert np.array_equal(back.color[hit], np.fliplr(front.color)[hit])
    ambient_only = to_uint8(np.array([0.5, 0.25, 1.0]) * 0.35)
    assert np.all(back.color[hit][:, 2] > ambient_only[2])


def test_shading_matches_the_formula_exactly():
    scene = _quad_scene(3.0, (0.0, 0.6, 0.8), cull=False)
    frame = render(scene, 16, 16)
    hit = frame.instance >= 0
    light = np.array([0.0, 0.6, 0.8], dtype=np.float32).astype(np.float64)
    n_dot_l = float(light[2] / np.linalg.norm(light))
    base = np.array([0.5, 0.25, 1.0], dtype=np.float32).astype(np.float64)
    expected = [math.floor(c * (0.35 + 0.65 * n_dot_l) * 255 + 0.5) for c in base]
    assert expected == [111, 55, 222]
    assert hit.sum() >= 100
    assert np.all(frame.color[hit] == [*expected, 255])
    background = [math.floor(c * 255 + 0.5) for c in Settings().background]
    assert np.all(frame.color[~hit] == [*background, 255])


def test_to_uint8_rounds_and_clips():
    values = np.array([[-1.0, 0.0, 0.5 / 255], [1.0, 2.0, np.nan]])
    assert to_uint8(values).tolist() == [[0, 0, 1], [255, 255, 0]]


def _checker_expectation(a: np.ndarray, b: np.ndarray, cell: float) -> tuple[np.ndarray, np.ndarray]:
    """Parity of each point and whether it is safely away from cell borders."""
    fa, fb = a / cell, b / cell
    parity = (np.floor(fa) + np.floor(fb)) % 2
    away = (np.abs(fa - np.round(fa)) > 1e-6) & (np.abs(fb - np.round(fb)) > 1e-6)
    return parity, away


def test_uv_checker_cells_alternate():
    scene = Scene(settings=Settings(light_dir=(0.0, 0.0, 1.0)))
    scene.add_mesh("quad", "quad", color=(0.8, 0.6, 0.4), checker=0.25)
    face_camera(scene, 2.5)
    backend, _ = upload(scene)
    camera = scene_camera(scene)
    w = h = 48
    d = camera.primary_directions(w, h).reshape(-1, 3)
    result = backend.trace_rays(camera.position, d)
    color = backend.render(camera, w, h).color.reshape(-1, 4)
    hit = np.isfinite(result.depth)
    p = camera.position + np.where(hit, result.depth, 0.0)[:, None] * d
    u, v = (p[:, 0] + 1.0) / 2.0, (p[:, 1] + 1.0) / 2.0  # the quad's UVs map [-1, 1]^2 onto [0, 1]^2
    parity, away = _checker_expectation(u, v, 0.25)
    sel = hit & away
    bright = to_uint8(np.array([0.8, 0.6, 0.4], dtype=np.float32).astype(np.float64))
    dark = to_uint8(np.array([0.8, 0.6, 0.4], dtype=np.float32).astype(np.float64) * 0.5)
    assert np.all(color[sel & (parity == 0), :3] == bright)
    assert np.all(color[sel & (parity == 1), :3] == dark)
    assert (sel & (parity == 0)).sum() > 50 and (sel & (parity == 1)).sum() > 50


def test_triplanar_checker_uses_world_axes(tmp_path):
    floor = [(-1.0, 0.0, 1.0), (1.0, 0.0, 1.0), (1.0, 0.0, -1.0), (-1.0, 0.0, -1.0)]
    scene = Scene(settings=Settings(light_dir=(0.0, 1.0, 0.0)))
    scene.add_asset("floor", path=write_obj(tmp_path / "floor.obj", floor, [(0, 1, 2), (0, 2, 3)]))
    scene.add_mesh("floor", "floor", position=(0.3, -1.0, -0.2), scale=3.0, color=(0.9, 0.9, 0.9), checker=0.7)
    scene.set_camera((0.0, 2.0, 3.0), look_at=(0.0, -1.0, -0.5))
    backend, packer = upload(scene)
    assert packer.packed is not None and packer.packed.tables["instances"]["meta"][0, 3] == 0  # no UVs
    camera = scene_camera(scene)
    w, h = 48, 36
    d = camera.primary_directions(w, h).reshape(-1, 3)
    result = backend.trace_rays(camera.position, d)
    hit = np.isfinite(result.depth)
    p = camera.position + np.where(hit, result.depth, 0.0)[:, None] * d
    parity, away = _checker_expectation(p[:, 2], p[:, 0], 0.7)
    sel = hit & away
    levels = result.color[sel, 0]
    assert np.allclose(levels[parity[sel] == 1] * 2.0, levels[parity[sel] == 0].max())
    assert (parity[sel] == 0).sum() > 50 and (parity[sel] == 1).sum() > 50


# --- AOVs -------------------------------------------------------------------------------------


def test_aovs_dtypes_shapes_and_no_nan():
    scene = Scene()
    ids = {scene.add_mesh("box", "box", checker=0.2), scene.add_mesh("ball", "sphere", position=(1.0, 0.5, 0.0))}
    scene.set_camera((1.0, 1.0, 3.0), look_at=(0.0, 0.0, 0.0))
    backend, _ = upload(scene)
    frame = backend.render(scene_camera(scene), 40, 30)
    assert frame.present() == list(AOVS)
    assert frame.color.shape == (30, 40, 4) and frame.color.dtype == np.uint8
    assert np.all(frame.color[..., 3] == 255)
    for name in ("depth", "perceived"):
        image = frame.aov(name)
        assert image.shape == (30, 40) and image.dtype == np.float32
        assert not np.any(np.isnan(image))
    assert frame.instance.shape == (30, 40) and frame.instance.dtype == np.int32
    assert frame.events.shape == (30, 40) and frame.events.dtype == np.uint8
    assert set(np.unique(frame.instance).tolist()) == ids | {-1}
    assert np.array_equal(frame.perceived, frame.depth)
    assert np.array_equal(np.isinf(frame.depth), frame.instance == -1)
    assert np.all(np.isfinite(frame.depth[frame.instance >= 0])) and np.all(frame.depth[frame.instance >= 0] > 0)
    assert np.all(frame.events == 0)
    only = backend.render(scene_camera(scene), 40, 30, aovs=("depth",))
    assert only.present() == ["depth"] and np.array_equal(only.depth, frame.depth)


def test_row_zero_is_top():
    scene = Scene()
    scene.add_mesh("high", "box", position=(0.0, 1.5, 0.0), scale=0.5)
    face_camera(scene, 6.0)
    frame = render(scene, 32, 32)
    rows = np.flatnonzero((frame.instance >= 0).any(axis=1))
    assert rows.size and rows.max() < 16


def test_degenerate_triangles_and_bad_rays(tmp_path):
    verts = [(0, 0, 0), (1, 1, 0), (2, 2, 0), (-1, -1, 0.5), (1, -1, 0.5), (0, 1, 0.5)]
    faces = [(0, 1, 2), (0, 0, 1), (3, 4, 5), (1, 1, 1)]
    scene = Scene()
    scene.add_asset("bad", path=write_obj(tmp_path / "bad.obj", verts, faces))
    entity = scene.add_mesh("bad", "bad", checker=0.3)
    face_camera(scene, 3.0)
    backend, _ = upload(scene)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        frame = backend.render(scene_camera(scene), 32, 32)
        d = np.array([[0, 0, 0], [np.nan, 0, -1], [np.inf, 0, -1], [0, 0, -1], [1e-300, 0, 0]], dtype=float)
        result = backend.trace_rays(np.array([0.0, 0.0, 3.0]), d)
    assert set(np.unique(frame.instance).tolist()) == {-1, entity}
    assert not np.any(np.isnan(frame.depth))
    assert result.instance.tolist() == [-1, -1, -1, entity, -1]
    assert np.all(np.isfinite(result.color))
    geo = backend.geometry
    degenerate = np.flatnonzero(np.linalg.norm(np.cross(geo.v1 - geo.v0, geo.v2 - geo.v0), axis=1) == 0)
    assert degenerate.size == 3
    hits = intersect_triangles(
        np.zeros((3, 3)), np.tile([0, 1, 2], (3, 1)), np.tile([0.0, 0.0, 1.0], (3, 1)),
        geo.v0[degenerate], geo.v1[degenerate], geo.v2[degenerate], np.zeros(3, bool),
    )  # fmt: skip
    assert np.all(np.isinf(hits.t))


# --- BVH traversal against brute force ------------------------------------------------------


def _brute_force(geo: Geometry, origin: np.ndarray, direction: np.ndarray, t_min: np.ndarray):
    """Nearest t and triangle over every triangle of a one-instance scene."""
    m = geo.world_to_object[0]
    o = np.einsum("ij,nj->ni", m[:, :3], origin) + m[:, 3]
    d = np.einsum("ij,nj->ni", m[:, :3], direction)
    sheared = shear_rays(d)
    tris = len(geo.v0)
    best = np.full(len(o), np.inf)
    for k in range(len(o)):
        hit = intersect_triangles(
            np.broadcast_to(o[k], (tris, 3)), np.broadcast_to(sheared.perm[k], (tris, 3)),
            np.broadcast_to(sheared.shear[k], (tris, 3)), geo.v0, geo.v1, geo.v2, np.zeros(tris, bool),
        )  # fmt: skip
        t = np.where(hit.t > t_min[k], hit.t, np.inf)
        best[k] = t.min()
    return best


def test_bvh_traversal_matches_brute_force(tmp_path):
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=1.0)
    assert len(mesh.faces) > 20000
    scene = Scene()
    mesh.export(tmp_path / "ball.ply")
    scene.add_asset("ball", path=tmp_path / "ball.ply")
    entity = scene.add_mesh(
        "ball", "ball", position=(0.2, -0.1, 0.0), euler_deg=(20.0, 35.0, 5.0), scale=(1.0, 0.8, 1.3)
    )
    scene.set_camera((0.4, 0.6, 3.0), look_at=(0.0, 0.0, 0.0))
    backend, _ = upload(scene)
    camera = scene_camera(scene)
    frame = backend.render(camera, 96, 96)
    assert set(np.unique(frame.instance).tolist()) == {-1, entity}
    d = camera.primary_directions(96, 96).reshape(-1, 3)
    rng = np.random.default_rng(7)
    hit_rows = np.flatnonzero(frame.instance.reshape(-1) >= 0)
    miss_rows = np.flatnonzero(frame.instance.reshape(-1) < 0)
    rows = np.concatenate([rng.choice(hit_rows, 160, replace=False), rng.choice(miss_rows, 40, replace=False)])
    origin = np.broadcast_to(camera.position, (len(rows), 3))
    t_min = np.full(len(rows), 1e-9 * max(1.0, float(np.linalg.norm(camera.position))))
    expected = _brute_force(backend.geometry, origin, d[rows], t_min)
    traversed = nearest_mesh_hits(backend.geometry, np.ascontiguousarray(origin), d[rows], t_min)
    np.testing.assert_array_equal(np.isfinite(traversed.t), np.isfinite(expected))
    np.testing.assert_allclose(traversed.t, expected, rtol=1e-12)
    depth = frame.depth.reshape(-1)[rows]
    np.testing.assert_array_equal(depth, expected.astype(np.float32))


def test_many_instances_match_brute_force():
    """The instance tree and nearest-instance-first order find the same hits as testing every instance."""
    scene = Scene()
    rng = np.random.default_rng(11)
    for k in range(80):
        scene.add_mesh(
            f"box{k}", "box", position=rng.uniform(-4, 4, 3), euler_deg=rng.uniform(-90, 90, 3),
            scale=rng.uniform(0.3, 1.5, 3),
        )  # fmt: skip
    scene.set_camera((0.5, 1.0, 9.0), look_at=(0.0, 0.0, 0.0))
    backend, packer = upload(scene)
    camera = scene_camera(scene)
    d = camera.primary_directions(40, 30).reshape(-1, 3)
    assert packer.packed is not None
    o = np.broadcast_to(camera.position - packer.packed.origin, d.shape).copy()  # the tables' coordinates
    t_min = np.full(len(d), 1e-9 * max(1.0, float(np.linalg.norm(o[0]))))
    geo = backend.geometry
    hits = nearest_mesh_hits(geo, o, d, t_min)
    best_t, best_entity = np.full(len(d), np.inf), np.full(len(d), -1)
    tris = len(geo.v0)
    for row in range(geo.instance_count):
        m = geo.world_to_object[row]
        ob, db = o @ m[:, :3].T + m[:, 3], d @ m[:, :3].T
        sheared = shear_rays(db)
        pairs = np.arange(len(d) * tris)
        ray, tri = pairs // tris, pairs % tris
        hit = intersect_triangles(
            ob[ray], sheared.perm[ray], sheared.shear[ray], geo.v0[tri], geo.v1[tri], geo.v2[tri],
            np.zeros(len(pairs), bool),
        )  # fmt: skip
        t = np.where(hit.t > t_min[ray], hit.t, np.inf).reshape(len(d), tris).min(axis=1)
        closer = t < best_t
        best_t[closer], best_entity[closer] = t[closer], geo.entity[row]
    assert np.isfinite(best_t).sum() > 300
    np.testing.assert_array_equal(np.isfinite(hits.t), np.isfinite(best_t))
    np.testing.assert_allclose(hits.t, best_t, rtol=1e-12)
    found = np.isfinite(best_t)
    assert np.array_equal(geo.entity[hits.instance[found]], best_entity[found])
    assert packer.packed is not None and len(packer.packed.instance_entities) == 80


def test_empty_scene_renders_background():
    scene = Scene()
    face_camera(scene, 3.0)
    frame = render(scene, 8, 6)
    background = [math.floor(c * 255 + 0.5) for c in Settings().background]
    assert np.all(frame.color == [*background, 255])
    assert np.all(frame.instance == -1) and np.all(np.isinf(frame.depth))


def test_a_camera_relative_packing_renders_the_same():
    """Tables packed relative to a far origin (as float32 backends use) trace to the same image."""
    scene = Scene()
    scene.add_mesh("box", "box", position=(1000.5, 2000.25, -3000.0), checker=0.25)
    scene.add_mesh("ball", "sphere", position=(1001.5, 2000.0, -3001.0), checker=0.1)
    scene.set_camera((1000.5, 2000.9, -2997.5), look_at=(1001.0, 2000.1, -3000.5), fov_deg=70.0)
    camera = scene_camera(scene)
    frames = []
    for relative in (False, True):
        backend = ReferenceBackend()
        packer = ScenePacker(precision="f64", camera_relative=relative)
        updates = packer.sync(scene)
        assert packer.packed is not None
        assert np.any(packer.packed.origin != 0) == relative
        backend.upload(packer.packed, updates)
        frames.append(backend.render(camera, 40, 30))
    a, b = frames
    assert np.array_equal(a.instance, b.instance) and (a.instance >= 0).sum() > 100
    np.testing.assert_allclose(a.depth, b.depth, rtol=1e-6)
    assert np.mean(np.any(a.color != b.color, axis=2)) < 0.01


@pytest.mark.parametrize("demo", ["starter", "nested_aberrations", "portal_in_aberration"])
def test_a_frame_traced_in_bands_is_the_frame_traced_at_once(monkeypatch, demo):
    """Big frames are traced a band of rows at a time (bounded memory): bit for bit what one pass gives."""
    import backends.reference.backend as reference_backend
    from demos import build_demo

    scene = build_demo(demo)
    try:
        whole = render_scene_frame(scene, 61, 37)
        monkeypatch.setattr(reference_backend, "RAYS_PER_BAND", 61 * 5 + 7)  # bands of 5 rows, the last of 2
        banded = render_scene_frame(scene, 61, 37)
    finally:
        scene.close()
    for name in AOVS:
        np.testing.assert_array_equal(banded.aov(name), whole.aov(name), err_msg=name)


def render_scene_frame(scene: Scene, width: int, height: int):
    backend, _ = upload(scene)
    return backend.render(scene_camera(scene), width, height)
