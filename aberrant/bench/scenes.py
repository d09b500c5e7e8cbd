"""The scenes ``aberrant bench`` measures, and the builders the pytest benchmarks and parity tests share.

One registry (:func:`bench_scenes`) names every scene with how to build it,
whether it has a fixed frame size (the watertightness views aim pixel
centres at mesh vertices and edges, so only their own size tests anything),
and its group (``bench``, ``demos``, ``hard``, ``overhead``,
``architecture``, ``hotel``, ``space-count``, ``features``). Builders take a folder for
the mesh files they generate, so the files are made once and the scenes
stay plain scene objects.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import trimesh

from aberrant.bench.architecture import architecture_cases, hotel_views
from aberrant.bench.features import FEATURES
from aberrant.bench.space import PLAIN, space_cases, thirty_boxes
from components import Transform
from engine.errors import AberrantError
from engine.scene import Scene
from engine.settings import Settings

#: The far-from-origin scenes are moved by this (camera too): about 1e5 units, with fractions so the
#: floating origin (a 16-unit grid) does not absorb the move exactly.
FAR = (100000.37, -99999.61, 100000.173)


# --- the pytest-benchmark scenes (tests/backends/bench_tracers.py) ---------------------------------------------


def ten_boxes(folder: Path) -> Scene:
    """Ten boxes standing on a checkered floor."""
    scene = Scene("ten-boxes")
    scene.add_mesh("floor", "plane", scale=(40.0, 1.0, 40.0), checker=1.0)
    rng = np.random.default_rng(1)
    for k in range(10):
        scene.add_mesh(
            f"box{k}",
            "box",
            position=(-4.5 + k, 0.5 + 0.3 * (k % 3), -2.0 - 1.5 * (k % 4)),
            euler_deg=(0.0, 17.0 * k, 0.0),
            scale=0.8,
            color=tuple(rng.uniform(0.2, 1.0, 3)),
        )
    scene.set_camera((0.0, 2.5, 6.0), look_at=(0.0, 0.5, -2.0), fov_deg=60.0)
    return scene


def torus(folder: Path, major_sections: int, minor_sections: int) -> Scene:
    """One imported torus filling most of the view (2 * major * minor triangles)."""
    path = folder / f"torus-{major_sections}x{minor_sections}.obj"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        trimesh.creation.torus(
            major_radius=1.0, minor_radius=0.4, major_sections=major_sections, minor_sections=minor_sections
        ).export(path)
    scene = Scene(f"torus-{2 * major_sections * minor_sections}")
    scene.add_asset("torus", path=path)
    scene.add_mesh("torus", "torus", euler_deg=(60.0, 0.0, 0.0), color=(0.9, 0.7, 0.3))
    scene.set_camera((0.0, 0.0, 2.2), look_at=(0.0, 0.0, 0.0), fov_deg=60.0)
    return scene


def mesh_10k(folder: Path) -> Scene:
    return torus(folder, 100, 50)


def mesh_200k(folder: Path) -> Scene:
    return torus(folder, 500, 200)


# --- hard cases (tests/backends/test_parity.py) -------------------------------------------------------------------


def grid_cube(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The cube [-1/2, 1/2]^3, each face an n x n grid of quads with shared vertices and alternating diagonals."""
    ids: dict[tuple[int, int, int], int] = {}
    faces = []

    def vertex(p: tuple[int, int, int]) -> int:
        return ids.setdefault(p, len(ids))

    for axis in range(3):
        u_axis, v_axis = (axis + 1) % 3, (axis + 2) % 3
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    corners = []
                    for du, dv in ((0, 0), (1, 0), (1, 1), (0, 1)):
                        p = [0, 0, 0]
                        p[axis], p[u_axis], p[v_axis] = side, i + du, j + dv
                        corners.append(vertex((p[0], p[1], p[2])))
                    a, b, c, d = corners if side == n else corners[::-1]
                    faces += [(a, b, c), (a, c, d)] if (i + j) % 2 == 0 else [(a, b, d), (b, c, d)]
    vertices = np.array(list(ids), dtype=np.float64) / n - 0.5
    return vertices, np.array(faces)


def grid_cube_ply(folder: Path, n: int = 64) -> Path:
    path = folder / f"grid_cube{n}.ply"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        vertices, faces = grid_cube(n)
        mesh = trimesh.Trimesh(vertices, faces, process=False)
        assert mesh.is_watertight and mesh.is_winding_consistent
        mesh.export(path)
    return path


def inside_grid_cube(folder: Path, view: str) -> Scene:
    """The camera at the centre of a closed 64 x 64-per-face grid cube of side 2: every ray must hit.

    ``vertices``: 65 x 65 pixels whose centre rays pass through grid vertices (and, at the border,
    through the cube's edges); ``diagonals``: 64 x 64 pixels whose rays cross cell centres, on the
    shared diagonal edges; ``corner``: looking into a corner, rays along the faces' shared edges.
    """
    scene = Scene(f"watertight-{view}")
    scene.add_asset("cube", path=grid_cube_ply(folder))
    scene.add_mesh("cube", "cube", scale=2.0, color=(0.8, 0.8, 0.8), checker=0.3)
    if view == "vertices":
        scene.set_camera((0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=2 * math.degrees(math.atan(65 / 64)))
    elif view == "diagonals":
        scene.set_camera((0.0, 0.0, 0.0), rotation=(0.0, 0.0, 0.0, 1.0), fov_deg=90.0)
    else:
        scene.set_camera((0.0, 0.0, 0.0), look_at=(1.0, 1.0, -1.0), fov_deg=100.0)
    return scene


def inside_sphere(folder: Path) -> Scene:
    """The camera inside a placed, closed icosphere (20,480 triangles): every ray must hit."""
    path = folder / "icosphere5.ply"
    if not path.exists():
        folder.mkdir(parents=True, exist_ok=True)
        trimesh.creation.icosphere(subdivisions=5, radius=1.0).export(path)
    scene = Scene("watertight-sphere")
    scene.add_asset("sphere", path=path)
    scene.add_mesh("sphere", "sphere", position=(0.1, -0.2, 0.05), euler_deg=(17.0, 41.0, -8.0), scale=(3.0, 2.0, 2.5))
    scene.set_camera((0.2, 0.1, 0.3), look_at=(1.0, 0.5, -2.0), fov_deg=120.0)
    return scene


def translated(scene: Scene, offset: tuple[float, float, float]) -> Scene:
    """The scene with every transform (camera included) moved by ``offset``."""
    for entity, transform in scene.query(Transform):
        position = tuple(float(p + o) for p, o in zip(transform.position, offset, strict=True))
        scene.set(entity, replace(transform, position=position))
    return scene


def far_ten_boxes(folder: Path) -> Scene:
    """Ten boxes and the camera moved about 1e5 units from the origin: float32 must stay camera-relative."""
    scene = translated(ten_boxes(folder), FAR)
    scene.name = "far-ten-boxes"
    return scene


def facing_portals(folder: Path) -> Scene:
    """Two portals facing each other down a short corridor: most rays loop until ``max_events`` (endless paths)."""
    scene = Scene("facing-portals", settings=Settings(max_events=16))
    scene.add_mesh("floor", "plane", position=(0.0, 0.0, 0.0), scale=(4.0, 1.0, 6.0), checker=0.5)
    scene.add_mesh("crate", "box", position=(1.0, 0.4, -1.0), euler_deg=(0.0, 30.0, 0.0), scale=0.8)
    scene.add_mesh("ball", "sphere", position=(-1.2, 1.6, 0.5), scale=0.5, color=(0.3, 0.6, 0.9))
    size = {"scale": (8.0, 8.0, 1.0)}  # each door fills the view: every ray meets one
    scene.add_portal_pair(
        "door_a", "door_b", a={"position": (0.0, 1.6, -3.0), **size}, b={"position": (0.0, 1.6, 3.0), **size}
    )
    scene.set_camera((0.0, 1.6, 2.0), look_at=(0.0, 1.5, -3.0), fov_deg=60.0)
    return scene


# --- non-Euclidean overhead: ten boxes seen through deformed space ------------------------------------------


def ten_boxes_aberration(folder: Path) -> Scene:
    """Ten boxes behind a metric aberration box that covers the whole view (rays enter, bend and leave)."""
    scene = ten_boxes(folder)
    scene.name = "ten-boxes-aberration"
    scene.add_aberration("lens", (0.3, -0.2, 0.3), position=(0.0, 3.0, 2.5), scale=(14.0, 5.98, 3.0))
    return scene


def ten_boxes_portals(folder: Path) -> Scene:
    """Ten boxes seen through a portal pair whose near door covers the whole view (one teleport per ray)."""
    scene = ten_boxes(folder)
    scene.name = "ten-boxes-portals"
    scene.add_portal_pair(
        "near",
        "far",
        a={"position": (0.0, 2.2, 4.0), "scale": (4.0, 3.0, 1.0)},
        b={"position": (0.0, 2.2, 3.5), "scale": (4.0, 3.0, 1.0)},
    )
    return scene


# --- the registry ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class SceneSpec:
    """A bench scene: its builder, a fixed frame size (``None``: the run's sizes) and its group."""

    name: str
    build: Callable[[Path], Scene]
    group: str
    size: tuple[int, int] | None = None
    description: str = ""
    #: The plain scene this one adds deformed space to: its frames alternate with this scene's.
    baseline: Callable[[Path], Scene] | None = None
    #: Only each backend's base setting: the scene is itself one point of a sweep (``space-count``).
    base_only: bool = False
    #: Samples a pixel of this scene's frames and of its baseline's, whatever --spp (what more samples cost).
    spp: tuple[int, int] | None = None


def _demo_builder(name: str) -> Callable[[Path], Scene]:
    def build(folder: Path) -> Scene:
        from demos import build_demo

        return build_demo(name)

    return build


def _specs() -> dict[str, SceneSpec]:
    from demos import demo_names, describe

    specs = [
        SceneSpec("ten-boxes", ten_boxes, "bench", description="ten boxes and a checkered floor"),
        SceneSpec("mesh-10k", mesh_10k, "bench", description="a 10,000-triangle torus filling the view"),
        SceneSpec("mesh-200k", mesh_200k, "bench", description="a 200,000-triangle torus filling the view"),
    ]
    for name in demo_names():
        specs.append(SceneSpec(name, _demo_builder(name), "demos", description=f"demo: {describe(name)}"))
    specs += [
        SceneSpec(
            "watertight-vertices",
            lambda f: inside_grid_cube(f, "vertices"),
            "hard",
            (65, 65),
            "inside a grid cube, rays through its vertices",
        ),
        SceneSpec(
            "watertight-diagonals",
            lambda f: inside_grid_cube(f, "diagonals"),
            "hard",
            (64, 64),
            "inside a grid cube, rays through shared diagonals",
        ),
        SceneSpec(
            "watertight-corner",
            lambda f: inside_grid_cube(f, "corner"),
            "hard",
            (64, 48),
            "inside a grid cube, looking into a corner",
        ),
        SceneSpec("watertight-sphere", inside_sphere, "hard", (64, 48), "inside a closed icosphere"),
        SceneSpec("far-ten-boxes", far_ten_boxes, "hard", description="ten boxes moved 1e5 from the origin"),
        SceneSpec("facing-portals", facing_portals, "hard", description="two facing portals: endless paths"),
        SceneSpec(
            "ten-boxes-aberration",
            ten_boxes_aberration,
            "overhead",
            description="ten boxes behind a view-filling metric aberration",
            baseline=ten_boxes,
        ),
        SceneSpec(
            "ten-boxes-portals",
            ten_boxes_portals,
            "overhead",
            description="ten boxes through a view-filling portal pair",
            baseline=ten_boxes,
        ),
    ]
    specs += [SceneSpec(name, build, "architecture", description=text) for name, build, text in architecture_cases()]
    for name, build, plain, text in hotel_views():
        specs.append(SceneSpec(name, build, "hotel", description=text, baseline=plain, base_only=True))
    specs.append(SceneSpec(PLAIN, thirty_boxes, "space-count", description="30 boxes and a floor", base_only=True))
    for name, build, description in space_cases():
        specs.append(SceneSpec(name, build, "space-count", description=description, baseline=thirty_boxes,
                               base_only=True))  # fmt: skip
    for f in FEATURES:
        specs.append(SceneSpec(f.name, f.build, "features", description=f"starter: {f.what}", baseline=f.plain,
                               base_only=True, spp=f.spp))  # fmt: skip
    return {spec.name: spec for spec in specs}


def bench_scenes() -> dict[str, SceneSpec]:
    """Every bench scene by name, in report order (the demo registry is read each call)."""
    return _specs()


#: Names that stand for several scenes on the command line.
GROUPS: tuple[str, ...] = (
    "all", "bench", "demos", "hard", "overhead", "architecture", "hotel", "space-count", "features",
)  # fmt: skip

#: What ``--quick`` measures: one of each kind, small.
QUICK_SCENES: tuple[str, ...] = (
    "ten-boxes",
    "mesh-10k",
    "watertight-diagonals",
    "far-ten-boxes",
    "facing-portals",
    "ten-boxes-aberration",
)


def _level_spec(source: str) -> SceneSpec:
    """A scene file or level module given on the command line, opened now so a mistake fails before measuring."""
    from aberrant.levels import open_level

    with open_level(source) as level:
        label = level.label

    def build(folder: Path) -> Scene:
        return open_level(source).scene

    return SceneSpec(source, build, "files", description=label)


def _is_level_file(name: str) -> bool:
    from aberrant.levels import split_source

    return split_source(name) is not None or name.lower().endswith(".json") or Path(name).is_file()


def resolve_scenes(names: list[str] | None, quick: bool = False) -> list[SceneSpec]:
    """The specs named (scene names or groups, in registry order; then scene files and level modules, as given).

    An unknown name is an error naming the choices.
    """
    specs = bench_scenes()
    if not names:
        names = list(QUICK_SCENES) if quick else ["all"]
    chosen: set[str] = set()
    files: dict[str, SceneSpec] = {}
    for name in names:
        if name not in specs and name not in GROUPS and _is_level_file(name):
            files.setdefault(name, _level_spec(name))
        elif name == "all":
            chosen.update(specs)
        elif name in GROUPS:
            chosen.update(n for n, s in specs.items() if s.group == name)
        elif name in specs:
            chosen.add(name)
        else:
            raise AberrantError(f"unknown scene {name!r}; choose from {', '.join([*GROUPS, *specs])}")
    return [spec for name, spec in specs.items() if name in chosen] + list(files.values())
