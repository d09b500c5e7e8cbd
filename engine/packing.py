"""Packing the ECS into the flat tables every tracer reads (layouts in :mod:`engine.layout`).

The packer is incremental: it follows the scene's change journal and
re-packs a table row when one entity changes, the whole table only when the
scene's structure (entities, components, assets) changes. Each sync returns
the :class:`engine.packed.TableUpdate` list a backend needs to upload: a static tick
returns nothing.

Float32 backends trace in camera-relative coordinates (docs/semantics.md, "Primary rays"):
the packer subtracts a float64 *origin* near the camera from every world
transform. The origin snaps to a grid of ``origin_cell`` units and moves only
when the camera leaves its cell, so walking does not re-upload every
transform each frame, yet coordinates stay within a cell of the camera, where
float32 is fine-grained (1e-6 at 16 units).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from components import Mesh, Transform
from engine import layout
from engine.affine_batch import transform_arrays, trs_forward, trs_inverse_batch
from engine.bvh import BvhParams
from engine.camera_view import scene_camera
from engine.maths import normalize
from engine.packed import Features, PackedScene, TableUpdate
from engine.packing_geometry import PackedGeometry, pack_geometry
from engine.packing_lights import light_entities, pack_lights, shadowing
from engine.packing_space import SpaceTables
from engine.records import Precision
from engine.scene import Scene
from engine.scene_world import SETTINGS
from engine.textures import DEFAULT_BUDGET_MIB
from engine.tlas import FAT_MARGIN, AabbTree
from engine.tlas_wide import WideTlas


def _round_out(lo: np.ndarray, hi: np.ndarray, precision: Precision) -> tuple[np.ndarray, np.ndarray]:
    if precision == "f64":
        return lo, hi
    lo32 = np.nextafter(lo.astype(np.float32), np.float32(-np.inf))
    hi32 = np.nextafter(hi.astype(np.float32), np.float32(np.inf))
    return lo32, hi32


def _changed_ranges(old: np.ndarray, new: np.ndarray) -> list[range]:
    """Contiguous row ranges whose bytes differ."""
    a = old.view(np.uint8).reshape(len(old), -1)
    b = new.view(np.uint8).reshape(len(new), -1)
    rows = np.flatnonzero(np.any(a != b, axis=1))
    if rows.size == 0:
        return []
    breaks = np.flatnonzero(np.diff(rows) > 1)
    starts = np.concatenate([[rows[0]], rows[breaks + 1]])
    ends = np.concatenate([rows[breaks], [rows[-1]]]) + 1
    return [range(int(s), int(e)) for s, e in zip(starts, ends, strict=True)]


def _at_least_one_row(table: np.ndarray) -> np.ndarray:
    return table if len(table) else np.zeros(1, dtype=table.dtype)


# --- the packer ------------------------------------------------------------------------


class ScenePacker:
    """Keeps a :class:`engine.packed.PackedScene` in step with a :class:`engine.scene.Scene`, one journal
    cursor at a time."""

    def __init__(
        self,
        precision: Precision = "f32",
        camera_relative: bool = True,
        origin_cell: float = 16.0,
        bvh_params: BvhParams | None = None,
        bvh_width: int = 2,
        tlas_margin: float = FAT_MARGIN,
        bvh_compact: bool = False,
        tlas_width: int = 2,
        texture_budget_mib: float = DEFAULT_BUDGET_MIB,
    ) -> None:
        if bvh_width not in layout.BVH_WIDTHS:
            raise ValueError(f"bvh_width must be one of {sorted(layout.BVH_WIDTHS)}, got {bvh_width!r}")
        if bvh_compact and bvh_width != 2:
            raise ValueError(f"bvh_compact needs bvh_width=2, got {bvh_width!r}")
        self.precision: Precision = precision
        #: Children per BVH node in ``bvh_nodes`` (the backend's ``bvh_width``: what it traverses fastest).
        self.bvh_width = bvh_width
        #: Binary trees as compact records (the backend's ``bvh_compact``: fewer loads per visit).
        self.bvh_compact = bvh_compact
        self.camera_relative = camera_relative
        self.origin_cell = origin_cell
        self.bvh_params = bvh_params or BvhParams()
        #: The most MiB of texels the scene's textures may take (16 bytes a texel); past it, a clear error.
        self.texture_budget_mib = texture_budget_mib
        self.packed: PackedScene | None = None
        self._cursor = -1
        self._scene_world: str | None = None
        self._instance_row: dict[int, int] = {}
        #: The asset tables' offsets (each asset's tree root and flags, normals, texels) of the last full pack.
        self._geometry = PackedGeometry({}, {}, {}, {}, {})
        self.tlas_margin = tlas_margin
        #: The top-level tree over the instance rows (``tlas_nodes``), kept in step with them.
        self.tlas = AabbTree.build(np.zeros((0, 3)), np.zeros((0, 3)), tlas_margin)
        #: Children per node of the packed top-level tree (``tlas_nodes``, :mod:`engine.tlas_wide`).
        self.tlas_width = tlas_width
        self.tlas_wide = WideTlas.of(self.tlas, tlas_width)
        #: The portal and aberration rows and the trees over them (``space_nodes``).
        self.space = SpaceTables(precision)

    # origin ---------------------------------------------------------------------------

    def _choose_origin(self, camera_position: np.ndarray, current: np.ndarray | None) -> np.ndarray:
        if not self.camera_relative:
            return np.zeros(3)
        if current is not None and np.max(np.abs(camera_position - current)) <= self.origin_cell:
            return current
        return np.round(camera_position / self.origin_cell) * self.origin_cell

    # sync ---------------------------------------------------------------------------------

    def sync(self, scene: Scene, camera_position: np.ndarray | None = None) -> list[TableUpdate]:
        """Bring the packed tables up to date; returns what changed (empty when nothing did)."""
        if camera_position is None:
            camera_position = scene_camera(scene).position
        camera_position = np.asarray(camera_position, dtype=np.float64)
        changes = None if self._scene_world != scene.world else scene.changes_since(self._cursor)
        packed = self.packed
        if packed is None or changes is None or any(c.kind in ("structure", "assets") for c in changes):
            self._full(scene, self._choose_origin(camera_position, None if packed is None else packed.origin))
            self._cursor = scene.cursor
            self._scene_world = scene.world
            assert self.packed is not None
            return [TableUpdate(name) for name in layout.TABLES]
        self._cursor = scene.cursor
        updates: list[TableUpdate] = []
        origin = self._choose_origin(camera_position, packed.origin)
        if not np.array_equal(origin, packed.origin):
            delta = origin - packed.origin
            packed.origin = origin
            self._pack_instances(scene)
            self.tlas.translate(delta, *self._instance_bounds())
            self._store_tlas()
            updates += [TableUpdate("instances"), TableUpdate("tlas_nodes")]
            updates += self.space.translate(scene, packed, delta, self._instance_bounds())
            self._pack_lights(scene)
            updates += [TableUpdate("lights")]
            changes = [c for c in changes if c.kind not in ("transform",)]
        instance_rows: set[int] = set()
        material_rows: set[int] = set()
        portals: set[int] = set()
        boxes: set[int] = set()
        components = False
        lights = set(light_entities(scene))
        for change in changes:
            if change.kind == "light" or (change.kind == "transform" and change.entity in lights):
                self._pack_lights(scene)
                updates.append(TableUpdate("lights"))
                components |= change.kind == "light"
            if change.kind == SETTINGS:
                self._pack_settings(scene)
                updates.append(TableUpdate("settings"))
            elif change.kind in ("transform", "mesh") and change.entity in self._instance_row:
                mesh = scene.get(change.entity, Mesh)
                if scene.asset(mesh.asset).content_hash not in self._geometry.roots or (
                    change.kind == "mesh" and not self._has_shading_data(scene, mesh)
                ):
                    return self._resync(scene, camera_position)
                instance_rows.add(self._instance_row[change.entity])
                if change.kind == "mesh":
                    material_rows.add(self._instance_row[change.entity])
            if change.kind in ("transform", "aberration") and change.entity in self.space.boxes.row:
                boxes.add(change.entity)
                components |= change.kind == "aberration"
            if change.kind in ("transform", "portal", "name") and change.entity in self.space.portals.row:
                portals.add(change.entity)
                components |= change.kind == "portal"
        for row in sorted(instance_rows):
            self._pack_instance_rows(scene, [row])
            updates.append(TableUpdate("instances", range(row, row + 1)))
        if instance_rows:
            updates += self._update_tlas(sorted(instance_rows))
        for row in sorted(material_rows):
            self._pack_material_row(scene, row)
            updates.append(TableUpdate("materials", range(row, row + 1)))
        components |= bool(material_rows)  # a checker added or removed changes the features
        if portals or boxes or instance_rows:
            space = self.space.update(scene, packed, portals, boxes, self._instance_bounds(), sorted(instance_rows))
            if space is None:  # a box's priority moved its row: the space tables anew
                self.space.full(scene, packed, self._instance_bounds())
                space = [TableUpdate(name) for name in ("portals", "aberrations", "space_nodes")]
                components = True
            updates += space
        if components:
            features = packed.features
            self._update_features_and_counts(scene)
            if packed.features != features:
                updates.append(TableUpdate("settings"))
        updates = _merge(updates)
        for u in updates:
            packed.versions[u.table] = packed.versions.get(u.table, 0) + 1
        return updates

    def _has_shading_data(self, scene: Scene, mesh: Mesh) -> bool:
        """Whether the packed normals and texels already hold what ``mesh`` shades with."""
        asset = scene.asset(mesh.asset)
        if mesh.smooth and (asset.content_hash, mesh.crease_deg) not in self._geometry.normal_offset:
            return False
        texture = scene.texture(mesh) if asset.uvs is not None else None
        return texture is None or texture.content_hash in self._geometry.texture_first

    def _resync(self, scene: Scene, camera_position: np.ndarray) -> list[TableUpdate]:
        self.packed = None
        return self.sync(scene, camera_position)

    # full packing --------------------------------------------------------------------

    def _full(self, scene: Scene, origin: np.ndarray) -> None:
        scene.validate()
        old_versions = self.packed.versions if self.packed is not None else {}
        meshes = scene.query(Transform, Mesh)
        self._instance_row = {entity: row for row, (entity, _) in enumerate(meshes)}
        geometry = pack_geometry(scene, meshes, self.bvh_params, self.bvh_width, self.bvh_compact,
                                 self.texture_budget_mib)  # fmt: skip
        self._geometry = geometry
        tables = geometry.tables
        counts = {name: len(t) for name, t in tables.items()}
        tables = {name: _at_least_one_row(t) for name, t in tables.items()}
        features = Features(textures=bool(self._geometry.texture_first), smooth=bool(self._geometry.normal_offset))
        self.packed = PackedScene(
            self.precision, origin, tables, counts, features, np.array([e for e, _ in meshes], dtype=np.int32),
            versions={name: old_versions.get(name, 0) + 1 for name in layout.TABLES},
        )  # fmt: skip
        self._pack_instances(scene)
        self.tlas = AabbTree.build(*self._instance_bounds(), self.tlas_margin)
        self._store_tlas()
        self._pack_materials(scene)
        self.space.full(scene, self.packed, self._instance_bounds())
        self._pack_lights(scene)
        self._update_features_and_counts(scene)

    def _pack_lights(self, scene: Scene) -> None:
        """The ``lights`` table anew: a few rows, re-packed whole when one changes."""
        assert self.packed is not None
        self.packed.tables["lights"], self.packed.counts["lights"] = pack_lights(
            scene, self.packed.origin, self.precision
        )

    def _pack_settings(self, scene: Scene) -> None:
        assert self.packed is not None
        s = scene.settings
        row = np.zeros(1, dtype=layout.SETTINGS_DTYPE)
        row["background"][0, :3] = s.background
        row["background"][0, 3] = 1.0
        row["light_dir"][0, :3] = normalize(s.light_dir)
        row["event_limit_color"][0, :3] = s.event_limit_color
        row["event_limit_color"][0, 3] = 1.0
        row["shading"][0, 0] = s.ambient
        c = self.packed.counts
        row["counts"][0] = (c["instances"], c["aberrations"], c["portals"], s.max_events)
        row["space_roots"][0] = (0, self.space.box_root, *self.space.wide_roots)
        row["lights"][0] = (c.get("lights", 0), 0, 0, 0)
        self.packed.tables["settings"] = row
        self.packed.counts["settings"] = 1
        self.packed.features = replace(self.packed.features, max_events=s.max_events)

    def _update_features_and_counts(self, scene: Scene) -> None:
        assert self.packed is not None
        lights = self.packed.counts.get("lights", 0) > 0
        cells = self.packed.tables["materials"]["color"][: self.packed.counts["materials"], 3]
        self.packed.features = replace(
            self.packed.features, portals=self.space.linked, aberration_modes=self.space.modes,
            max_events=scene.settings.max_events, lights=lights, shadows=lights and shadowing(scene),
            checker=bool(np.any(cells > 0)),
        )  # fmt: skip
        self._pack_settings(scene)

    def _pack_instances(self, scene: Scene) -> None:
        assert self.packed is not None
        n = len(self._instance_row)
        self.packed.counts["instances"] = n
        self.packed.tables["instances"] = np.zeros(max(n, 1), dtype=layout.instance_dtype(self.precision))
        if n:
            self._pack_instance_rows(scene, list(range(n)))

    def _pack_instance_rows(self, scene: Scene, rows: list[int]) -> None:
        packed = self.packed
        assert packed is not None
        entities = [int(packed.instance_entities[r]) for r in rows]
        transforms = [scene.get(e, Transform) for e in entities]
        meshes = [scene.get(e, Mesh) for e in entities]
        p, r, s = transform_arrays(transforms, packed.origin)
        forward = trs_forward(p, r, s)
        table = packed.tables["instances"]
        table["world_to_object"][rows, :, :] = trs_inverse_batch(p, r, s)
        for i, (row, entity, mesh) in enumerate(zip(rows, entities, meshes, strict=True)):
            asset = scene.asset(mesh.asset)
            lo, hi = asset.bounds()
            corners = np.array(
                [[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])], dtype=np.float64
            )
            world = corners @ forward[i, :, :3].T + forward[i, :, 3]
            bmin, bmax = _round_out(world.min(axis=0), world.max(axis=0), self.precision)
            table["bounds_min"][row, :3] = bmin
            table["bounds_max"][row, :3] = bmax
            table["meta"][row] = (
                self._geometry.roots[asset.content_hash],
                row,
                entity,
                self._geometry.flags[asset.content_hash] | (layout.INSTANCE_FLAG_SMOOTH if mesh.smooth else 0),
            )

    def _instance_bounds(self, rows: list[int] | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Exact world bounds of instance rows (all live rows by default) as float64 (n, 3)."""
        assert self.packed is not None
        table = self.packed.tables["instances"]
        index = slice(0, self.packed.counts["instances"]) if rows is None else rows
        return table["bounds_min"][index, :3].astype(np.float64), table["bounds_max"][index, :3].astype(np.float64)

    def _store_tlas(self) -> None:
        """The packed table of the whole tree (after a build, a rebuild or an origin shift)."""
        assert self.packed is not None
        self.tlas_wide = WideTlas.of(self.tlas, self.tlas_width)
        self.packed.tables["tlas_nodes"] = self.tlas_wide.nodes
        self.packed.counts["tlas_nodes"] = self.tlas_wide.count

    def _update_tlas(self, rows: list[int]) -> list[TableUpdate]:
        """The tree after instance ``rows`` moved: nothing while they stay in their fat boxes, else the
        refitted node rows, or the whole table when it was rebuilt."""
        changed = self.tlas.update(rows, *self._instance_bounds(rows))
        if changed is None:
            self._store_tlas()
            return [TableUpdate("tlas_nodes")]
        return [TableUpdate("tlas_nodes", range(n, n + 1)) for n in self.tlas_wide.refit(self.tlas, changed)]

    def _pack_materials(self, scene: Scene) -> None:
        assert self.packed is not None
        n = len(self._instance_row)
        self.packed.counts["materials"] = n
        self.packed.tables["materials"] = np.zeros(max(n, 1), dtype=layout.MATERIAL_DTYPE)
        for row in range(n):
            self._pack_material_row(scene, row)

    def _pack_material_row(self, scene: Scene, row: int) -> None:
        assert self.packed is not None
        mesh = scene.get(int(self.packed.instance_entities[row]), Mesh)
        table = self.packed.tables["materials"]
        table["color"][row] = (*mesh.color, mesh.checker)
        table["flags"][row] = (int(mesh.cull_backfaces), 0, 0, 0)
        asset = scene.asset(mesh.asset)
        table["color"][row, :3] *= asset.base_color
        texture = scene.texture(mesh) if asset.uvs is not None else None
        first, height, width = 0, 0, 0
        if texture is not None:
            first = self._geometry.texture_first[texture.content_hash]
            height, width = texture.pixels.shape[:2]
        offset = self._geometry.normal_offset.get((asset.content_hash, mesh.crease_deg), 0) if mesh.smooth else 0
        table["texture"][row] = (first, width, height, offset)


def _merge(updates: list[TableUpdate]) -> list[TableUpdate]:
    """One update per table: whole-table updates absorb row updates; adjacent rows coalesce."""
    by_table: dict[str, list[TableUpdate]] = {}
    for u in updates:
        by_table.setdefault(u.table, []).append(u)
    merged: list[TableUpdate] = []
    for table, items in by_table.items():
        if any(u.rows is None for u in items):
            merged.append(TableUpdate(table))
            continue
        spans = sorted((u.rows.start, u.rows.stop) for u in items if u.rows is not None)
        start, stop = spans[0]
        for s, e in spans[1:]:
            if s <= stop:
                stop = max(stop, e)
            else:
                merged.append(TableUpdate(table, range(start, stop)))
                start, stop = s, e
        merged.append(TableUpdate(table, range(start, stop)))
    return merged
