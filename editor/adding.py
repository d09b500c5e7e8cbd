"""The Add menu's operations: primitives, imported meshes, aberrations, portal pairs, lights, the camera,
duplicates.

Each one is a single undoable command that appends entities at the end of
the creation order (so undo removes them and the file is as before) and
selects what it made.
"""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING

from components import Aberration, Camera, Light, Mesh, Portal, Transform
from editor.commands import AssetOp, Command, CreateOp, EntityRecord, Op, SetOp, capture
from engine.errors import AberrantError
from engine.maths import quat_from_euler_deg
from engine.mesh_files import MESH_SUFFIXES
from engine.scene_world import AssetSpec

if TYPE_CHECKING:
    from engine.scene import Scene

Vec3 = tuple[float, float, float]

#: Colours handed to new aberrations and portal pairs in turn, so neighbours are told apart in the preview.
ABERRATION_COLORS: tuple[Vec3, ...] = ((1.0, 0.55, 0.1), (0.95, 0.3, 0.55), (0.65, 0.4, 1.0), (1.0, 0.85, 0.2))
PORTAL_COLORS: tuple[Vec3, ...] = ((0.2, 0.6, 1.0), (0.2, 0.9, 0.6), (0.9, 0.3, 0.9), (0.3, 0.95, 0.95))
#: New meshes are a neutral grey.
MESH_COLOR: Vec3 = (0.8, 0.8, 0.8)
#: How far apart the two ends of a new portal pair stand.
PORTAL_PAIR_GAP = 3.0


class AddingMixin:
    """Entity creation for :class:`editor.model.EditorModel`."""

    scene: Scene
    selected_name: str | None
    if TYPE_CHECKING:

        def execute(self, command: Command) -> bool: ...

        def error(self, text: str) -> None: ...

    # --- names ------------------------------------------------------------------------

    def unique_name(self, base: str) -> str:
        """``base``, or ``base_2``, ``base_3``... whichever is free (a trailing ``_N`` is replaced)."""
        names = {self.scene.name_of(e) for e in self.scene.entities()}
        if base not in names:
            return base
        stem = re.sub(r"_\d+$", "", base) or base
        n = 2
        while f"{stem}_{n}" in names:
            n += 1
        return f"{stem}_{n}"

    def _append(self, label: str, records: Sequence[EntityRecord], extra: Sequence[Op] = ()) -> int | None:
        """Create ``records`` at the end of the creation order as one command; the first one is selected."""
        start = len(self.scene.entities())
        ops: list[Op] = [*extra]
        ops += [CreateOp(record, start + i) for i, record in enumerate(records)]
        if not self.execute(Command(label, ops)):
            return None
        self.selected_name = records[0].name
        return self.scene.entity(records[0].name)

    def _count(self, kind: type) -> int:
        return len(self.scene.query(kind))

    # --- the Add menu -----------------------------------------------------------------

    def add_primitive(self, primitive: str, position: Sequence[float] = (0.0, 0.0, 0.0)) -> int | None:
        """A mesh entity of a built-in primitive (box, plane, quad, sphere, pyramid, cylinder)."""
        name = self.unique_name(primitive)
        transform = Transform(tuple(position))
        return self._append(f"add {name}", [EntityRecord(name, (transform, Mesh(primitive, MESH_COLOR)))])

    def add_mesh_file(self, path: str | Path, position: Sequence[float] = (0.0, 0.0, 0.0)) -> int | None:
        """A mesh entity of an imported file (OBJ, glTF, PLY, STL, OFF); a file that cannot be read is refused."""
        file = Path(path).expanduser().resolve()
        if file.suffix.lower() not in MESH_SUFFIXES:
            self.error(f"{file}: not a mesh file (expected one of {', '.join(MESH_SUFFIXES)})")
            return None
        try:
            self.scene.library.load(file)
        except (AberrantError, OSError) as e:
            self.error(f"cannot import {file}: {e}")
            return None
        spec = AssetSpec(path=str(file))
        asset = next((n for n, s in self.scene.assets.items() if s == spec), None)
        extra: list[Op] = []
        if asset is None:
            asset = self._unique_asset(re.sub(r"\W+", "_", file.stem) or "mesh")
            extra.append(AssetOp(asset, None, spec))
        name = self.unique_name(asset)
        record = EntityRecord(name, (Transform(tuple(position)), Mesh(asset, MESH_COLOR)))
        return self._append(f"import {file.name}", [record], extra)

    def _unique_asset(self, base: str) -> str:
        from engine.assets import PRIMITIVES

        name, n = base, 2
        while name in self.scene.assets or name in PRIMITIVES:
            name, n = f"{base}_{n}", n + 1
        return name

    def add_aberration(self, position: Sequence[float] = (0.0, 0.0, 0.0)) -> int | None:
        """A 2-unit box that compresses space along x (D = (1, 0, 0)): visible at once, easy to tune."""
        name = self.unique_name("aberration")
        color = ABERRATION_COLORS[self._count(Aberration) % len(ABERRATION_COLORS)]
        transform = Transform(tuple(position), scale=(2.0, 2.0, 2.0))
        aberration = Aberration((1.0, 0.0, 0.0), color=color)
        return self._append(f"add {name}", [EntityRecord(name, (transform, aberration))])

    def add_portal_pair(self, position: Sequence[float] = (0.0, 0.0, 0.0)) -> int | None:
        """Two portals side by side that lead into each other."""
        a = self.unique_name("portal_a")
        b = self.unique_name("portal_b")
        color = PORTAL_COLORS[(self._count(Portal) // 2) % len(PORTAL_COLORS)]
        x, y, z = (float(c) for c in position)
        half = PORTAL_PAIR_GAP / 2
        records = [
            EntityRecord(a, (Transform((x - half, y, z)), Portal(b, color))),
            EntityRecord(b, (Transform((x + half, y, z)), Portal(a, color))),
        ]
        return self._append(f"add portals {a} and {b}", records)

    def add_light(self, kind: str, position: Sequence[float] = (0.0, 0.0, 0.0)) -> int | None:
        """A shadowing sun shining down at 60 degrees, or a point light bright enough for a room (3 units up:
        intensity 9 lights the floor below it as a unit sun would)."""
        name = self.unique_name(kind if kind == "sun" else "lamp")
        x, y, z = (float(c) for c in position)
        if kind == "sun":
            transform = Transform((x, y, z), tuple(float(c) for c in quat_from_euler_deg((-60.0, 30.0, 0.0))))
            light = Light("sun")
        else:
            transform, light = Transform((x, y + 3.0, z)), Light("point", intensity=9.0)
        return self._append(f"add {name}", [EntityRecord(name, (transform, light))])

    def add_camera(self, transform: Transform) -> int | None:
        """Create the scene camera at ``transform``, or move the existing one there (a scene has one camera)."""
        camera = self.scene.camera_entity
        if camera is not None:
            name = self.scene.name_of(camera)
            before = self.scene.get(camera, Transform)
            if not self.execute(Command(f"move {name} to the view", [SetOp(name, Transform, before, transform)])):
                return None
            self.selected_name = name
            return camera
        name = self.unique_name("camera")
        return self._append(f"add {name}", [EntityRecord(name, (transform, Camera()), camera=True)])

    def duplicate(self, entity: int) -> int | None:
        """A copy of ``entity`` at the end of the list (the camera cannot be copied: a scene has one)."""
        if entity == self.scene.camera_entity or self.scene.has(entity, Camera):
            self.error("the camera cannot be duplicated: a scene has exactly one camera")
            return None
        record = capture(self.scene, entity)
        name = self.unique_name(record.name if re.search(r"_\d+$", record.name) else f"{record.name}_2")
        return self._append(f"duplicate {record.name}", [EntityRecord(name, record.components)])
