"""Watertightness of the reference tracer: rays through shared edges and vertices never fall through."""

from __future__ import annotations

from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import trimesh
from scenes import upload_to_reference as upload

from backends.reference.intersect import exact_sign_of_difference, intersect_triangles, shear_rays
from backends.reference.traverse import nearest_mesh_hits
from engine.camera_view import scene_camera
from engine.scene import Scene


def grid_cube(n: int) -> trimesh.Trimesh:
    """The unit cube [-1/2, 1/2]^3, each face an n x n grid of quads with shared vertices.

    Diagonals alternate per cell, so vertices have 4 to 8 triangles around
    them; with n a power of two every coordinate is an exact dyadic fraction.
    """
    index: dict[tuple[int, int, int], int] = {}
    verts: list[tuple[float, float, float]] = []
    faces: list[tuple[int, int, int]] = []

    def vertex(p: tuple[int, int, int]) -> int:
        if p not in index:
            index[p] = len(verts)
            verts.append(tuple(c / n - 0.5 for c in p))
        return index[p]

    for axis in range(3):
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    corners = []
                    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0, 0, 0]
                        p[axis], p[u_axis], p[v_axis] = side, i + du, j + dv
                        corners.append(vertex(tuple(p)))
                    a, b, c, d = corners if side == n else corners[::-1]
                    faces += [(a, b, c), (a, c, d)] if (i + j) % 2 == 0 else [(a, b, d), (b, c, d)]
    mesh = trimesh.Trimesh(np.array(verts), np.array(faces), process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent and mesh.volume > 0
    return mesh


def mesh_scene(tmp_path: Path, mesh: trimesh.Trimesh, **placement) -> tuple[Scene, int]:
    path = tmp_path / "mesh.ply"
    mesh.export(path)
    scene = Scene()
    scene.add_asset("mesh", path=path)
    entity = scene.add_mesh("mesh", "mesh", **placement)
    scene.set_camera((0.0, 0.0, 10.0), look_at=(0.0, 0.0, 0.0))
    return scene, entity


def edge_points(mesh: trimesh.Trimesh, fractions: tuple[float, ...]) -> np.ndarray:
    """Points on every unique edge at the given fractions, plus every vertex (object space)."""
    vertices = mesh.vertices.astype(np.float32).astype(np.float64)  # what the asset stores
    edges = vertices[mesh.edges_unique]
    pts = [vertices] + [edges[:, 0] + f * (edges[:, 1] - edges[:, 0]) for f in fractions]
    return np.concatenate(pts)


def aim_from_outside(targets: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Object-space origins outside, in front of every face at the target (a ray never grazes a fold)."""
    radial = targets / np.linalg.norm(targets, axis=1, keepdims=True)
    return targets + 3.0 * (radial + rng.uniform(-0.25, 0.25, targets.shape))


# --- exact predicates ------------------------------------------------------------------------


def test_exact_sign_of_difference_matches_rationals():
    rng = np.random.default_rng(1)
    a = rng.uniform(-1, 1, 4000) * 10.0 ** rng.integers(-8, 8, 4000)
    b = rng.uniform(-1, 1, 4000)
    # c*d within a few ulps of a*b (or exactly equal): the float64 difference is untrustworthy.
    c = a * (1.0 + rng.integers(-3, 4, 4000) * 2.0**-52)
    d = b.copy()
    d[::3] = np.nextafter(b[::3], np.inf)
    c[::5], d[::5] = b[::5], a[::5]  # exactly equal products
    got = exact_sign_of_difference(a, b, c, d)
    for k in range(len(a)):
        exact = Fraction(a[k]) * Fraction(b[k]) - Fraction(c[k]) * Fraction(d[k])
        assert got[k] == (exact > 0) - (exact < 0), k
    assert np.any(got == 0) and np.any(got > 0) and np.any(got < 0)


@pytest.mark.parametrize("cull", [False, True])
def test_shared_edge_of_two_triangles_is_never_missed(cull):
    """Random triangle pairs sharing an edge; rays aimed at points of that edge hit at least one."""
    rng = np.random.default_rng(2)
    count = 3000
    p, q = rng.normal(size=(count, 3)), rng.normal(size=(count, 3))
    normal = np.cross(q - p, rng.normal(size=(count, 3)))
    side = np.cross(normal, q - p)
    r1 = (p + q) / 2 + side * rng.uniform(0.2, 1.0, (count, 1))
    r2 = (p + q) / 2 - side * rng.uniform(0.2, 1.0, (count, 1)) + normal * rng.uniform(-0.3, 0.3, (count, 1))
    target = p + rng.uniform(0, 1, (count, 1)) * (q - p)
    # From the front of triangle (p, q, r1) (and of (q, p, r2), its consistently wound neighbour).
    n1 = np.cross(q - p, r1 - p)
    origin = target + 2.0 * n1 / np.linalg.norm(n1, axis=1, keepdims=True) + rng.uniform(-0.3, 0.3, (count, 3))
    direction = target - origin
    sheared = shear_rays(direction)
    culls = np.full(count, cull)
    first = intersect_triangles(origin, sheared.perm, sheared.shear, p, q, r1, culls)
    second = intersect_triangles(origin, sheared.perm, sheared.shear, q, p, r2, culls)
    hit = np.isfinite(first.t) | np.isfinite(second.t)
    # Where one triangle faces the ray and the other does not, the edge is a silhouette fold and a
    # ray grazing it may rightly miss; elsewhere the pair covers the edge from both sides.
    front1 = np.einsum("ij,ij->i", n1, direction) < 0
    front2 = np.einsum("ij,ij->i", np.cross(p - q, r2 - q), direction) < 0
    covered = (front1 & front2) if cull else (front1 == front2)
    assert covered.sum() > count // 3
    assert np.all(hit[covered]), f"{np.sum(~hit[covered])} rays fell through a shared edge"


# --- rays aimed exactly at vertices and edges --------------------------------------------------


def test_grid_cube_exact_rays_through_vertices_and_edges(tmp_path):
    """Dyadic geometry and dyadic rays: every ray passes *exactly* through a vertex or an edge."""
    n = 8
    scene, _ = mesh_scene(tmp_path, grid_cube(n))
    scene.set_camera((0.0, 0.0, 0.0), look_at=(0.0, 0.0, -1.0))  # the tables (camera-relative) are then in world units
    geo = upload(scene).geometry
    grid = np.arange(n + 1) / n - 0.5
    half = grid[:-1] + 0.5 / n
    # On a face z = 1/2: vertices, points on grid lines, cell centres (on diagonals).
    uv = (
        [(x, y) for x in grid for y in grid]
        + [(x, y) for x in grid for y in half]
        + [(x, y) for x in half for y in grid]
    )
    uv += [(x, y) for x in half for y in half]
    lateral = [(0.0, 0.0), (0.25, 0.0), (0.0, -0.125), (0.375, 0.25), (-0.5, 0.625)]
    origins, directions, targets = [], [], []
    for axis in range(3):
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        for sign in (1.0, -1.0):
            for a, b in uv:
                for du, dv in lateral:
                    p, d = np.zeros(3), np.zeros(3)
                    p[axis], p[u_axis], p[v_axis] = 0.5 * sign, a, b
                    d[axis], d[u_axis], d[v_axis] = -sign, du, dv
                    origins.append(p - 2.0 * d)
                    directions.append(d)
                    targets.append(p)
    o, d = np.array(origins), np.array(directions)
    assert len(o) > 5000
    hits = nearest_mesh_hits(geo, o, d, np.full(len(o), 1e-9))
    assert np.all(hits.triangle >= 0), f"{np.sum(hits.triangle < 0)} rays fell through"
    assert np.all(hits.t == 2.0)


@pytest.mark.parametrize(
    ("mesh_name", "placement"),
    [
        ("icosphere", {"position": (0.3, -0.2, 0.1), "euler_deg": (17.0, 41.0, -8.0), "scale": (1.3, 0.9, 1.1)}),
        ("grid_cube", {"position": (-0.1, 0.25, 0.05), "euler_deg": (-30.0, 12.0, 55.0), "scale": (2.0, 1.0, 1.5)}),
    ],
)
def test_rays_aimed_at_vertices_and_edges_of_a_placed_mesh_all_hit(tmp_path, mesh_name, placement):
    """Thousands of rays aimed (in float64) at vertices and edge points of a transformed closed mesh."""
    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.5) if mesh_name == "icosphere" else grid_cube(8)
    assert mesh.is_watertight
    scene, _ = mesh_scene(tmp_path, mesh, **placement)
    backend = upload(scene)
    geo = backend.geometry
    m = geo.world_to_object[0]
    to_world = np.linalg.inv(np.vstack([m, [0.0, 0.0, 0.0, 1.0]]))
    local = edge_points(mesh, (0.5, 0.25, 0.8))
    world = local @ to_world[:3, :3].T + to_world[:3, 3]
    origin = aim_from_outside(local, np.random.default_rng(3)) @ to_world[:3, :3].T + to_world[:3, 3]
    direction = world - origin
    distance = np.linalg.norm(direction, axis=1)
    direction /= distance[:, None]
    assert len(origin) > 3000
    hits = nearest_mesh_hits(geo, origin, direction, np.full(len(origin), 1e-9))
    assert np.all(hits.triangle >= 0), f"{np.sum(hits.triangle < 0)} of {len(origin)} rays fell through"
    excess = hits.t - distance
    assert excess.max() <= 1e-12 * distance.max(), excess.max()


# --- rendered: a closed mesh around the camera --------------------------------------------------


@pytest.mark.parametrize(
    "look_at", [(0.0, 0.0, -1.0), (1.0, 1.0, 1.0), (1.0, 0.0, 1.0), (0.0, -1.0, 0.001), (0.3, -0.7, 0.2)]
)
def test_camera_inside_a_closed_mesh_sees_no_background(tmp_path, look_at):
    """From the centre of a tessellated box (and an icosphere) every pixel hits the mesh."""
    for mesh in (grid_cube(8), trimesh.creation.icosphere(subdivisions=3, radius=0.5)):
        scene, entity = mesh_scene(tmp_path, mesh, scale=8.0)
        scene.set_camera((0.0, 0.0, 0.0), look_at=look_at, fov_deg=100.0)
        frame = upload(scene).render(scene_camera(scene), 48, 40, aovs=("instance", "depth", "color"))
        holes = np.sum(frame.instance != entity)
        assert holes == 0, f"{holes} background pixels inside a closed mesh"
        assert np.all(np.isfinite(frame.depth))
