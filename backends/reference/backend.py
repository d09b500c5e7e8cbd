"""The float64 NumPy reference tracer: slow, simple, and the truth other backends are measured against."""

from __future__ import annotations

import time
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from backends.base import AOV_DTYPES, AOVS, Backend, Frame
from backends.reference.aberrations import Boxes, SigmaBounds
from backends.reference.portals import Portals
from backends.reference.shading import Lights, ShadingSettings, to_uint8
from backends.reference.trace import Space, TraceResult, shadow_rays_lit, trace
from backends.reference.traverse import Geometry
from engine.camera_view import CameraView
from engine.errors import AberrantError
from engine.layout import bvh_compact, bvh_width
from engine.packed import Features, PackedScene, TableUpdate
from engine.records import Precision

#: Tables converted to float64 on upload: mesh data (once per asset set) and per-entity rows.
_MESH_TABLES = ("triangles", "triangle_uvs", "bvh_nodes", "triangle_normals", "texels")
_INSTANCE_TABLES = ("instances", "materials")


class ReferenceBackend(Backend):
    """Traces every pixel in float64 with NumPy, vectorised over rays (docs/semantics.md)."""

    name: ClassVar[str] = "reference"
    precisions: ClassVar[tuple[Precision, ...]] = ("f64",)
    #: Camera-relative tables, like the fast backends' floating origin: the tracer's tolerances scale with
    #: ``|o|`` (``T_MIN_RELATIVE``, ``TIE_RELATIVE``), so in world coordinates a scene 1e10 from the origin
    #: had a 10-unit ``t_min`` and vanished; relative to the camera's 16-unit cell they stay tiny.
    camera_relative: bool = True
    #: Measured through ``aberrant render`` at 4096x4096 (peak resident memory): 4-6 bytes a pixel more
    #: for the colour image, 27 for all AOVs; the bands' working set is ~75 MB (RAYS_PER_BAND).
    aov_copies: ClassVar[float] = 2.0

    def __init__(self, precision: Precision | None = None) -> None:
        super().__init__(precision)
        self._tables: dict[str, np.ndarray] = {}
        self._counts: dict[str, int] = {}
        self._origin = np.zeros(3)
        self._features = Features()
        self._geometry: Geometry | None = None
        self._settings: ShadingSettings | None = None
        self._boxes = Boxes.empty()
        self._portals = Portals.empty()
        self._lights: Lights | None = None

    @classmethod
    def probe(cls) -> str | None:
        return None  # NumPy is a core dependency

    def info(self) -> dict[str, str]:
        return {"device": "CPU (NumPy)", "numpy": np.__version__, "precision": "float64"}

    @property
    def features(self) -> Features:
        """What the last uploaded scene contains."""
        return self._features

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        """Copy the changed tables (or rows), as a device upload would; returns the bytes moved."""
        if bvh_width(packed.tables["bvh_nodes"]) != self.bvh_width or bvh_compact(packed.tables["bvh_nodes"]):
            raise AberrantError(
                f"reference backend traverses binary BVHs; pack with bvh_width={self.bvh_width}, bvh_compact=False"
                " (ScenePacker)"
            )
        updates = list(updates)
        first = not self._tables
        for u in updates:
            source = packed.tables[u.table]
            mine = self._tables.get(u.table)
            if u.rows is None or mine is None or mine.shape != source.shape or mine.dtype != source.dtype:
                self._tables[u.table] = source.copy()
            else:
                mine[u.rows.start : u.rows.stop] = source[u.rows.start : u.rows.stop]
        for name, table in packed.tables.items():  # a first upload given a partial list still gets everything
            if name not in self._tables:
                self._tables[name] = table.copy()
        self._counts = dict(packed.counts)
        self._origin = np.asarray(packed.origin, dtype=np.float64).copy()
        self._features = packed.features
        changed = {u.table for u in updates}
        if self._geometry is None or changed & set(_MESH_TABLES):
            self._geometry = Geometry.from_tables(self._tables, self._counts)
        elif changed & set(_INSTANCE_TABLES):
            self._geometry = Geometry.from_tables(self._tables, self._counts, reuse_mesh_data=self._geometry)
        if self._settings is None or "settings" in changed:
            self._settings = ShadingSettings.from_table(self._tables["settings"])
        # Converted (and their trees built) when their tables change.
        if first or "aberrations" in changed:
            self._boxes = Boxes.from_table(self._tables["aberrations"], self._counts.get("aberrations", 0))
        if first or "portals" in changed:
            self._portals = Portals.from_table(self._tables["portals"], self._counts.get("portals", 0))
        if first or "lights" in changed:
            count = self._counts.get("lights", 0)
            self._lights = Lights.from_table(self._tables["lights"], count) if count else None
        return packed.update_bytes(updates)

    def trace_rays(
        self, origin: np.ndarray, directions: np.ndarray, sigma: tuple[np.ndarray, np.ndarray] | None = None
    ) -> TraceResult:
        """Trace arbitrary world rays (unit ``directions`` (N, 3)) and keep the float64 results.

        For tests and error reports that need more than the float32 AOVs.
        ``sigma`` is the radial mode's ``(m, M)`` (``CameraView.sigma_bounds``);
        without it every axis spans [-1, 1].
        """
        if self._geometry is None or self._settings is None:
            raise AberrantError("reference backend: trace_rays() before upload(); upload a packed scene first")
        o = np.asarray(origin, dtype=np.float64) - self._origin
        d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
        bounds = SigmaBounds.default() if sigma is None else SigmaBounds(*(np.asarray(b, np.float64) for b in sigma))
        return trace(self._geometry, self._settings, o, d, self._origin, self.space(bounds), self._lights)

    def lit(
        self, points: np.ndarray, normals: np.ndarray, towards: np.ndarray, reach: np.ndarray | None = None
    ) -> np.ndarray:
        """Whether shadow rays from world ``points`` (off the surface along unit ``normals``) towards unit
        ``towards`` get there: to the sky, or ``reach`` along the journey (docs/semantics.md, "Lights and
        shadows"). For tests of exact shadow edges."""
        if self._geometry is None or self._settings is None:
            raise AberrantError("reference backend: lit() before upload(); upload a packed scene first")
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self._origin
        n = np.broadcast_to(np.asarray(normals, dtype=np.float64), p.shape)
        t = np.broadcast_to(np.asarray(towards, dtype=np.float64), p.shape)
        far = np.full(len(p), np.inf) if reach is None else np.broadcast_to(np.asarray(reach, np.float64), len(p))
        with np.errstate(all="ignore"):
            return shadow_rays_lit(self._geometry, self._settings, self.space(), p, n, t, far)

    def space(self, sigma: SigmaBounds | None = None) -> Space:
        """The uploaded aberrations and portals as float64 arrays, with the radial bounds to trace by."""
        return Space(self._boxes, self._portals, sigma or SigmaBounds.default())

    @property
    def geometry(self) -> Geometry:
        """The uploaded mesh tables as float64 arrays (for tests and tools)."""
        if self._geometry is None:
            raise AberrantError("reference backend: nothing uploaded yet")
        return self._geometry

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        """Trace one frame; only the requested AOVs are filled."""
        width, height = self.check_request(
            width, height, aovs, uploaded=self._geometry is not None and self._settings is not None
        )
        assert self._geometry is not None and self._settings is not None
        start = time.perf_counter()
        origin = np.asarray(camera.position, dtype=np.float64) - self._origin
        space = self.space(SigmaBounds(*camera.sigma_bounds(width / height)))
        frame = _empty_frame(width, height, aovs)
        band = max(1, RAYS_PER_BAND // width)
        for first in range(0, height, band):
            rows = (first, min(height, first + band))
            directions = camera.primary_directions(width, height, rows).reshape(-1, 3)
            result = trace(self._geometry, self._settings, origin, directions, self._origin, space, self._lights)
            _fill(frame, rows, result)
        frame.timings_ms["render"] = (time.perf_counter() - start) * 1e3
        return frame


#: Rays traced at once. The vectorised tracer keeps ~700 bytes of state per ray (more with aberrations
#: and portals), so a frame is traced in bands of rows of about this many rays: ~50 MB of working memory
#: whatever the image size, and only the AOVs (17 bytes a pixel at most) grow with it. Each ray's result
#: is independent of the others traced with it, so bands give the same frame as one pass.
RAYS_PER_BAND = 1 << 16


def _empty_frame(width: int, height: int, aovs: Sequence[str]) -> Frame:
    frame = Frame(width, height)
    for name in aovs:
        dtype, tail = AOV_DTYPES[name]
        setattr(frame, name, np.empty((height, width, *tail), dtype))
    return frame


def _fill(frame: Frame, rows: tuple[int, int], result: TraceResult) -> None:
    """Write per-ray results of ``rows`` (first, end) into the frame's AOV images (row 0 = top)."""
    shape = (rows[1] - rows[0], frame.width)
    band = slice(*rows)
    if frame.color is not None:
        frame.color[band, :, :3] = to_uint8(result.color).reshape(*shape, 3)
        frame.color[band, :, 3] = 255
    if frame.depth is not None:
        frame.depth[band] = result.depth.astype(np.float32).reshape(shape)
    if frame.perceived is not None:
        frame.perceived[band] = result.perceived.astype(np.float32).reshape(shape)
    if frame.instance is not None:
        frame.instance[band] = result.instance.astype(np.int32).reshape(shape)
    if frame.events is not None:
        frame.events[band] = np.minimum(result.events, 255).astype(np.uint8).reshape(shape)
