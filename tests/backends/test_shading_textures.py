"""Textures and smooth normals: colour at known pixels and parity on every backend, the shading normal."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import require_backend
from PIL import Image
from scenes import EVERY, FAST, aim, aimed_pixel
from test_parity import compare, render

from backends.reference.backend import ReferenceBackend
from backends.reference.shading import shading_normals, world_normals
from backends.reference.traverse import nearest_mesh_hits
from engine.scene import Scene
from engine.settings import Settings

N = 33  # an aimed image: pixel (16, 16) looks straight down -z
#: A 2x2 texture: top row red, green; bottom row blue, white.
TEXELS = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [255, 255, 255]]], np.uint8)


def textured_quad(folder) -> Scene:
    """The [-1, 1]^2 quad facing the camera, textured, lit head-on with no ambient term to hide errors."""
    path = folder / "tex.png"
    Image.fromarray(TEXELS).save(path)
    scene = Scene()
    scene.settings = Settings(light_dir=(0.0, 0.0, 1.0), ambient=0.25)
    scene.add_mesh("quad", "quad", texture=str(path), color=(1.0, 1.0, 1.0))
    aim(scene, (0.0, 0.0, 2.0), N)
    return scene


def smooth_balls() -> Scene:
    scene = Scene()
    scene.add_mesh("ball", "sphere", smooth=True, position=(-0.6, 0.0, 0.0), color=(0.9, 0.5, 0.3))
    scene.add_mesh("flat", "sphere", position=(0.6, 0.0, 0.0), euler_deg=(10.0, 30.0, 0.0), scale=(1.0, 0.7, 1.2))
    scene.add_mesh("can", "cylinder", smooth=True, position=(0.0, 0.8, -0.5), scale=0.6, checker=0.1)
    scene.set_camera((0.0, 0.3, 2.4), look_at=(0.0, 0.2, 0.0))
    return scene


def expected_color(u: float, v: float) -> np.ndarray:
    """The bilinear, repeat-wrapped texel colour at (u, v), written out independently of the tracers."""
    texels = TEXELS.astype(np.float64) / 255.0
    s, t = (u % 1.0) * 2 - 0.5, (1.0 - v % 1.0) * 2 - 0.5
    x0, y0 = int(np.floor(s)), int(np.floor(t))
    ax, ay = s - x0, t - y0
    at = lambda x, y: texels[y % 2, x % 2]  # noqa: E731
    top = (1 - ax) * at(x0, y0) + ax * at(x0 + 1, y0)
    bottom = (1 - ax) * at(x0, y1 := y0 + 1) + ax * at(x0 + 1, y1)
    return (1 - ay) * top + ay * bottom


@pytest.mark.parametrize(("backend_name", "precision"), EVERY)
def test_a_textured_quad_has_its_texels_colours_at_known_pixels(backend_factory, tmp_path, backend_name, precision):
    frame = render(backend_factory(backend_name, precision), textured_quad(tmp_path), (N, N))
    # Pixel slopes (x, y) meet the quad at (2x, 2y): uv = (x + 1/2, y + 1/2); lit head-on, so the colour is the
    # texture's (ambient + (1 - ambient) * 1 = 1).
    for sx, sy in [(0.0, 0.0), (-0.25, 0.25), (0.25, -0.375), (0.4375, 0.4375), (-0.4375, -0.0625)]:
        row, col = aimed_pixel(N, sx, sy)
        want = np.floor(np.clip(expected_color(sx + 0.5, sy + 0.5), 0, 1) * 255 + 0.5)
        got = frame.color[row, col, :3].astype(float)
        assert np.abs(got - want).max() <= 1, f"pixel {(row, col)}: {got} != {want}"


@pytest.mark.parametrize(("backend_name", "precision"), FAST)
def test_textured_and_smooth_frames_match_the_reference(backend_factory, tmp_path, backend_name, precision):
    fast = backend_factory(backend_name, precision)
    ref = ReferenceBackend()
    try:
        for scene in (textured_quad(tmp_path), smooth_balls()):
            result = compare(render(fast, scene, (48, 36)), render(ref, scene, (48, 36)))
            assert result.mismatch < 2e-3 and result.color_off < 2e-3, result
    finally:
        ref.release()


def test_a_spheres_shading_normal_is_its_position_direction():
    """The primitive sphere carries its exact normals, so interpolated ones point from the centre to the hit."""
    scene = Scene()
    centre = np.array([0.3, -0.2, -4.0])
    scene.add_mesh("ball", "sphere", smooth=True, position=tuple(centre), scale=2.0, euler_deg=(20.0, 40.0, 0.0))
    scene.set_camera((0.0, 0.0, 0.0), look_at=tuple(centre))
    backend = ReferenceBackend()
    render(backend, scene, (4, 4))
    geo = backend.geometry
    rng = np.random.default_rng(3)
    directions = centre + rng.uniform(-0.9, 0.9, (500, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    origin = np.zeros((500, 3))  # the camera, at the packed origin
    hits = nearest_mesh_hits(geo, origin, directions, np.full(500, 1e-9))
    hit = hits.triangle >= 0
    assert hit.mean() > 0.5
    n = world_normals(geo, hits.instance, hits.triangle)
    flipped = np.sum(n * directions, axis=1) > 0
    n = np.where(flipped[:, None], -n, n)
    shading = shading_normals(geo, hits, n, flipped)[hit]
    position = hits.t[hit, None] * directions[hit]
    radial = (position - centre) / np.linalg.norm(position - centre, axis=1, keepdims=True)
    assert np.abs(shading - radial).max() < 1e-5
    assert np.abs(n[hit] - radial).max() > 1e-3  # the facets' own normals are not radial
    backend.release()


def test_glsl_storage_buffers_with_every_aov_keep_the_shading_tables_in_images(tmp_path):
    """Storage buffers for the tables: normals and texels go in images (a compute shader has 16 storage blocks,
    which the other tables, the camera and the four AOV outputs already fill)."""
    require_backend("glsl")
    from backends.glsl.backend import GlslBackend

    scene = textured_quad(tmp_path)
    scene.add_mesh("ball", "sphere", smooth=True, position=(0.5, 0.0, 0.5), scale=0.3)
    backend, ref = GlslBackend(tables="ssbo"), ReferenceBackend()
    try:
        result = compare(render(backend, scene, (N, N)), render(ref, scene, (N, N)))
        assert result.mismatch < 2e-3 and result.color_off < 2e-3, result
    finally:
        backend.release()
        ref.release()
