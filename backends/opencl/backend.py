"""The OpenCL backend (pyopencl): the shared tracer core as an OpenCL C kernel.

It runs on PoCL (CPU) here and on any OpenCL GPU elsewhere. The packed tables
go unchanged into one ``__global`` buffer each (kernel arguments in the order
of :data:`engine.layout.TABLES`). The kernel source is concatenated from
defines + ``prelude_cl.h`` + the shared ``layout.h`` + ``bindings_cl.h`` + the
shared tracer files (``shared.TRACER_FILES``) + ``trace.cl`` (concatenated rather than ``#include``d: the
source is then the whole cache key, and no include path has to survive a
zipped install). Each variant (scene features, precision, traversal stack) is
built once per context, its ``pyopencl.Kernel`` created once and kept:
``program.trace`` would make a new kernel object, and reset its arguments, on
every access.

``precision="f64"`` traces in double (``REAL_IS_DOUBLE``, real tables packed
as float64) where the device has ``cl_khr_fp64``.
"""

from __future__ import annotations

import hashlib
import time
from collections.abc import Sequence
from functools import partial
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from backends import shared
from backends.base import AOV_DTYPES, AOVS, Backend, Frame
from backends.opencl import cache
from backends.opencl.build import BUILD_OPTIONS, build_program
from backends.opencl.cache import configure_caches
from backends.opencl.devices import (
    FP64_EXTENSION,
    INSTALL_PYOPENCL,
    device_has_fp64,
    device_kind,
    import_cl,
    pocl_version,
    select_device,
)
from backends.opencl.frame_plan import frame_launches
from backends.opencl.packets import packet_frame, work_size
from engine import layout
from engine.camera_view import CameraView, pack_camera
from engine.errors import AberrantError, BackendUnavailable
from engine.packed import Features, PackedScene, TableUpdate
from engine.records import Precision

if TYPE_CHECKING:  # pyopencl is imported lazily: importing this module must not need it
    import pyopencl as cl

#: Kernel source files, in assembly order (package, name).
_SOURCES: tuple[tuple[str, str], ...] = (
    ("backends.shared", "prelude_cl.h"),
    ("backends.shared", "layout.h"),
    ("backends.shared", "bindings_cl.h"),
    *(("backends.shared", name) for name in shared.TRACER_FILES),
    ("backends.opencl", "packet.cl"),
    ("backends.opencl", "trace.cl"),
)
#: Kernel arguments, in order (``trace.cl`` declares the same): the tables, the camera, the view tiles, the tile
#: order (tile_order.py), one buffer per AOV.
KERNEL_ARGS: tuple[str, ...] = (*layout.TABLES, "camera", "view_tiles", "tile_order", *(f"{name}_out" for name in AOVS))
#: The BVH width each precision traverses fastest (see ``OpenClBackend.bvh_width``). The default
#: ``BvhParams`` build the 8-wide trees too: CPU time per 800x800 frame (mesh-10k / mesh-200k /
#: ten-boxes, PoCL 3.1) was within 1 % for traversal cost 0.3, 0.5 or 2.0, and worse for leaves of
#: 8 triangles (+8 % / +5 %) or 2 (+1 % / +5 %).
BVH_WIDTH_BY_PRECISION: dict[Precision, int] = {"f32": 8, "f64": 4}
#: The instance tree's width (OpenClBackend.tlas_width) by precision.
TLAS_WIDTH_BY_PRECISION: dict[Precision, int] = {"f32": 8, "f64": 4}
#: Work-group size on a CPU device (PoCL). Measured on PoCL 3.0, 800x800 frames of three scenes:
#: None, 8x8, 16x16, 32x8, 32x32 and 64x4 are all within 3 % of each other (the traversal loops keep
#: PoCL from vectorising across work-items, so a group is a plain loop over pixels); 16x16 is
#: never worse than the driver's choice and keeps a group's rays coherent.
CPU_LOCAL_SIZE: tuple[int, int] = (16, 16)
#: Work-group size on a GPU: 64 work-items in an 8x8 tile (coherent rays, any warp size).
GPU_LOCAL_SIZE: tuple[int, int] = (8, 8)


class OpenClBackend(shared.UploadedScene, Backend):
    """Traces with the shared core in an OpenCL C kernel (pyopencl)."""

    name: ClassVar[str] = "opencl"
    #: Loops over up to 4 portals and 1 box: interleaved A/B, 320x320, 30 boxes in view, CPU time: with 8
    #: portals the tree costs 1.01x the loop in view and 0.90x hidden behind a wall (0.83x / 0.80x with 16);
    #: the box tree 0.88x with 2 boxes in view, 0.48x with 16.
    tree_min: ClassVar[tuple[int, int]] = (4, 1)
    space_wide: ClassVar[bool] = True
    #: Camera rays' first mesh search from the view tiles' lists (CPU per frame, 800x800, interleaved): the
    #: hotel doors shut 0.70x, its open views 0.74-0.87x, ten-boxes and ground 0.88x, starter and the village
    #: 0.95x; the house 1.02x, the planks and one-mesh scenes 1.00x.
    instance_tiles: bool = True
    precisions: ClassVar[tuple[Precision, ...]] = ("f32", "f64")
    camera_relative: bool = True
    #: Measured through ``aberrant render`` at 4096x4096 on PoCL (peak resident memory): 8 bytes a pixel
    #: for the colour image, 34 for all AOVs (device buffers, read-back, the written files).
    aov_copies: ClassVar[float] = 2.5
    #: 8-wide nodes tested with float8 operations: PoCL runs each work-item as scalar code, so the
    #: vector width is what a CPU core's SIMD gets (one AVX2 register per bound component). Against
    #: 4-wide (PoCL 3.1, 800x800, CPU time per frame, interleaved): -3 % on the 10k torus, -4 % on the
    #: 200k one, even on ten boxes; binary -> 4-wide gave -17 %. Leaves stay blocks of 4 triangles.
    #: At f64 a double8 is two AVX registers (and PoCL warns of its ABI on every build): 4-wide
    #: (double4, one register) takes 8 % less CPU per frame on both tori, 4 % on ten boxes.
    bvh_width: int = 8
    #: The instance tree 4-wide: against binary, CPU per frame (PoCL, 320x320, interleaved, f32 / f64)
    #: 0.89x / 0.84x on the village, 0.80x / 0.76x on the hotel shut, 0.89x / 0.89x on the starter, 0.82x /
    #: 0.76x on the house. 8-wide at f32 (float8 lanes) against 4-wide: 0.94x on the village, 0.98x on the
    #: hotel shut, 0.86x on the starter, 0.93x on the house. At f64 (double8: two AVX registers) it is mixed,
    #: 0.99x / 1.05x / 0.88x / 0.92x, so f64 keeps 4-wide (TLAS_WIDTH_BY_PRECISION).
    tlas_width: int = 4

    def __init__(
        self,
        precision: Precision | None = None,
        *,
        device: str | None = None,
        local_size: tuple[int, int] | str | None = "auto",
    ) -> None:
        """``device``: ``"platform:device"`` as ``$PYOPENCL_CTX`` (which it overrides).

        ``local_size``: the work-group size, ``None`` to let the driver choose, or
        ``"auto"`` for the measured default of the device type.
        """
        super().__init__(precision)
        self.bvh_width = BVH_WIDTH_BY_PRECISION[self.precision]
        self.tlas_width = TLAS_WIDTH_BY_PRECISION[self.precision]
        self._cl = import_cl()
        self._cache_dir = configure_caches()
        self.device: cl.Device = select_device(device, prefer_fp64=self.precision == "f64")
        self.fp64 = device_has_fp64(self.device)
        if self.precision == "f64" and not self.fp64:
            raise BackendUnavailable(
                f"opencl backend cannot trace at f64 on {self.device.name.strip()}: the device lacks "
                f"{FP64_EXTENSION} (double precision); use precision f32 or another device (PYOPENCL_CTX)"
            )
        if local_size == "auto":
            local_size = GPU_LOCAL_SIZE if self.device.type & self._cl.device_type.GPU else CPU_LOCAL_SIZE
        self.local_size: tuple[int, int] | None = (
            None if local_size is None else (int(local_size[0]), int(local_size[1]))
        )
        self._ctx: cl.Context | None = cache.shared_context(self.device)
        self._queue = self._cl.CommandQueue(self._ctx)
        self._tables: dict[str, cl.Buffer] = {}
        self._forget_upload()
        mf = self._cl.mem_flags
        self._camera = self._cl.Buffer(self._ctx, mf.READ_ONLY, layout.camera_dtype(self.precision).itemsize)
        self._camera_row: np.ndarray | None = None  # kept alive while its non-blocking copy runs
        self._view_tiles = self._cl.Buffer(self._ctx, mf.READ_ONLY, layout.VIEW_TILE_DTYPE.itemsize)
        self._view_tile_rows: np.ndarray | None = None  # likewise
        self._tile_order = self._cl.Buffer(self._ctx, mf.READ_ONLY, 4)
        self._tile_order_rows: np.ndarray | None = None  # likewise
        self._outputs: dict[str, cl.Buffer] = {}
        self._size: tuple[int, int] = (0, 0)
        self._kernels: dict[tuple[tuple[str, int], ...], cl.Kernel] = {}
        #: Arguments last set on each kernel (by id of the kernel): re-set only what changed.
        self._bound: dict[int, list[object]] = {}
        #: The program (source hash, options) of each kernel (by id), to give it back on release.
        self._program_keys: dict[int, tuple[str, tuple[str, ...]]] = {}
        #: How many program variants this backend has built (tests check the cache).
        self.compile_count = 0
        #: Whether the last frame traced its camera rays eight at a time (packets.py; tests) ...
        self.last_frame_packets = False
        #: ... and the rows of its tile order's launches (tile_order.py), None for one launch over the image.
        self.last_frame_tiles: tuple[int, ...] | None = None
        #: Extra defines for every variant (benchmarks: ``{"BRUTE_FORCE": 1}``).
        self.extra_defines: dict[str, int] = {}
        #: Program build options (benchmarks may compare others; part of each kernel's cache key).
        self.build_options: tuple[str, ...] = BUILD_OPTIONS

    # --- availability ------------------------------------------------------------------

    @classmethod
    def probe(cls) -> str | None:
        """``None`` when pyopencl imports and an OpenCL device (``$PYOPENCL_CTX``'s, if set) exists."""
        try:
            import_cl()
        except ImportError as e:
            return f"pyopencl is not installed ({e}); {INSTALL_PYOPENCL}"
        try:
            select_device()
        except BackendUnavailable as e:
            return str(e)
        return None

    def info(self) -> dict[str, str]:
        """Platform, device, OpenCL version, compute units, fp64 (``aberrant backends``)."""
        device = self.device
        platform = device.platform
        facts = {
            "platform": f"{platform.name.strip()} ({platform.version.strip()})",
            "device": device.name.strip(),
            "type": device_kind(device),
            "opencl": f"{device.version.strip()}, {device.opencl_c_version.strip()}",
            "compute units": str(device.max_compute_units),
            "fp64": "yes" if self.fp64 else "no",
            "precision": self.precision,
            "work group": "driver's choice" if self.local_size is None else "x".join(map(str, self.local_size)),
        }
        version = pocl_version(platform)
        if version is not None:
            facts["pocl"] = version
        return facts

    def _context(self) -> cl.Context:
        if self._ctx is None:
            raise AberrantError("opencl backend: used after release()")
        return self._ctx

    @property
    def context(self) -> cl.Context:
        """The OpenCL context (tests and tools build their own programs in it)."""
        return self._context()

    @property
    def queue(self) -> cl.CommandQueue:
        """The in-order command queue every upload and frame goes through."""
        self._context()
        return self._queue

    def read_table(self, name: str) -> bytes:
        """The bytes a table's device buffer holds (for tests: what an upload really wrote)."""
        buffer = self._tables[name]
        host = np.empty(buffer.size, np.uint8)
        self._cl.enqueue_copy(self.queue, host, buffer)
        return host.tobytes()

    # --- upload -------------------------------------------------------------------------

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        """Write changed rows into the table buffers (reallocating only on a size change); returns bytes."""
        if packed.precision != self.precision:
            raise AberrantError(
                f"opencl backend traces at {self.precision} but the scene was packed at {packed.precision}"
            )
        cl = self._cl
        ctx = self._context()
        written = 0
        rewritten: set[str] = set()
        todo = list(updates)
        listed = {u.table for u in todo}
        todo += [TableUpdate(name) for name in layout.TABLES if name not in self._tables and name not in listed]
        for update in todo:
            table = np.ascontiguousarray(packed.tables[update.table])
            buffer = self._tables.get(update.table)
            whole = update.rows is None or buffer is None or buffer.size != table.nbytes
            if whole:
                if buffer is not None and buffer.size == table.nbytes:
                    cl.enqueue_copy(self._queue, buffer, table)
                else:
                    if buffer is not None:
                        buffer.release()
                    flags = cl.mem_flags.READ_ONLY | cl.mem_flags.COPY_HOST_PTR
                    self._tables[update.table] = cl.Buffer(ctx, flags, hostbuf=table)
                written += table.nbytes
                rewritten.add(update.table)
            else:
                assert buffer is not None and update.rows is not None
                rows = table[update.rows.start : update.rows.stop]
                cl.enqueue_copy(self._queue, buffer, rows, dst_offset=update.rows.start * table.dtype.itemsize)
                written += rows.nbytes
        self._note_upload(packed, rewritten, {u.table for u in todo})
        return written

    # --- programs -----------------------------------------------------------------------

    def _defines(self, features: Features | None = None) -> dict[str, int]:
        features = features or self._features
        defines: dict[str, int] = dict(features.defines())
        defines.update(
            REAL_IS_DOUBLE=int(self.precision == "f64"),
            # Double helpers of the float tracer, only with fp64. Exact signs for edge functions that are
            # exactly 0 in float are not needed for watertightness (a float edge function has the exact sign
            # or is 0, and 0 counts on both sides of a shared edge) and cost a CPU device 20-25 % of a frame
            # (PoCL 3.1, 800x800 ten boxes / 10k / 200k triangles): GPUs only, as the GLSL backend does.
            EDGE_FALLBACK_FP64=int(self.fp64 and not self.device.type & self._cl.device_type.CPU),
            WORLD_FP64=int(self.fp64),
            # The checker's code stays in without a checker: PoCL branches around it, and compiled out its
            # frame was slower (mesh-10k / mesh-200k 1.07-1.08x, 400x400), where llvmpipe's was 0.90x.
            HAS_CHECKER=1,
            **self._bvh,
            TLAS_STACK_SIZE=self._tlas_stack,
            TLAS_WIDTH=self._tlas_width,
            **self._instance_search_defines(),
            **self._space,
        )
        defines.update(self.extra_defines)
        return defines

    @staticmethod
    def source(defines: dict[str, int]) -> str:
        """The full OpenCL C source of one variant."""
        return shared.assemble("// aberrant opencl tracer\n", defines, _SOURCES)

    def _kernel(self, defines: dict[str, int]) -> cl.Kernel:
        """The kernel of a variant, built on first use and kept."""
        key = (*sorted(defines.items()), *((option, 1) for option in self.build_options))
        kernel = self._kernels.get(key)
        if kernel is None:
            kernel = self._build(self.source(defines))
            self._kernels[key] = kernel
            self.compile_count += 1
        return kernel

    def _build(self, source: str) -> cl.Kernel:
        """This backend's kernel object of a program built once per context (see :mod:`backends.opencl.cache`)."""
        context = self._context()
        key = (hashlib.sha256(source.encode()).hexdigest(), tuple(self.build_options))
        program = cache.kept_program(
            context, key, lambda: build_program(context, source, self.build_options, self._cache_dir)
        )
        kernel = cache.take_kernel(context, key, lambda: self._cl.Kernel(program, "trace"))
        self._program_keys[id(kernel)] = key
        return kernel

    def _bind(self, kernel: cl.Kernel, args: list[cl.Buffer | None]) -> None:
        """Set the kernel arguments that differ from what it holds (each set costs a driver call)."""
        bound = self._bound.setdefault(id(kernel), [object()] * len(args))
        for index, (old, new) in enumerate(zip(bound, args, strict=True)):
            if old is not new:
                kernel.set_arg(index, new)
                bound[index] = new

    # --- render -------------------------------------------------------------------------

    def _ensure_outputs(self, width: int, height: int, aovs: Sequence[str]) -> None:
        """(Re)allocate the requested AOV buffers only when the image size changes."""
        if self._size != (width, height):
            for buffer in self._outputs.values():
                buffer.release()
            self._outputs.clear()
            self._size = (width, height)
        for name in aovs:
            if name not in self._outputs:
                dtype, tail = AOV_DTYPES[name]
                nbytes = width * height * dtype.itemsize * int(np.prod(tail, dtype=np.int64))
                self._outputs[name] = self._cl.Buffer(self._context(), self._cl.mem_flags.WRITE_ONLY, nbytes)

    def _global_size(self, items: tuple[int, int]) -> tuple[int, int]:
        """The launch size of ``items`` work-items: rounded up to whole work-groups where their size is set."""
        if self.local_size is None:
            return items
        lx, ly = self.local_size
        return (-(-items[0] // lx) * lx, -(-items[1] // ly) * ly)

    def _frame_defines(
        self, features: Features, tiles: shared.FrameTiles | None, aovs: Sequence[str]
    ) -> dict[str, int]:
        """A frame's kernel defines, after its camera row is packed: the scene's, the camera row's proofs, the view
        tiles' and packets where the frame qualifies (packets.py)."""
        assert self._camera_row is not None
        defines = self._defines(features)
        defines["SHADE"] = int("color" in aovs)  # a frame without colour skips the shading (and its shadow rays)
        defines.update(self._frame_space_defines(features, self._camera_row, self.precision))
        defines.update(self.extra_defines)
        defines.update(shared.view_tile_defines(tiles))
        defines["PACKET_PRIMARY"] = int(packet_frame(defines, self.extra_defines.get("PACKET_PRIMARY", 1)))
        defines["TILE_ORDER"] = 0
        return defines

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        """Launch one frame; reads back only the requested AOVs."""
        width, height = self.check_request(width, height, aovs, uploaded=self._uploaded)
        queue = self._queue
        start = time.perf_counter()
        self._camera_row = pack_camera(
            camera, self._origin, self.precision, width, height, self._boxes, self._bounds, self._box_tree
        )
        features = self._frame_features(camera, width, height, shade="color" in aovs)
        tiles = self._frame_view_tiles(camera, width, height, features, self._camera_row)
        defines_of = partial(self._frame_defines, aovs=aovs)
        launches, order = frame_launches(self, defines_of, self.local_size, camera, features, tiles, width, height)
        kernels = [self._kernel(defines) for defines, _ in launches]
        self.last_frame_packets = any(defines["PACKET_PRIMARY"] for defines, _ in launches)
        self.last_frame_tiles = None if order is None else tuple(launch.rows for _, launch in launches if launch)
        self._ensure_outputs(width, height, aovs)
        self._cl.enqueue_copy(queue, self._camera, self._camera_row, is_blocking=False)
        if tiles is not None:
            self._view_tiles, self._view_tile_rows = self._staged(self._view_tiles, tiles.table)
        if order is not None:
            self._tile_order, self._tile_order_rows = self._staged(self._tile_order, order)
        args: list[cl.Buffer | None] = [self._tables[name] for name in layout.TABLES]
        args += [self._camera, self._view_tiles, self._tile_order]
        args += [self._outputs[name] if name in aovs else None for name in AOVS]
        for kernel, (defines, launch) in zip(kernels, launches, strict=True):
            self._bind(kernel, args)
            if launch is None:
                items = work_size(width, height, bool(defines["PACKET_PRIMARY"]))
                self._cl.enqueue_nd_range_kernel(queue, kernel, self._global_size(items), self.local_size)
            elif launch.rows:
                self._cl.enqueue_nd_range_kernel(
                    queue, kernel, launch.global_size, launch.local_size, global_work_offset=launch.global_offset
                )
        queue.finish()
        traced = time.perf_counter()
        for kernel in kernels:
            cache.record_once((self._program_keys[id(kernel)], self.local_size))
        frame = Frame(width, height)
        for name in aovs:
            dtype, tail = AOV_DTYPES[name]
            host = np.empty((height, width, *tail), dtype)
            self._cl.enqueue_copy(queue, host, self._outputs[name], is_blocking=False)
            setattr(frame, name, host)
        queue.finish()
        end = time.perf_counter()
        frame.timings_ms["dispatch"] = (traced - start) * 1e3
        frame.timings_ms["readback"] = (end - traced) * 1e3
        frame.timings_ms["render"] = (end - start) * 1e3
        return frame

    def _staged(self, buffer: cl.Buffer, rows: np.ndarray) -> tuple[cl.Buffer, np.ndarray]:
        """``rows`` copied into ``buffer`` without waiting (regrown to twice their size where they do not fit);
        the buffer and the rows, which must stay alive until the frame's queue finishes."""
        if buffer.size < rows.nbytes:
            buffer.release()
            buffer = self._cl.Buffer(self._context(), self._cl.mem_flags.READ_ONLY, 2 * rows.nbytes)
        self._cl.enqueue_copy(self._queue, buffer, rows, is_blocking=False)
        return buffer, rows

    # --- teardown -----------------------------------------------------------------------

    def release(self) -> None:
        """Free buffers, kernels and the queue; idempotent. The device's context and the programs built in
        it stay for the next backend (:func:`backends.opencl.cache.shared_context`)."""
        if self._ctx is None:
            return
        self._queue.finish()
        for buffer in [
            *self._tables.values(),
            *self._outputs.values(),
            self._camera,
            self._view_tiles,
            self._tile_order,
        ]:
            buffer.release()
        self._tables.clear()
        self._outputs.clear()
        cache.give_back_kernels(self._ctx, [(self._program_keys[id(k)], k) for k in self._kernels.values()])
        self._kernels.clear()
        self._program_keys.clear()
        self._bound.clear()
        self._camera_row = None
        self._view_tile_rows = None
        self._tile_order_rows = None
        self._ctx = None
        self._uploaded = False
