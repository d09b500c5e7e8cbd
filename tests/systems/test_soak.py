"""Soak: 10,000 headless ticks of a demo through aberrations and portals.

The demo ``portal_in_aberration`` (an atrium, a hall filled by a metric
aberration, a garden, two portal pairs) is walked by its own camera path,
replayed through the real systems (``systems.app.App``: camera movement,
portal teleport) and looped: at the path's end the camera is put back at its
start and the path replayed at another rate, so the ticks land on other
points of the walk each time. Every RENDER_EVERY ticks the real upload and
render systems (``GpuUploadProcessor``, ``RenderProcessor``) draw a tiny frame
with the GLSL backend (and, on a shorter run, OpenCL), so their buffers,
textures and kernels are exercised the whole time.

Checked: the walk goes through both portals and the aberration on every loop;
after a warm-up of WARM_UP ticks resident memory (``/proc/self/statm``) grows
by less than 5 %; no GL error (``ctx.error``) and no OpenCL exception; every
frame is clean; and after every tick the camera is *in the level*:

* not inside a wall: outside the (oriented) bounding box of every mesh
  instance, shrunk by a millimetre -- the level is built of blocks, so that box
  is the solid itself for walls, floors and door frames, and a loose bound
  for round things;
* not outside the level: a floor lies below it at standing height (a ray
  straight down meets a mesh box within FLOOR_BELOW) and it is walled in
  (rays along +-x and +-z each meet a mesh box within WALLED_IN). Walking out
  through a wall, falling through a floor or being teleported into the void
  would break one of these.

Measured here (2 cores, llvmpipe, PoCL): 520 to 710 ticks/s with the checks
and a frame every 100 ticks, so the 10,000-tick GLSL run takes 14 to 19 s (11
loops, 23 crossings, 40 % of the ticks in the aberration); RSS grows by 0.8 %
after the warm-up (172.8 -> 174.2 MiB: about the scene's change journal, one
entry per tick, which the scene compacts at 65,536 entries); 2,000 OpenCL
ticks take about 3 s (+0.04 %). ``pytest -s`` prints the numbers.
"""

from __future__ import annotations

import gc
import os
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
import pytest
from conftest import require_backend
from test_parity import assert_clean

from backends.base import Backend, backend_class
from components import Mesh, Transform
from demos import build_demo
from demos.portal_in_aberration import camera_path
from engine.input import InputState
from engine.maths import trs_inverse
from engine.scene import Scene
from systems.app import App
from systems.camera_movement import active_box, speed_boxes
from systems.camera_path import CameraPath, PathInput
from systems.gpu_upload import GpuUploadProcessor
from systems.render import RenderProcessor
from systems.state import FrameSlot, UploadStats

DEMO = "portal_in_aberration"
TICKS = 10_000
WARM_UP = 1_000
DT = 1.0 / 60.0
RENDER_EVERY = 100
RENDER_SIZE = (32, 24)
#: Playback rates of successive loops of the path.
RATES = (1.0, 0.8, 1.25, 0.6, 1.1)
#: "Standing on a floor": its top at most this far below the camera (eye height is 1.7 to 2.1).
FLOOR_BELOW = 2.5
#: "Walled in": geometry within this distance along +-x and +-z.
WALLED_IN = 60.0
#: The solids are shrunk by this before testing whether the camera is inside one.
SKIN = 1e-3
MAX_RSS_GROWTH = 0.05


def rss_bytes() -> int:
    """Resident set size of this process (Linux: /proc/self/statm, in pages)."""
    with open("/proc/self/statm") as f:
        return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")


class LoopedPath:
    """Replays a camera path through the systems; at its end puts the camera back at the start and replays it."""

    def __init__(self, path: CameraPath, scene: Scene) -> None:
        self.path = path
        self.scene = scene
        self.loops = 0
        self.inputs = self._start()

    def _start(self) -> PathInput:
        self.path.place_camera(self.scene)
        return self.path.inputs(self.scene, rate=RATES[self.loops % len(RATES)])

    def poll(self, dt: float) -> InputState:
        if self.inputs.done:
            self.loops += 1
            self.inputs = self._start()
        return self.inputs.poll(dt)


@dataclass(frozen=True)
class Solids:
    """Every mesh instance as an oriented box: world -> local transforms and the asset's local bounds."""

    to_local: np.ndarray  # (M, 3, 4)
    lo: np.ndarray  # (M, 3)
    hi: np.ndarray  # (M, 3)

    @staticmethod
    def of(scene: Scene) -> Solids:
        to_local, lo, hi = [], [], []
        for _, (transform, mesh) in scene.query(Transform, Mesh):
            to_local.append(trs_inverse(transform.position, transform.rotation, transform.scale)[:3])
            low, high = scene.asset(mesh.asset).bounds()
            lo.append(low)
            hi.append(high)
        return Solids(np.array(to_local), np.array(lo, dtype=np.float64), np.array(hi, dtype=np.float64))

    def local(self, point: np.ndarray) -> np.ndarray:
        return np.einsum("mij,j->mi", self.to_local[:, :, :3], point) + self.to_local[:, :, 3]

    def inside(self, point: np.ndarray) -> np.ndarray:
        """Which solids contain ``point`` (more than SKIN inside, measured in local units scaled back)."""
        a = self.local(point)
        scale = np.linalg.norm(self.to_local[:, :, :3], axis=2)  # local units per world unit, per axis
        return np.all((a > self.lo + SKIN * scale) & (a < self.hi - SKIN * scale), axis=1)

    def distance(self, point: np.ndarray, direction: np.ndarray) -> float:
        """Distance along ``direction`` (unit) to the nearest solid's box, or inf."""
        a = self.local(point)
        v = np.einsum("mij,j->mi", self.to_local[:, :, :3], direction)
        with np.errstate(divide="ignore", invalid="ignore"):
            t1, t2 = (self.lo - a) / v, (self.hi - a) / v
        parallel = v == 0.0
        inside = (a >= self.lo) & (a <= self.hi)
        near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2)).max(axis=1)
        far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2)).min(axis=1)
        hits = (near <= far) & (far >= 0.0)
        return float(np.min(np.where(hits, np.maximum(near, 0.0), np.inf)))


AXES = [np.array(v, dtype=np.float64) for v in ((1, 0, 0), (-1, 0, 0), (0, 0, 1), (0, 0, -1))]
DOWN = np.array([0.0, -1.0, 0.0])


def where_wrong(solids: Solids, position: np.ndarray) -> str | None:
    """Why the camera is not in the level at ``position``, or None."""
    inside = np.flatnonzero(solids.inside(position))
    if inside.size:
        return f"inside solid #{inside[0]}"
    below = solids.distance(position, DOWN)
    if not below <= FLOOR_BELOW:
        return f"no floor within {FLOOR_BELOW} below (nearest {below:.3g})"
    for axis in AXES:
        if not solids.distance(position, axis) <= WALLED_IN:
            return f"not walled in along {axis}"
    return None


@dataclass
class SoakResult:
    ticks: int
    seconds: float
    frames: int
    loops: int
    crossings: int
    ticks_in_aberration: int
    rss_warm: int
    rss_end: int

    def __str__(self) -> str:
        growth = (self.rss_end - self.rss_warm) / self.rss_warm
        return (
            f"{self.ticks} ticks in {self.seconds:.1f} s ({self.ticks / self.seconds:.0f}/s), {self.frames} frames, "
            f"{self.loops} loops, {self.crossings} portal crossings, {self.ticks_in_aberration} ticks in the "
            f"aberration; RSS after warm-up {self.rss_warm / 2**20:.1f} MiB, at the end "
            f"{self.rss_end / 2**20:.1f} MiB ({growth:+.2%})"
        )


def soak(backend: Backend, ticks: int) -> SoakResult:
    """Run the looped walk for ``ticks`` ticks, rendering every RENDER_EVERY; checks the camera every tick."""
    scene = build_demo(DEMO)
    try:
        solids = Solids.of(scene)
        boxes = speed_boxes(scene)
        source = LoopedPath(camera_path(), scene)
        assert where_wrong(solids, np.array(scene.get(scene.camera_entity, Transform).position)) is None
        upload = GpuUploadProcessor(scene, backend, UploadStats())
        slot = FrameSlot()
        render = RenderProcessor(scene, backend, slot, RENDER_SIZE)
        crossings = in_box = frames = 0
        rss_warm = 0
        start = time.perf_counter()
        with App(scene, input_source=source) as app:
            for tick in range(ticks):
                app.tick(DT)
                assert scene.camera_entity is not None
                position = np.array(scene.get(scene.camera_entity, Transform).position)
                problem = where_wrong(solids, position)
                assert problem is None, f"tick {tick}, camera at {position}: {problem}"
                crossings += len(app.motion.crossings)
                in_box += active_box(boxes, position) is not None
                if tick % RENDER_EVERY == 0:
                    upload.process(DT)  # the real upload and render systems, called directly
                    render.process(DT)
                    assert slot.frame is not None
                    assert_clean(slot.frame)
                    assert (slot.frame.instance >= 0).mean() > 0.5, f"tick {tick}: the frame shows the level"
                    frames += 1
                if tick + 1 == min(WARM_UP, ticks // 2):
                    gc.collect()
                    rss_warm = rss_bytes()
        seconds = time.perf_counter() - start
        gc.collect()
        return SoakResult(ticks, seconds, frames, source.loops, crossings, in_box, rss_warm, rss_bytes())
    finally:
        scene.close()


def check(result: SoakResult, ticks: int) -> None:
    assert result.ticks == ticks and result.frames == ticks // RENDER_EVERY
    assert result.loops >= ticks // 1500, result  # the path lasts about 800 ticks at rate 1
    assert result.crossings >= 2 * result.loops, f"both portals on every loop: {result}"
    assert result.ticks_in_aberration > 0.1 * ticks, result
    assert result.rss_end < result.rss_warm * (1.0 + MAX_RSS_GROWTH), result


@pytest.fixture
def glsl() -> Iterator[Backend]:
    """A private GLSL backend, so the soak's buffers and textures are its own."""
    require_backend("glsl")
    backend = backend_class("glsl")(precision="f32")
    yield backend
    backend.release()


@pytest.fixture
def opencl() -> Iterator[Backend]:
    require_backend("opencl")
    backend = backend_class("opencl")(precision="f32")
    yield backend
    backend.release()


def test_soak_glsl_10000_ticks(glsl):
    result = soak(glsl, TICKS)
    check(result, TICKS)
    error = glsl._context().error  # moderngl: the first GL error since the last read
    assert error == "GL_NO_ERROR", f"{error} after {result}"
    print(result)


def test_soak_opencl_2000_ticks(opencl):
    ticks = 2_000
    result = soak(opencl, ticks)  # any pyopencl error is an exception and fails the test
    check(result, ticks)
    opencl.queue.finish()
    print(result)


def test_the_level_checks_catch_a_camera_in_a_wall_or_out_of_the_level():
    """The soak's checks are not vacuous: a camera in a wall, under the floor, between the places or up in
    the air is caught; the path's start is fine."""
    scene = build_demo(DEMO)
    try:
        solids = Solids.of(scene)
        assert scene.camera_entity is not None
        start = np.array(scene.get(scene.camera_entity, Transform).position)
    finally:
        scene.close()
    assert where_wrong(solids, start) is None
    for point in ((-5.15, 1.7, 0.0), (-1.2, 1.0, -1.0), (0.0, -0.1, 0.0)):  # a wall, a door post, the floor
        assert "inside solid" in str(where_wrong(solids, np.array(point))), point
    for point in ((0.0, -5.0, 0.0), (25.0, 1.7, 0.0), (0.0, 10.0, 0.0), (0.0, 1.7, 20.0)):  # below, between, above
        assert "no floor" in str(where_wrong(solids, np.array(point))), point
    assert "not walled in" in str(where_wrong(solids, np.array([0.0, 5.6, 0.0])))  # on the atrium's roof
