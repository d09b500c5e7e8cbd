"""A sunlit gallery room: coloured blocks, a sphere and a knot on a plinth.

The first scene to render: plain Euclidean space (no aberrations, no
portals), so it exercises meshes, instancing, an imported OBJ file, the
checker material, textures, smooth shading and the lighting, and gives a known-good picture to compare
the backends on.
"""

from __future__ import annotations

from pathlib import Path

from engine.scene import Scene
from engine.settings import Settings

#: Place in the demo gallery (``aberrant demos``); see demos/__init__.py.
ORDER = 0

#: The imported mesh and the textures (demos/assets/make_textures.py), found beside this module so the demo
#: works from any working directory.
KNOT_PATH = Path(__file__).resolve().parent / "assets" / "knot.obj"
PLANKS_PATH = Path(__file__).resolve().parent / "assets" / "planks.png"
TILES_PATH = Path(__file__).resolve().parent / "assets" / "tiles.png"
PLASTER_PATH = Path(__file__).resolve().parent / "assets" / "plaster.png"

# A warm, slightly desaturated palette that reads well under one light.
PLASTER = (0.90, 0.85, 0.76)
SAGE = (0.60, 0.70, 0.64)
TERRACOTTA = (0.84, 0.42, 0.30)
MUSTARD = (0.93, 0.72, 0.26)
TEAL = (0.18, 0.55, 0.58)
INDIGO = (0.30, 0.36, 0.70)
BONE = (0.95, 0.93, 0.88)
GOLD = (0.98, 0.76, 0.32)
FLOOR = (0.84, 0.76, 0.64)


def build() -> Scene:
    """The starter room, viewed from its open front, a little to the right."""
    scene = Scene(
        "starter",
        settings=Settings(background=(0.14, 0.16, 0.21), light_dir=(0.5, 0.9, 0.55), ambient=0.35),
    )
    scene.add_asset("knot", path=KNOT_PATH)
    # The sun over the open front's right: the knot, the plinth and the blocks cast shadows on the floor.
    scene.add_light("daylight", "sun", look_at=(-0.5, -0.9, -0.55), color=(1.0, 0.97, 0.9), intensity=1.1)

    # The room: a checkered floor, a back wall and two side walls, open at the front and top.
    scene.add_mesh("floor", "plane", scale=(10.0, 1.0, 10.0), color=FLOOR, checker=0.05)
    scene.add_mesh(
        "back_wall", "box", position=(0.0, 2.25, -5.1), scale=(10.4, 4.5, 0.2), color=PLASTER, texture=str(PLASTER_PATH)
    )
    scene.add_mesh("left_wall", "box", position=(-5.1, 2.25, 0.0), scale=(0.2, 4.5, 10.4), color=SAGE)
    scene.add_mesh("right_wall", "box", position=(5.1, 2.25, 0.0), scale=(0.2, 4.5, 10.4), color=SAGE)

    # The centrepiece: the knot standing on a round plinth.
    scene.add_mesh("plinth", "cylinder", smooth=True, position=(0.0, 0.4, -1.6), scale=(1.4, 0.8, 1.4), color=BONE)
    scene.add_mesh(
        "knot", "knot", smooth=True, position=(0.0, 1.72, -1.6), euler_deg=(90.0, 35.0, 0.0), scale=2.0, color=GOLD
    )

    # Blocks of different sizes and turns around it: a stack on the right, a column and a ball on the left.
    scene.add_mesh(
        "crate", "box", position=(2.9, 0.7, -2.8), euler_deg=(0.0, 28.0, 0.0), scale=1.4, texture=str(PLANKS_PATH),
        color=(1.0, 1.0, 1.0),
    )  # fmt: skip
    scene.add_mesh("cube", "box", position=(2.8, 1.75, -2.7), euler_deg=(0.0, -14.0, 0.0), scale=0.7, color=MUSTARD)
    scene.add_mesh(
        "pillar", "box", position=(-3.2, 1.6, -3.6), euler_deg=(0.0, 38.0, 0.0), scale=(0.9, 3.2, 0.9), color=INDIGO
    )
    scene.add_mesh("ball", "sphere", smooth=True, position=(-2.4, 0.55, 0.2), scale=1.1, color=TERRACOTTA)
    scene.add_mesh("tilted", "box", position=(-1.9, 0.33, -2.4), euler_deg=(0.0, 25.0, 38.0), scale=0.55, color=TEAL)
    scene.add_mesh(
        "slab", "box", position=(2.2, 0.2, 0.6), euler_deg=(0.0, -20.0, 0.0), scale=(1.6, 0.4, 1.0),
        texture=str(TILES_PATH), color=(1.0, 1.0, 1.0),
    )  # fmt: skip
    scene.add_mesh(
        "pyramid", "pyramid", position=(0.9, 0.35, 1.6), euler_deg=(0.0, 15.0, 0.0), scale=0.7, color=MUSTARD
    )

    scene.set_camera((2.3, 2.2, 5.4), look_at=(0.0, 1.15, -1.6), fov_deg=55.0)
    return scene
