"""Euclidean scenes built like real levels, and the hotel's views against its plain twin.

The torus of ``mesh-10k`` fills the view with small, even triangles: the
easiest case for a BVH. Levels are not like that: a large flat ground seen
at grazing angles, long thin triangles (planks, beams, strips of a lawn)
whose boxes overlap, walls and windows made of many small instances. These
scenes have those traits, and each gets its Embree ratio like every
Euclidean bench scene. The demos' own views count too: ``house`` with its
portals removed and ``hotel`` with every portal closed (a quad where the
portal was) are Euclidean.

The hotel's views are also timed against that closed twin from the same
camera, frames alternated (``SceneSpec.baseline``): what 104 portals cost
over the same level without them, per view.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator
from pathlib import Path

import numpy as np
import trimesh

from components import Portal, Transform
from engine.scene import Scene
from engine.settings import Settings

SKY = Settings(background=(0.58, 0.74, 0.92), light_dir=(0.5, 0.8, 0.35))


def grid_mesh(folder: Path, name: str, cells: int, jitter: float = 0.0) -> Path:
    """A unit square in XZ ([-1/2, 1/2]^2, facing +Y) of ``cells`` x ``cells`` quads, as an OBJ (made once).

    ``jitter`` lifts each inner vertex by up to that much (a fraction of the square), so a lawn is not flat.
    """
    path = folder / f"{name}.obj"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        u = np.linspace(-0.5, 0.5, cells + 1)
        x, z = np.meshgrid(u, u, indexing="ij")
        y = np.zeros_like(x)
        if jitter:
            y[1:-1, 1:-1] = np.random.default_rng(7).uniform(0.0, jitter, (cells - 1, cells - 1))
        vertices = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
        i, j = np.meshgrid(np.arange(cells), np.arange(cells), indexing="ij")
        a = (i * (cells + 1) + j).ravel()
        b, c, d = a + cells + 1, a + cells + 2, a + 1
        faces = np.concatenate([np.column_stack([a, d, c]), np.column_stack([a, c, b])])  # counter-clockwise from +Y
        trimesh.Trimesh(vertices, faces, process=False).export(path)
    return path


def strips_mesh(folder: Path, count: int, length: float, width: float, angle_deg: float) -> Path:
    """``count`` long strips side by side in XZ (two triangles each, ``length`` by ``width``), turned by
    ``angle_deg`` about +Y so that their boxes are far bigger than they are: planks laid diagonally."""
    path = folder / f"strips-{count}x{length:g}x{width:g}-{angle_deg:g}.obj"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        vertices: list[list[float]] = []
        faces: list[list[int]] = []
        for k in range(count):
            x0 = (k - 0.5 * count) * width
            base = len(vertices)
            vertices += [[x0, 0.0, -0.5 * length], [x0 + 0.9 * width, 0.0, -0.5 * length],
                         [x0 + 0.9 * width, 0.0, 0.5 * length], [x0, 0.0, 0.5 * length]]  # fmt: skip
            faces += [[base, base + 3, base + 2], [base, base + 2, base + 1]]
        a = math.radians(angle_deg)
        turn = np.array([[math.cos(a), 0.0, math.sin(a)], [0.0, 1.0, 0.0], [-math.sin(a), 0.0, math.cos(a)]])
        trimesh.Trimesh(np.asarray(vertices) @ turn.T, np.asarray(faces), process=False).export(path)
    return path


def ground_grid(folder: Path) -> Scene:
    """A 256 x 256 ground of 128 x 128 quads (32,768 triangles) seen at eye height, a few blocks standing on it."""
    scene = Scene("ground-grid", settings=SKY)
    scene.add_asset("ground", path=grid_mesh(folder, "ground-128", 128))
    scene.add_mesh("ground", "ground", scale=(256.0, 1.0, 256.0), color=(0.42, 0.62, 0.30), checker=2.0)
    rng = np.random.default_rng(11)
    for k in range(24):
        x, z = float(rng.uniform(-30.0, 30.0)), float(rng.uniform(-80.0, -6.0))
        h = float(rng.uniform(1.0, 6.0))
        scene.add_mesh(f"block{k}", "box", position=(x, 0.5 * h, z), euler_deg=(0.0, float(rng.uniform(0, 90)), 0.0),
                       scale=(float(rng.uniform(1.0, 4.0)), h, float(rng.uniform(1.0, 4.0))),
                       color=tuple(rng.uniform(0.3, 0.95, 3)))  # fmt: skip
    scene.set_camera((0.0, 1.8, 0.0), look_at=(3.0, 0.8, -40.0), fov_deg=70.0)
    return scene


def long_triangles(folder: Path) -> Scene:
    """Long thin triangles and small ones: a deck of 400 diagonal planks (60 x 0.25 each), thin beams crossing
    the view, and a finely tessellated sphere (20,480 small triangles)."""
    scene = Scene("long-triangles", settings=SKY)
    scene.add_asset("deck", path=strips_mesh(folder, 400, 60.0, 0.25, 35.0))
    scene.add_mesh("deck", "deck", color=(0.70, 0.52, 0.34), checker=0.5)
    path = folder / "icosphere5-small.ply"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        trimesh.creation.icosphere(subdivisions=5, radius=0.5).export(path)
    scene.add_asset("ball", path=path)
    scene.add_mesh("ball", "ball", position=(1.5, 1.2, -6.0), scale=2.4, color=(0.9, 0.7, 0.3))
    for k in range(12):
        scene.add_mesh(f"beam{k}", "box", position=(0.0, 2.0 + 0.45 * k, -4.0 - 3.0 * k),
                       euler_deg=(0.0, 20.0 + 13.0 * k, 8.0), scale=(40.0, 0.08, 0.12),
                       color=(0.35, 0.35, 0.40))  # fmt: skip
    scene.set_camera((0.0, 2.2, 4.0), look_at=(0.0, 1.0, -10.0), fov_deg=65.0)
    return scene


def _house(scene: Scene, prefix: str, x: float, z: float, rng: np.random.Generator) -> None:
    """A small house of blocks: walls with two windows a side, a floor, a pyramid roof, a chimney."""
    w, d, h, t = float(rng.uniform(5.0, 7.0)), float(rng.uniform(5.0, 7.0)), 2.8, 0.25
    wall = tuple(rng.uniform(0.6, 0.95, 3))
    for side, (cx, cz, sx, sz) in {"n": (0.0, -0.5 * d, w, t), "s": (0.0, 0.5 * d, w, t),
                                   "w": (-0.5 * w, 0.0, t, d), "e": (0.5 * w, 0.0, t, d)}.items():  # fmt: skip
        along = sx if sx > sz else sz
        # Window holes at a quarter and three quarters of the wall: below sill, above lintel, three piers.
        for name, lo, hi in (("base", 0.0, 0.9), ("top", 2.0, h)):
            scene.add_mesh(f"{prefix}_{side}_{name}", "box", position=(x + cx, 0.5 * (lo + hi), z + cz),
                           scale=(sx, hi - lo, sz), color=wall)  # fmt: skip
        for i, (a, b) in enumerate(((-0.5, -0.35), (-0.15, 0.15), (0.35, 0.5))):
            offset, length = 0.5 * (a + b) * along, (b - a) * along
            px, pz = (x + cx + offset, z + cz) if sx > sz else (x + cx, z + cz + offset)
            scene.add_mesh(f"{prefix}_{side}_pier{i}", "box", position=(px, 1.45, pz),
                           scale=(length, 1.1, sz) if sx > sz else (sx, 1.1, length), color=wall)  # fmt: skip
    scene.add_mesh(f"{prefix}_roof", "pyramid", position=(x, h + 1.0, z), scale=(w + 0.8, 2.0, d + 0.8),
                   color=(0.75, 0.25, 0.2))  # fmt: skip
    scene.add_mesh(f"{prefix}_chimney", "box", position=(x + 0.25 * w, h + 1.4, z - 0.2 * d), scale=(0.5, 1.6, 0.5),
                   color=(0.5, 0.45, 0.42))  # fmt: skip
    scene.add_mesh(f"{prefix}_floor", "box", position=(x, 0.05, z), scale=(w, 0.1, d), color=(0.6, 0.5, 0.4))


def village(folder: Path) -> Scene:
    """Many instances: 30 houses of blocks (windows, roofs, chimneys) along a street, trees, a tessellated lawn."""
    scene = Scene("village", settings=SKY)
    scene.add_asset("lawn", path=grid_mesh(folder, "lawn-96", 96, jitter=0.002))
    scene.add_mesh("lawn", "lawn", scale=(200.0, 1.0, 200.0), color=(0.42, 0.62, 0.30), checker=1.0)
    scene.add_mesh("street", "box", position=(0.0, 0.02, -40.0), scale=(5.0, 0.04, 100.0), color=(0.35, 0.35, 0.38))
    rng = np.random.default_rng(5)
    for k in range(30):
        side, row = (-1.0, k // 2) if k % 2 == 0 else (1.0, k // 2)
        _house(scene, f"house{k}", side * 8.0, -8.0 * row, rng)
        tx, tz = side * 13.0, -8.0 * row - 4.0
        scene.add_mesh(f"tree{k}_trunk", "cylinder", position=(tx, 1.0, tz), scale=(0.4, 2.0, 0.4),
                       color=(0.45, 0.3, 0.2))  # fmt: skip
        scene.add_mesh(f"tree{k}_crown", "sphere", position=(tx, 2.8, tz), scale=2.6, color=(0.2, 0.5, 0.25))
    scene.set_camera((-1.0, 1.7, 6.0), look_at=(1.0, 2.0, -30.0), fov_deg=65.0)
    return scene


def without_portals(scene: Scene) -> Scene:
    """The scene with its portals deleted (doorways open onto whatever lies behind them)."""
    for entity, _ in scene.query(Portal):
        scene.delete(entity)
    return scene


def closed_portals(scene: Scene) -> Scene:
    """The scene with every portal replaced by a quad mesh of the same shape and place: its doors shut."""
    for entity, portal in scene.query(Portal):
        transform = scene.get(entity, Transform)
        name = scene.name_of(entity)
        scene.delete(entity)
        scene.add_mesh(f"{name}_shut", "quad", position=transform.position, rotation=transform.rotation,
                       scale=transform.scale, color=portal.color)  # fmt: skip
    return scene


def _demo(name: str, change: Callable[[Scene], Scene], view: str | None = None) -> Callable[[Path], Scene]:
    def build(folder: Path) -> Scene:
        from demos import build_demo

        scene = change(build_demo(name))
        if view is not None:
            from demos.hotel import views

            eye, look = views()[view]
            scene.set_camera(eye, look_at=look, fov_deg=64.0)
        return scene

    return build


def architecture_cases() -> list[tuple[str, Callable[[Path], Scene], str]]:
    """(name, builder, description) of the Euclidean scenes built like levels."""
    return [
        ("ground-grid", ground_grid, "a 256 x 256 tessellated ground at eye height, 24 blocks on it"),
        ("long-triangles", long_triangles, "400 long diagonal planks, thin beams and a fine sphere"),
        ("village", village, "30 block houses with windows, trees and a tessellated lawn (many instances)"),
        ("house-open", _demo("house", without_portals), "demo: house, its portals removed (view of the demo)"),
        ("hotel-closed", _demo("hotel", closed_portals), "demo: hotel, every portal shut (view of the demo)"),
    ]


def hotel_views() -> Iterator[tuple[str, Callable[[Path], Scene], Callable[[Path], Scene], str]]:
    """(name, builder, plain twin, description) of each hotel view: the level against its doors shut."""
    from demos.hotel import views

    for view in views():
        yield (f"hotel-view-{view}", _demo("hotel", lambda scene: scene, view), _demo("hotel", closed_portals, view),
               f"demo: hotel from its {view} view, against its portals shut")  # fmt: skip
