"""Undoable edits: small reversible operations grouped into commands.

Operations name entities by *name*, never by esper id: undoing a delete
recreates the entity under a new id, but because the undo history is
linear, the scene is in exactly the state an operation saw whenever it is
applied or reverted, so the names it recorded are valid then. Entities are
re-inserted at their old place in creation order, so a saved file after an
undo is byte for byte the file before the edit.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from typing import Protocol

from components import Name, Portal
from engine.scene import Scene
from engine.scene_world import AssetSpec
from engine.settings import Settings


class Op(Protocol):
    """One reversible change of a scene."""

    def apply(self, scene: Scene) -> None: ...

    def revert(self, scene: Scene) -> None: ...


@dataclass(frozen=True)
class EntityRecord:
    """Everything needed to recreate an entity: its name, its other components, whether it is the camera."""

    name: str
    components: tuple[object, ...]
    camera: bool = False


def capture(scene: Scene, entity: int) -> EntityRecord:
    """The record of a live entity."""
    parts = tuple(c for c in scene.components(entity) if not isinstance(c, Name))
    return EntityRecord(scene.name_of(entity), parts, entity == scene.camera_entity)


def _create(scene: Scene, record: EntityRecord) -> int:
    entity = scene.create_entity(record.name, *record.components)
    if record.camera:
        scene.camera_entity = entity
    return entity


def insert_entity(scene: Scene, record: EntityRecord, index: int) -> int:
    """Create ``record`` at position ``index`` of the creation order (recreating the entities after it)."""
    later_ids = scene.entities()[index:]
    later = [capture(scene, e) for e in later_ids]
    for entity in later_ids:
        scene.delete(entity)
    created = _create(scene, record)
    for other in later:
        _create(scene, other)
    return created


def _put(scene: Scene, name: str, kind: type, value: object | None) -> None:
    entity = scene.entity(name)
    if value is None:
        if scene.has(entity, kind):
            scene.remove(entity, kind)
    else:
        scene.set(entity, value)


@dataclass(frozen=True)
class SetOp:
    """Replace (or add, or remove: ``None``) one component of a named entity."""

    name: str
    kind: type
    before: object | None
    after: object | None

    def apply(self, scene: Scene) -> None:
        _put(scene, self.name, self.kind, self.after)

    def revert(self, scene: Scene) -> None:
        _put(scene, self.name, self.kind, self.before)


@dataclass(frozen=True)
class RenameOp:
    """Rename an entity; the scene retargets portals that named it, and revert restores them exactly."""

    old: str
    new: str
    portals_before: tuple[tuple[str, Portal], ...] = ()

    def apply(self, scene: Scene) -> None:
        scene.rename(scene.entity(self.old), self.new)

    def revert(self, scene: Scene) -> None:
        scene.rename(scene.entity(self.new), self.old)
        for name, portal in self.portals_before:
            scene.set(scene.entity(name), portal)


@dataclass(frozen=True)
class CreateOp:
    """Create an entity at a place in the creation order."""

    record: EntityRecord
    index: int

    def apply(self, scene: Scene) -> None:
        insert_entity(scene, self.record, self.index)

    def revert(self, scene: Scene) -> None:
        scene.delete(scene.entity(self.record.name))


@dataclass(frozen=True)
class DeleteOp:
    """Delete an entity; revert puts it back where it was."""

    record: EntityRecord
    index: int

    def apply(self, scene: Scene) -> None:
        scene.delete(scene.entity(self.record.name))

    def revert(self, scene: Scene) -> None:
        insert_entity(scene, self.record, self.index)


@dataclass(frozen=True)
class AssetOp:
    """Register (or unregister: ``None``) a named mesh asset."""

    name: str
    before: AssetSpec | None
    after: AssetSpec | None

    @staticmethod
    def _put(scene: Scene, name: str, spec: AssetSpec | None) -> None:
        if spec is None:
            scene.assets.pop(name, None)  # nothing in the packed tables refers to an unused asset
        else:
            scene.add_asset(name, primitive=spec.primitive, path=spec.path)

    def apply(self, scene: Scene) -> None:
        self._put(scene, self.name, self.after)

    def revert(self, scene: Scene) -> None:
        self._put(scene, self.name, self.before)


@dataclass(frozen=True)
class SettingsOp:
    """Replace the scene-wide settings."""

    before: Settings
    after: Settings

    def apply(self, scene: Scene) -> None:
        scene.settings = self.after

    def revert(self, scene: Scene) -> None:
        scene.settings = self.before


@dataclass(frozen=True)
class SceneNameOp:
    """Rename the scene itself."""

    before: str
    after: str

    def apply(self, scene: Scene) -> None:
        scene.name = self.after

    def revert(self, scene: Scene) -> None:
        scene.name = self.before


_command_ids = itertools.count(1)


@dataclass
class Command:
    """What one user action did: undone and redone as a whole.

    ``merge_key`` lets a continuous edit (a gizmo drag, a dragged number)
    fold its many small steps into this one command while it stays open.
    """

    label: str
    ops: list[Op]
    merge_key: object | None = None
    id: int = field(default_factory=lambda: next(_command_ids))
    version: int = 0

    def apply(self, scene: Scene) -> None:
        done: list[Op] = []
        try:
            for op in self.ops:
                op.apply(scene)
                done.append(op)
        except BaseException:
            for op in reversed(done):
                op.revert(scene)
            raise

    def revert(self, scene: Scene) -> None:
        for op in reversed(self.ops):
            op.revert(scene)
