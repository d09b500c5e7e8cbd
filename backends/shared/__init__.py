"""The tracer core shared by the GLSL and OpenCL backends (docs/design.md section 4).

The files here are written once in the common subset of GLSL 4.30 and
OpenCL C 1.2. A backend assembles a program as::

    defines + its language prelude + layout.h + its bindings + the tracer files + its main

where the prelude maps the core's types and helpers to the language
(``backends/glsl/prelude.glsl``, ``prelude_cl.h`` here), ``layout.h`` declares the
packed records (written from ``engine.layout``'s declarations, ``layout_h.py``, not
stored) and the bindings say
how the packed tables are reached (GLSL: storage-buffer arrays, or RGBA32UI
images on llvmpipe, ``backends/glsl/bindings.glsl``; OpenCL: a struct of
``__global`` pointers, ``bindings_cl.h``); the tracer files are :data:`TRACER_FILES`, ``options.h``
(the compile-time options) to ``pixel.h``. See ``core.h`` for the macros a prelude must provide.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import replace
from importlib import resources
from typing import ClassVar

import numpy as np

from engine import layout
from engine.box_clearance import instance_bounds
from engine.camera_view import CAMERA_FACE_MARGIN, CameraView, seen_leaves, view_reaches
from engine.packed import Features, PackedScene
from engine.tlas import rows_at
from engine.tlas_wide import TlasLanes

from .frame_tiles import INSTANCE_TILE_MAX as INSTANCE_TILE_MAX
from .frame_tiles import INSTANCE_TILE_MIN as INSTANCE_TILE_MIN
from .frame_tiles import INSTANCE_TILE_MIN_BESIDE as INSTANCE_TILE_MIN_BESIDE
from .frame_tiles import FrameTiles, frame_view_tiles
from .frame_tiles import view_tile_defines as view_tile_defines
from .layout_h import layout_h

#: The tracer core's files, in the order a backend concatenates them after its prelude, ``layout.h``
#: and its bindings: each builds on those before it (options.h's defines, then core.h's records and helpers, the
#: kernels' entry point ``trace_pixel`` in pixel.h last; shade.h after journey.h, whose shadow rays it sends).
TRACER_FILES: tuple[str, ...] = (
    "options.h",
    "core.h",
    "triangle.h",
    "bvh_binary.h",
    "bvh_wide.h",
    "instances.h",
    "space.h",
    "boxes.h",
    "portals.h",
    "legs.h",
    "journey.h",
    "shade.h",
    "pixel.h",
)


#: Kernel files written from the host's declarations rather than stored: name -> the function writing them.
GENERATED: dict[str, Callable[[], str]] = {"layout.h": layout_h}


def read(name: str, package: str = __name__) -> str:
    """The text of a kernel file shipped beside a backend (``importlib.resources``, so it works zipped too),
    or of one of this package's :data:`GENERATED` files."""
    if package == __name__ and name in GENERATED:
        return GENERATED[name]()
    return resources.files(package).joinpath(name).read_text(encoding="utf-8")


def defines_block(defines: Mapping[str, int | float | str]) -> str:
    """``#define NAME VALUE`` lines, in a stable order (a variant's source is its cache key)."""
    lines = []
    for name in sorted(defines):
        value = defines[name]
        if isinstance(value, bool):
            value = int(value)
        lines.append(f"#define {name} {value}")
    return "\n".join(lines) + "\n"


# --- helpers both fast backends need ----------------------------------------------------------

#: The smallest traversal stack compiled; deeper trees get a larger one, in steps of 16.
MIN_STACK = 32


def assemble(header: str, defines: Mapping[str, int | float | str], files: Sequence[tuple[str, str]]) -> str:
    """One variant's full source: ``header`` + defines + each ``(package, file)`` in order, each marked."""
    parts = [header, defines_block(defines)]
    for package, name in files:
        parts.append(f"// ---- {name}\n")
        parts.append(read(name, package))
    return "".join(parts)


def bvh_depth(nodes: np.ndarray, count: int) -> int:
    """The depth of the deepest tree in a packed node table (all assets' trees together).

    Roots are the nodes no interior node points to; a lone leaf has depth 1.
    """
    nodes = nodes[:count]
    if count == 0:
        return 0
    if layout.bvh_compact(nodes):  # from each header's root link, through the interior records' links
        link0, link1 = nodes["child0"][:, 3].astype(np.int64), nodes["child1"][:, 3].astype(np.int64)
        mask = (1 << layout.BVH_LINK_SHIFT) - 1
        frontier = link0[link1 == -1]
        depth = 0
        while frontier.size and depth <= count:
            depth += 1
            inner = frontier[(frontier >= 0) & (frontier & mask == 0)] >> layout.BVH_LINK_SHIFT
            inner = inner[inner < count]
            frontier = np.concatenate([link0[inner], link1[inner]])
        return depth
    if layout.bvh_width(nodes) > 2:  # wide nodes only: their leaves live in their slots
        child, kind = nodes["child"].reshape(count, -1).astype(np.int64), nodes["count"].reshape(count, -1)
        is_child = np.zeros(count, bool)
        kids = child[kind == 0]
        is_child[kids[(kids >= 0) & (kids < count)]] = True
        frontier = np.flatnonzero(~is_child)
        depth = 0
        while frontier.size and depth <= count:
            depth += 1
            frontier = child[frontier][kind[frontier] == 0]
            frontier = frontier[(frontier >= 0) & (frontier < count)]
        return depth
    first = nodes["first"].astype(np.int64)
    inner = nodes["count"] == 0
    is_child = np.zeros(count, bool)
    kids = first[inner]
    is_child[kids[(kids >= 0) & (kids < count)]] = True
    is_child[kids[(kids + 1 >= 0) & (kids + 1 < count)] + 1] = True
    frontier = np.flatnonzero(~is_child)
    depth = 0
    while frontier.size and depth <= count:
        depth += 1
        frontier = frontier[inner[frontier]]
        frontier = np.concatenate([first[frontier], first[frontier] + 1])
        frontier = frontier[(frontier >= 0) & (frontier < count)]
    return depth


def stack_entries(nodes: np.ndarray, count: int) -> int:
    """The most traversal-stack entries any tree of a node table can need.

    A binary visit leaves at most one entry per level; a w-wide one pushes up to w and pops 1, leaving w - 1.
    """
    depth = bvh_depth(nodes, count)
    width = layout.bvh_width(nodes[:count]) if count else 2
    return (width - 1) * depth + 1 if width > 2 else depth


def stack_size(nodes: np.ndarray, count: int) -> int:
    """``BVH_STACK_SIZE`` for a node table: every tree's stack fits, rounded up so few variants exist."""
    return max(MIN_STACK, -(-stack_entries(nodes, count) // 16) * 16)


def bvh_defines(nodes: np.ndarray, count: int) -> dict[str, int]:
    """The defines a ``bvh_nodes`` table asks for, from its dtype: ``BVH_WIDTH``, ``BVH_COMPACT``; and
    ``BVH_STACK_SIZE``."""
    return {
        "BVH_WIDTH": layout.bvh_width(nodes),
        "BVH_COMPACT": int(layout.bvh_compact(nodes)),
        "BVH_STACK_SIZE": stack_size(nodes, count),
    }


#: The smallest top-level (instance) traversal stack compiled; deeper trees get more, in steps of 8.
MIN_TLAS_STACK = 16


def tlas_stack_size(nodes: np.ndarray, count: int) -> int:
    """``TLAS_STACK_SIZE`` for a ``tlas_nodes`` table: its walk's entries fit (a SAH tree: about log2 of the
    instances, times width - 1 when wide), rounded up so few variants exist."""
    return max(MIN_TLAS_STACK, -(-stack_entries(nodes, count) // 8) * 8)


#: The loops' iterations grow with the portal and box counts at every event; llvmpipe ends every loop of a
#: shader invocation after 65,535 iterations of them all together (Mesa's LP_MAX_TGSI_LOOP_ITERATIONS),
#: which 16 events over 4,400 portals used up. The trees' grow with their depth: each backend loops only
#: below a few (UploadedScene.tree_min).


def tree_depth(nodes: np.ndarray, root: int) -> int:
    """Levels of the binary tree of ``nodes`` (TLAS layout: ``count == 0`` interior) from row ``root``."""
    frontier = np.array([root], np.int64)
    depth = 0
    while frontier.size and depth <= len(nodes):
        depth += 1
        inner = frontier[nodes["count"][frontier] == 0]
        first = nodes["first"][inner].astype(np.int64)
        frontier = np.concatenate([first, first + 1])
    return depth


def wide_space_depth(nodes: np.ndarray, root: int) -> int:
    """Levels of the 4-wide space tree stored from row ``root`` of ``space_nodes`` (engine/space_wide.py)."""
    raw = nodes.view(np.int32).reshape(len(nodes), 8)
    frontier = np.array([root], np.int64)
    depth = 0
    while frontier.size and depth <= len(nodes):
        depth += 1
        kids = raw[frontier + 3, :4].reshape(-1)
        frontier = kids[kids > 0].astype(np.int64)
    return depth


def space_defines(packed: PackedScene, tree_min: tuple[int, int], wide: bool = False) -> dict[str, int]:
    """PORTAL_TREE, BOX_TREE, SPACE_WIDE and SPACE_STACK_SIZE for a packed scene: a tree where there are more
    portals or boxes than ``tree_min`` says pay for it, walked in its 4-wide form where ``wide``; a stack that
    fits the deeper tree's walk (a binary one's depth, a wide one's 3 entries a level and one; the point
    look-up walks the binary tree), rounded up to 8, so few variants exist."""
    portals, boxes = packed.counts.get("portals", 0), packed.counts.get("aberrations", 0)
    nodes, roots = packed.tables["space_nodes"], packed.tables["settings"]["space_roots"][0]
    use = portals > tree_min[0], boxes > tree_min[1]
    depth = max([tree_depth(nodes, int(roots[k])) for k in (0, 1) if use[k]], default=0)
    if wide:
        depth = max([depth] + [3 * wide_space_depth(nodes, int(roots[k + 2])) + 1 for k in (0, 1) if use[k]])
    return {
        "PORTAL_TREE": int(use[0]),
        "BOX_TREE": int(use[1]),
        "SPACE_WIDE": int(wide),
        "SPACE_STACK_SIZE": max(MIN_SPACE_STACK, -(-depth // 8) * 8),
    }


#: The kernels' NUDGE_RELATIVE (core.h) by precision: the active box after an event is looked up this far
#: (times max(1, |o| + t)) past it.
FACE_NUDGE: dict[str, float] = {"f32": 5.0e-5, "f64": 1.0e-8}


#: The smallest stack of the trees over portals and boxes.
MIN_SPACE_STACK = 16


class UploadedScene:
    """Mixin of the fast backends: what they keep of their last upload. The tree defines, stack sizes
    and features pick the kernel variant; origin, boxes and instance bounds pack the camera row."""

    #: Above this many portals, and boxes, the kernels find them through their trees, below it with loops
    #: (where those are as fast: each backend's own, from scripts/space_scale.py A/Bs).
    tree_min: ClassVar[tuple[int, int]] = (8, 4)
    #: Whether the kernels walk the space trees' 4-wide forms (SPACE_WIDE), not the binary ones: each
    #: backend's own, from scripts/space_tree_ab.py A/Bs.
    space_wide: ClassVar[bool] = False
    #: Whether camera rays take their first leg's portals (VIEW_TILES) from the frame's view tiles where that
    #: frame allows (interleaved A/B in README.md's table; boxes keep their tree: no gain there).
    view_tiles: bool = True
    #: ... and their first mesh search's instances (INSTANCE_TILES): each backend's own (README.md's table),
    #: ``INSTANCE_TILES=1`` or ``=0`` in the extra defines decides alone.
    instance_tiles: bool = False
    #: ... and the leg after a first portal's instances (PORTAL_LEGS), where the frame allows: GLSL's (PoCL: 1.02x
    #: ten-boxes-portals' time at 400x400, 0.97x at 800x800), ``PORTAL_LEGS=1`` or ``=0`` decides alone.
    portal_legs: bool = False
    #: Extra defines for every variant (each backend's; ``VIEW_TILES=0`` or ``INSTANCE_TILES=0`` also skips
    #: building that section of the tiles).
    extra_defines: dict[str, int]

    def _forget_upload(self) -> None:
        self._counts: dict[str, int] = {}
        self._origin = np.zeros(3)
        self._boxes: np.ndarray | None = None
        self._box_tree: tuple[np.ndarray, int] | None = None
        self._space_nodes = np.zeros(1, layout.SPACE_NODE_DTYPE)
        self._portal_root: int | None = None
        self._portals: np.ndarray | None = None
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None
        self._tlas_nodes = np.zeros(1, layout.TLAS_NODE_DTYPE)
        self._tlas_lanes: TlasLanes | None = None
        # The portal tree's leaves a frame's camera sees (the camera, the aspect, the leaves), where
        # _frame_features walked them for its view tiles.
        self._seen_portals: tuple[CameraView, float, np.ndarray] | None = None
        self._box_gap = 0.0
        self._reach = 0.0
        self._features = Features()
        self._bvh: dict[str, int] = {"BVH_WIDTH": 2, "BVH_COMPACT": 0, "BVH_STACK_SIZE": MIN_STACK}
        self._tlas_stack = MIN_TLAS_STACK
        self._tlas_width = 2
        self._space: dict[str, int] = {
            "PORTAL_TREE": 0, "BOX_TREE": 0, "SPACE_WIDE": 0, "SPACE_STACK_SIZE": MIN_SPACE_STACK
        }  # fmt: skip
        self._uploaded = False

    def _note_upload(self, packed: PackedScene, rewritten: set[str], written: set[str]) -> None:
        """After an upload; ``rewritten``: the tables written whole (a tree table's depth may have changed),
        ``written``: every table written, whole or in rows."""
        if "bvh_nodes" in rewritten:
            self._bvh = bvh_defines(packed.tables["bvh_nodes"], packed.counts.get("bvh_nodes", 0))
        if "tlas_nodes" in rewritten:
            self._tlas_stack = tlas_stack_size(packed.tables["tlas_nodes"], packed.counts.get("tlas_nodes", 0))
            self._tlas_width = layout.bvh_width(packed.tables["tlas_nodes"])
        if rewritten & {"space_nodes", "portals", "aberrations"}:
            self._space = space_defines(packed, self.tree_min, self.space_wide)
        self._counts = dict(packed.counts)
        self._origin = np.asarray(packed.origin, dtype=np.float64).copy()
        # The boxes in use, for the camera row's box (pack_camera); a copy, as the packer edits its tables.
        self._boxes = packed.tables["aberrations"][: packed.counts.get("aberrations", 0)].copy()
        # ... and the trees over the boxes and the portals, to find it among many and to see what the camera sees.
        nodes, roots = packed.tables["space_nodes"].copy(), packed.tables["settings"]["space_roots"][0]
        self._space_nodes = nodes
        self._box_tree = (nodes, int(roots[1])) if self._boxes.size else None
        self._portal_root = int(roots[0]) if packed.counts.get("portals", 0) else None
        self._portals = packed.tables["portals"][: packed.counts.get("portals", 0)].copy()
        # The instances' bounds, for the camera's clearance (pack_camera: the first mesh search it proves empty).
        self._bounds = instance_bounds(packed)
        # ... and the tree over them, for the instances the camera sees (the view tiles; a copy, likewise): its
        # lanes are made when a frame's tiles first need them, so a tick that moves an instance inside its fat
        # leaf (no tree row written) or renders no tiles pays nothing for them.
        if "tlas_nodes" in written:
            self._tlas_nodes = packed.tables["tlas_nodes"][: max(1, packed.counts.get("tlas_nodes", 0))].copy()
            self._tlas_lanes = None
        # ... and what FACE_NEXT_ONLY's proof needs: the boxes' least gap, the largest |p| of what rays meet.
        self._box_gap = float(self._boxes["rotation"][:, 1, 3].min()) if self._boxes.size else 0.0
        corners = [self._bounds[0], self._bounds[1]]
        for root in (self._portal_root, self._box_tree[1] if self._box_tree else None):
            if root is not None:
                corners += [nodes["bounds_min"][root].astype(np.float64), nodes["bounds_max"][root].astype(np.float64)]
        self._reach = max(float(np.abs(c).max(initial=0.0)) for c in corners) * 3.0**0.5
        self._features = packed.features
        self._uploaded = True

    def _instance_search_defines(self) -> dict[str, int]:
        """A scene of one instance culls it by its bounds without the instance tree's walk (USE_TLAS 0): mesh-10k
        0.90x / 0.88x the time (OpenCL / GLSL, 400x400, interleaved); 13 instances lose (starter 1.09x / 1.25x)."""
        return {"USE_TLAS": int(self._counts.get("instances", 0) != 1)}

    def _frame_space_defines(self, features: Features, row: np.ndarray, precision: str) -> dict[str, int]:
        """Box code a frame provably never runs, compiled out (CAMERA_BOX_ENTRY, FACE_NEXT_ONLY in options.h): llvmpipe
        runs every branch masked for all its lanes, and PoCL folds the first leg's box state (none) into constants
        where the camera's transition is gone. ``row``: the frame's camera row (pack_camera).

        The gap test after a face (box_after_face) compares a box's gap with 2 nudges of |o| + t: a leg starts
        at the camera or on a portal, box or instance (within reach R of the packed origin) and its face lies
        within 2 R of that start, so |o| + t <= 3 R / |r|; it holds for every face when the least gap exceeds
        that with a factor 2 of margin (|r| is 1 within rounding)."""
        if not features.aberration_modes:
            return {}
        reach = max(self._reach, float(np.linalg.norm(row["position"][0, :3])))
        nudge = FACE_NUDGE[precision] * max(1.0, 4.0 * reach)
        return {
            "CAMERA_BOX_ENTRY": int(row["size"][0, 2] != -1),
            "FACE_NEXT_ONLY": int(np.isfinite(self._box_gap) and self._box_gap > 4.0 * nudge),
        }

    def _frame_features(self, camera: CameraView, width: int, height: int, shade: bool = True) -> Features:
        """The features a frame needs: no shadows without shading (``shade`` False: no colour asked for); none of
        the space's where the host proves that no primary ray meets a portal or a box (all outside the camera's
        pyramid, the camera in no box). Every ray then has one leg, and the Euclidean variant gives the same
        frame without paying for the space's code."""
        features = self._features if shade or not self._features.shadows else replace(self._features, shadows=False)
        self._seen_portals = None
        if not (features.portals or features.aberration_modes) or features.shadows:
            return features  # shadow rays start anywhere: they may meet what no primary ray does
        aspect = width / height
        portal_root = self._portal_root if features.portals else None
        if portal_root is not None and self.view_tiles and self._space["PORTAL_TREE"]:
            # The leaves the frame's view tiles list: one walk for both (1,024 portals in view: 0.2 ms less).
            leaves = seen_leaves(camera, aspect, self._origin, self._space_nodes, portal_root)
            self._seen_portals = (camera, aspect, leaves)
            if leaves.size:
                return features
        elif portal_root is not None and view_reaches(camera, aspect, self._origin, self._space_nodes, portal_root):
            return features
        if features.aberration_modes and self._box_tree is not None:
            nodes, root = self._box_tree
            position = np.asarray(camera.position, dtype=np.float64) - self._origin
            near = CAMERA_FACE_MARGIN * max(1.0, float(np.linalg.norm(position)))
            if view_reaches(camera, aspect, self._origin, nodes, root) or rows_at(nodes, root, position, near):
                return features
        return replace(features, portals=False, aberration_modes=frozenset())

    def split_frame(self, features: Features) -> bool:
        """Whether a frame of ``features`` may be traced in two dispatches: none by default; GLSL's own
        (backends/glsl/split.py)."""
        return False

    def _instance_lanes(self) -> TlasLanes:
        """The uploaded instance tree as lanes for the host's walks (engine.tlas_wide.TlasLanes), made once per
        change of the tree."""
        if self._tlas_lanes is None:
            self._tlas_lanes = TlasLanes.of(self._tlas_nodes)
        return self._tlas_lanes

    def _frame_view_tiles(
        self, camera: CameraView, width: int, height: int, features: Features, row: np.ndarray
    ) -> FrameTiles | None:
        """The frame's view tiles, or None (:func:`backends.shared.frame_tiles.frame_view_tiles`)."""
        return frame_view_tiles(self, camera, width, height, features, row)
