"""The GLSL compute-shader backend (moderngl): the shared tracer core in an OpenGL 4.3 compute shader.

Headless it runs on an EGL standalone context (Mesa llvmpipe here, any GPU
elsewhere); the editor can hand it its own context so the colour texture is
drawable without a read-back. The packed tables go unchanged into one std430
storage buffer each (binding = position in :data:`engine.layout.TABLES`), or,
on Mesa's llvmpipe, into one RGBA32UI image each (the same bytes, a texel per
4-vector): llvmpipe reads storage buffers one SIMD lane at a time and images
with vector gathers, about 13 times faster (``tables="auto"`` picks). The
shader is assembled from ``#version 430`` + defines + ``prelude.glsl`` + the
shared ``layout.h`` + ``bindings.glsl`` + the shared tracer files (``shared.TRACER_FILES``) +
``main.comp``; every variant (scene features, requested AOVs, precision,
table store) is compiled once per context and cached.
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager, nullcontext
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from backends import shared
from backends.base import AOVS, Backend, Frame
from backends.glsl.context import create_context, is_software, probe_context
from backends.glsl.outputs import OUTPUT_BINDINGS, FrameOutputs
from backends.glsl.split import QUEUE_BINDING, SplitDispatch
from backends.glsl.tables import (
    CAMERA_BINDING,
    CAMERA_IMAGE,
    TABLE_WIDTH,
    VIEW_TILES_IMAGE,
    DeviceTables,
    TableStore,
)
from engine import layout
from engine.camera_view import CameraView, pack_camera
from engine.errors import AberrantError, BackendUnavailable
from engine.packed import Features, PackedScene, TableUpdate
from engine.records import Precision

if TYPE_CHECKING:  # moderngl is imported lazily: importing this module must not need it
    import moderngl

#: Pixels per run of 8 consecutive invocations (one SIMD vector on llvmpipe): a 4x2 block instead of a row
#: of 8 diverges less in traversal. Interleaved A/B, 800x800 f32, CPU time per frame: mesh-10k 173 -> 169 ms,
#: mesh-200k 222 -> 216 ms, ten-boxes 106 -> 104 ms (2x4 and Morton order: smaller gains). Same frames.
LANE_BLOCK: tuple[int, int] = (4, 2)


def lane_block(workgroup: tuple[int, int], block: tuple[int, int] = LANE_BLOCK) -> tuple[int, int]:
    """The pixel block of consecutive invocations for a work-group shape: ``block`` where it tiles the group,
    else ``(workgroup[0], 1)``, rows (the plain ``gl_GlobalInvocationID`` mapping)."""
    if workgroup[0] % block[0] == 0 and workgroup[1] % block[1] == 0:
        return block
    return (workgroup[0], 1)


def shades(aovs: Sequence[str]) -> bool:
    """Whether a frame of ``aovs`` shades: the texture is its colour, wanted unless other AOVs come without it."""
    return not aovs or "color" in aovs


#: Shader source files, in assembly order (package, name).
_SOURCES: tuple[tuple[str, str], ...] = (
    ("backends.glsl", "prelude.glsl"),
    ("backends.shared", "layout.h"),
    ("backends.glsl", "bindings.glsl"),
    *(("backends.shared", name) for name in shared.TRACER_FILES),
    ("backends.glsl", "main.comp"),
)


#: BVH widths the shader traverses: 8-wide nodes are read as float8, which GLSL does not have.
GLSL_BVH_WIDTHS: tuple[int, ...] = (2, 4)


class GlslBackend(shared.UploadedScene, Backend):
    """Traces with the shared core in an OpenGL 4.3 compute shader (moderngl)."""

    name: ClassVar[str] = "glsl"
    #: Loops over up to 4 portals and 4 boxes: interleaved A/B, 320x320, CPU time: with 8 portals in view
    #: before 30 boxes the tree (and its view tiles) costs 0.80x the loop, the house demo's 8 doors 0.90x, 4
    #: portals in view 0.93-0.98x but 4 beside a box 1.06x (portal_in_aberration); with 8 boxes 1.05x (0.90x
    #: hidden behind a wall), with 16 0.85x (0.79x).
    tree_min: ClassVar[tuple[int, int]] = (4, 4)
    precisions: ClassVar[tuple[Precision, ...]] = ("f32", "f64")
    camera_relative: bool = True
    #: Compact records: a visit loads 2 texels instead of 4 (llvmpipe gathers texels at a bounded rate).
    bvh_compact: ClassVar[bool] = True

    #: Process-wide probe result: ``(reason,)`` once probed.
    _probe_cache: ClassVar[tuple[str | None] | None] = None

    def __init__(
        self,
        precision: Precision | None = None,
        *,
        context: moderngl.Context | None = None,
        workgroup: tuple[int, int] = (8, 8),
        tables: TableStore = "auto",
    ) -> None:
        """``context``: draw into an existing context (the editor's), else a headless EGL one is made;
        ``tables``: storage buffers or images for the packed tables (``auto``: images on llvmpipe)."""
        super().__init__(precision)
        if context is None:
            reason = self.probe()
            if reason is not None:
                raise BackendUnavailable(f"glsl backend cannot run here: {reason}")
        self._owns_context = context is None
        if context is None:
            try:
                context = create_context()
            except Exception as e:  # the probe passed, yet no context now: say so, do not crash the caller
                raise BackendUnavailable(f"glsl backend cannot create an OpenGL 4.3 context: {e}") from e
        self._ctx: moderngl.Context | None = context
        self.workgroup = (int(workgroup[0]), int(workgroup[1]))
        self.lane_block: tuple[int, int] = lane_block(self.workgroup)
        if tables not in ("auto", "ssbo", "image"):
            raise AberrantError(f"glsl backend: tables must be 'auto', 'ssbo' or 'image', got {tables!r}")
        renderer = str(self._ctx.info.get("GL_RENDERER", ""))
        #: A CPU rasteriser (llvmpipe): storage-buffer loads go one SIMD lane at a time, and the
        #: compiler flattens small branches, so rare-case code costs every lane.
        self.software = is_software(renderer)
        if tables == "auto":
            tables = "image" if self.software else "ssbo"
        #: Where the tables live on the device: ``"ssbo"`` or ``"image"``.
        self.table_store: str = tables
        with self._current():
            self._device = DeviceTables(self._ctx, tables, layout.camera_dtype(self.precision).itemsize)
        #: Each uploaded table's buffer or image (the device tables' own dict).
        self._tables = self._device.stores
        self._forget_upload()
        #: Whether frames may take view tiles: their image unit exists with the image store only.
        self.view_tiles = self.table_store == "image"
        #: ... and the instances' lists among them (README.md's table).
        self.instance_tiles = self.view_tiles
        self.portal_legs = self.view_tiles
        #: Whether a frame whose camera rays' first legs take their instances from the tiles' lists beside
        #: portals or boxes is traced in two dispatches (backends/glsl/split.py): llvmpipe runs the event
        #: loop's body for every SIMD lane even when none needs it.
        self.split_passes: bool = self.software and self.view_tiles
        self._split = SplitDispatch()
        self._outputs = FrameOutputs()
        self._programs: dict[tuple[tuple[str, int], ...], moderngl.ComputeShader] = {}
        #: How many shader variants this backend has compiled (tests check the cache).
        self.compile_count = 0
        #: Extra defines for every variant (benchmarks: ``{"BRUTE_FORCE": 1}``).
        self.extra_defines: dict[str, int] = {}

    # --- availability ---------------------------------------------------------------

    @classmethod
    def probe(cls) -> str | None:
        """``None`` when a headless OpenGL 4.3 context with compute shaders can be made (cached per process)."""
        if cls._probe_cache is None:
            cls._probe_cache = (probe_context(),)
        return cls._probe_cache[0]

    def info(self) -> dict[str, str]:
        """Renderer, version, vendor and compute limits (``aberrant backends``)."""
        ctx = self._context()
        with self._current():
            gl = ctx.info
            return {
                "renderer": str(gl.get("GL_RENDERER", "?")),
                "version": str(gl.get("GL_VERSION", "?")),
                "vendor": str(gl.get("GL_VENDOR", "?")),
                "max compute work-group size": "x".join(str(v) for v in gl.get("GL_MAX_COMPUTE_WORK_GROUP_SIZE", ())),
                "max compute work-group invocations": str(gl.get("GL_MAX_COMPUTE_WORK_GROUP_INVOCATIONS", "?")),
                "precision": self.precision,
                "work group": f"{self.workgroup[0]}x{self.workgroup[1]}",
                "tables": "RGBA32UI images" if self.table_store == "image" else "storage buffers",
            }

    # --- context ---------------------------------------------------------------------

    def _context(self) -> moderngl.Context:
        if self._ctx is None:
            raise AberrantError("glsl backend: used after release()")
        return self._ctx

    @contextmanager
    def _current(self) -> Iterator[None]:
        """Make our own context current for the block (several backends may live in one process)."""
        ctx = self._context()
        with ctx if self._owns_context else nullcontext():
            yield

    @property
    def context(self) -> moderngl.Context:
        """The OpenGL context the backend draws with."""
        return self._context()

    @property
    def color_texture(self) -> moderngl.Texture | None:
        """The last frame's colour as an RGBA8 texture, texel row 0 = the image's top row (None before a frame)."""
        return self._outputs.texture

    # --- upload ----------------------------------------------------------------------

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        """Write changed rows into the storage buffers (reallocating only on a size change); returns bytes."""
        if packed.precision != self.precision:
            raise AberrantError(
                f"glsl backend traces at {self.precision} but the scene was packed at {packed.precision}"
            )
        width = layout.bvh_width(packed.tables["bvh_nodes"])
        if width not in GLSL_BVH_WIDTHS:
            raise AberrantError(
                f"glsl backend traverses BVH widths {', '.join(map(str, GLSL_BVH_WIDTHS))}, not {width} "
                f"(8-wide nodes need 8-vectors, which GLSL lacks; OpenCL only); pack with "
                f"bvh_width={self.bvh_width} (ScenePacker)"
            )
        written = 0
        rewritten: set[str] = set()
        todo = list(updates)
        listed = {u.table for u in todo}
        todo += [TableUpdate(name) for name in layout.TABLES if name not in self._tables and name not in listed]
        with self._current():
            for update in todo:
                table = np.ascontiguousarray(packed.tables[update.table])
                whole = (
                    update.rows is None
                    or update.table not in self._tables
                    or self._device.nbytes[update.table] != table.nbytes
                )
                if whole:
                    self._device.write_whole(update.table, table)
                    written += table.nbytes
                    rewritten.add(update.table)
                else:
                    assert update.rows is not None
                    written += self._device.write_rows(update.table, table, update.rows)
        self._note_upload(packed, rewritten, {u.table for u in todo})
        return written

    def read_table(self, name: str) -> bytes:
        """The bytes of an uploaded table as the device holds them (tests, debugging)."""
        if name not in self._tables:
            raise AberrantError(f"glsl backend: table {name!r} has not been uploaded")
        with self._current():
            return self._device.read(name)

    # --- shaders ---------------------------------------------------------------------

    def _defines(self, aovs: Sequence[str], features: Features | None = None) -> dict[str, int]:
        features = features or self._features
        defines: dict[str, int] = dict(features.defines())
        # The rows the loops go through, compiled in where no tree finds them: llvmpipe unrolls the loops and
        # drops the settings load (ten-boxes-aberration -12 %, ten-boxes-portals -6 % of a frame's CPU time).
        if features.portals and not self._space["PORTAL_TREE"]:
            defines["PORTAL_COUNT"] = self._counts.get("portals", 0)
        if features.aberration_modes and not self._space["BOX_TREE"]:
            defines["BOX_COUNT"] = self._counts.get("aberrations", 0)
        defines.update(
            REAL_IS_DOUBLE=int(self.precision == "f64"),
            # Exact signs for edge functions that are exactly 0 in float (doubles are core in GLSL 4.00+).
            # Not needed for watertightness (a float edge function has the exact sign or is 0, and 0
            # counts on both sides of a shared edge); skipped on llvmpipe, where it costs about 5 %.
            EDGE_FALLBACK_FP64=int(not self.software),
            WORLD_FP64=1,
            **self._bvh,
            TLAS_STACK_SIZE=self._tlas_stack,
            TLAS_WIDTH=self._tlas_width,
            **self._instance_search_defines(),
            **self._space,
            WORKGROUP_X=self.workgroup[0],
            WORKGROUP_Y=self.workgroup[1],
            LANE_BLOCK_X=self.lane_block[0],
            LANE_BLOCK_Y=self.lane_block[1],
            CAMERA_BINDING=CAMERA_BINDING,
            QUEUE_BINDING=QUEUE_BINDING,
            TABLES_IN_IMAGES=int(self.table_store == "image"),
            TABLE_WIDTH=TABLE_WIDTH,
            TABLE_WIDTH_LOG2=TABLE_WIDTH.bit_length() - 1,
            CAMERA_IMAGE=CAMERA_IMAGE,
            VIEW_TILES_IMAGE=VIEW_TILES_IMAGE,
        )
        for name in layout.TABLES:
            defines[f"{name.upper()}_STRIDE"] = layout.table_dtype(name, self.precision).itemsize // 16
        defines["BVH_NODES_STRIDE"] = layout.BVH_WIDTHS[self._bvh["BVH_WIDTH"]].itemsize // 16
        defines["TLAS_NODES_STRIDE"] = layout.BVH_WIDTHS[self._tlas_width].itemsize // 16
        for name, binding in OUTPUT_BINDINGS.items():
            defines[f"{name.upper()}_BINDING"] = binding
            defines[f"WRITE_{name.upper()}"] = int(name in aovs)
        defines["SHADE"] = int(shades(aovs))
        defines.update(self.extra_defines)
        return defines

    @staticmethod
    def source(defines: dict[str, int]) -> str:
        """The full compute-shader source of one variant."""
        return shared.assemble("#version 430\n", defines, _SOURCES)

    def _program(self, defines: dict[str, int]) -> moderngl.ComputeShader:
        key = tuple(sorted(defines.items()))
        program = self._programs.get(key)
        if program is None:
            source = self.source(defines)
            try:
                program = self._context().compute_shader(source)
            except Exception as e:  # moderngl.Error carries the driver's compile log
                raise BackendUnavailable(f"glsl backend: the compute shader does not compile: {e}") from e
            self._programs[key] = program
            self.compile_count += 1
        return program

    # --- render ----------------------------------------------------------------------

    def split_frame(self, features: Features) -> bool:
        """Two dispatches for a frame with portals or boxes and no shadow rays (they would need the event loop
        in the first), unless a recent split frame queued most of its pixels (split.SPLIT_QUEUED_MAX)."""
        if not (self.split_passes and self.extra_defines.get("SPLIT_PASSES", 1)) or features.shadows:
            return False
        return bool(features.portals or features.aberration_modes) and self._split.allowed

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        """Dispatch one frame; reads back only the requested AOVs (``aovs=()``: the texture only)."""
        width, height = self.check_request(width, height, aovs, uploaded=self._uploaded)
        start = time.perf_counter()
        with self._current():
            ctx = self._context()
            row = pack_camera(
                camera, self._origin, self.precision, width, height, self._boxes, self._bounds, self._box_tree
            )
            self._split.observe(camera)
            features = self._frame_features(camera, width, height, shade=shades(aovs))
            defines = self._defines(aovs, features)
            tiles = self._frame_view_tiles(camera, width, height, features, row)
            defines.update(self._frame_space_defines(features, row, self.precision), **self.extra_defines)
            defines.update(shared.view_tile_defines(tiles))
            # Two where the first legs take the instances' lists apart from the event loop (FIRST_LEG_APART): without
            # the lists a first leg walks the tree in the first dispatch as in the loop's first pass, and two save
            # nothing (space-count in view: 0.99-1.03x the time); with the lists alone the loop is already lean.
            apart = tiles is not None and tiles.instances and not tiles.instances_only
            split = apart and self.extra_defines.get("FIRST_LEG_APART", 1) and self.split_frame(features)
            program = None if split else self._program(defines)
            if tiles is not None:
                self._device.bind_view_tiles(tiles.table)
            self._device.bind(row)
            self._outputs.bind(ctx, width, height, aovs)
            if program is None:
                passes = (self._program({**defines, "SPLIT_PASS": 1}), self._program({**defines, "SPLIT_PASS": 2}))
                self._split.run(ctx, passes, camera, (width, height), self.workgroup)
            else:
                gx, gy = self.workgroup
                program.run(math.ceil(width / gx), math.ceil(height / gy), 1)
            ctx.memory_barrier()
            dispatched = time.perf_counter()
            frame = self._outputs.read(width, height, aovs)
        end = time.perf_counter()
        frame.timings_ms["dispatch"] = (dispatched - start) * 1e3
        frame.timings_ms["readback"] = (end - dispatched) * 1e3
        frame.timings_ms["render"] = (end - start) * 1e3
        return frame

    # --- teardown ----------------------------------------------------------------------

    def release(self) -> None:
        """Free buffers, programs, the texture and (when it is ours) the context; idempotent."""
        if self._ctx is None:
            return
        with self._current():
            self._device.release()
            self._outputs.release()
            self._split.release()
            for program in self._programs.values():
                program.release()
        self._programs.clear()
        if self._owns_context:
            self._ctx.release()
        self._ctx = None
        self._uploaded = False
