"""The demos' building blocks and assets: textured blocks, the generated textures, the showpieces' lights."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from backends.base import create_backend
from components import Light, Mesh, Transform
from demos import build_demo, demo_names
from demos.assets import make_textures
from demos.kit import ASSETS, BLOCK, SEAM, block, texture, use_blocks
from engine.input import NoInput
from engine.maths import rotate
from engine.scene import Scene
from systems.app import App


def _meshes(scene: Scene) -> dict[str, tuple[Mesh, Transform]]:
    return {scene.name_of(e): (mesh, scene.get(e, Transform)) for e, mesh in scene.query(Mesh)}


def test_a_textured_block_is_tiled_so_each_repeat_keeps_one_world_size():
    scene = Scene("kit")
    use_blocks(scene)
    block(scene, "wall", (0.0, 0.0, 0.0), (9.0, 4.0, 0.3), (1.0, 1.0, 1.0), image=texture("plaster"))
    block(scene, "plain", (0.0, 0.0, 5.0), (9.0, 4.0, 5.3), (1.0, 1.0, 1.0))
    meshes = _meshes(scene)
    pieces = {name: mt for name, mt in meshes.items() if name.startswith("wall")}
    assert len(pieces) == 3 * 1 * 1  # 9 / 3 along x, 4 / 3 rounds to 1 along y, the thickness is one piece
    lo = np.min([np.subtract(t.position, 0.5 * np.asarray(t.scale)) for _, t in pieces.values()], axis=0)
    hi = np.max([np.add(t.position, 0.5 * np.asarray(t.scale)) for _, t in pieces.values()], axis=0)
    np.testing.assert_allclose(lo, (0.0, 0.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(hi, (9.0, 4.0, 0.3), atol=1e-12)
    for mesh, t in pieces.values():
        assert mesh.asset == "box" and mesh.texture == texture("plaster")
        np.testing.assert_allclose(t.scale[1:], (4.0, 0.3))
        assert 3.0 < t.scale[0] <= 3.0 + 2 * SEAM + 1e-12  # neighbours overlap at their shared faces, no gap
    seam = np.array([3.0, 2.0, 0.15])  # on the face the first two pieces share: inside both
    covering = [n for n, (_, t) in pieces.items() if np.all(np.abs(seam - t.position) < 0.5 * np.asarray(t.scale))]
    assert len(covering) == 2
    plain, _ = meshes["plain"]
    assert plain.asset == BLOCK and plain.texture == ""


def test_the_checked_in_textures_are_what_the_generator_makes_and_wrap_seamlessly():
    for name, make in make_textures.TEXTURES.items():
        image = make()
        assert np.array_equal(np.asarray(Image.open(ASSETS / name).convert("RGB")), image), name
        assert 64 <= image.shape[0] <= 256 and image.shape[0] == image.shape[1]
        np.testing.assert_array_equal(make(), image)  # deterministic


@pytest.mark.parametrize("demo", demo_names())
def test_each_demo_has_at_most_one_shadowing_light(demo):
    scene = build_demo(demo)
    try:
        assert sum(light.shadows for _, light in scene.query(Light)) <= 1
    finally:
        scene.close()


def test_the_sunset_shines_through_both_portals_onto_the_atrium_floor():
    """portal_in_aberration's showpiece: the atrium is roofed, yet its floor behind the frame is sunlit, the
    shadow ray passing the atrium's frame, the squeezed hall and the garden gate; beside the stripe it is not."""
    scene = build_demo("portal_in_aberration")
    backend = create_backend("reference")
    try:
        with App(scene, backend, size=(8, 6), aovs=("color",), input_source=NoInput()) as app:
            app.tick(0.0)
            ((sun, light),) = scene.query(Light)
            towards = rotate(scene.get(sun, Transform).rotation, (0.0, 0.0, 1.0))  # a sun shines along its -Z
            points = np.array([[0.0, 0.0, 0.5], [0.0, 0.0, 2.0], [3.5, 0.0, 2.0]])
            lit = backend.lit(points, np.array([0.0, 1.0, 0.0]), towards)
    finally:
        scene.close()
    assert light.shadows
    assert lit.tolist() == [True, True, False]
