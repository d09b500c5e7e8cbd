"""The scene's store: an esper world, its change journal, assets and settings.

esper 3 keeps worlds in module state; each scene owns a uniquely named world
and switches to it before touching components, so several scenes (an edited
one and a play-mode copy, a test's fixtures) live side by side.

Components are frozen: every edit goes through :meth:`SceneWorld.set`, which
appends to a change journal. Consumers (the GPU packer, the editor) keep a
cursor into the journal and re-pack only what changed. The builder API for
levels as code and the whole-scene checks stand on this in :mod:`engine.scene`.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import esper

from components import Mesh, Name, Portal, ValidationError
from engine.assets import PRIMITIVES, AssetLibrary
from engine.errors import SceneError
from engine.keyframes import Keyframe
from engine.mesh_asset import MeshAsset
from engine.settings import Settings
from engine.textures import TextureImage

C = TypeVar("C")

_world_ids = itertools.count()

STRUCTURE = "structure"
SETTINGS = "settings"
ASSETS = "assets"


@dataclass(frozen=True)
class AssetSpec:
    """Where an asset comes from: a built-in primitive or a file (relative to the scene file)."""

    primitive: str | None = None
    path: str | None = None

    def __post_init__(self) -> None:
        if (self.primitive is None) == (self.path is None):
            raise ValidationError("asset", "give exactly one of 'primitive' or 'path'")
        if self.primitive is not None and self.primitive not in PRIMITIVES:
            raise ValidationError("primitive", f"unknown primitive {self.primitive!r}; one of {', '.join(PRIMITIVES)}")


@dataclass(frozen=True)
class Change:
    """One journal entry: ``entity`` (-1 for scene-wide) and what changed."""

    entity: int
    kind: str


def _kind(component: object) -> str:
    return type(component).__name__.lower()


class SceneWorld:
    """An esper world plus the journal, assets and settings a level keeps beside it."""

    def __init__(
        self,
        name: str = "untitled",
        settings: Settings | None = None,
        base_dir: Path | None = None,
        library: AssetLibrary | None = None,
    ) -> None:
        self.name = name
        self.base_dir = base_dir
        self.library = library or AssetLibrary()
        self.assets: dict[str, AssetSpec] = {}
        self.camera_entity: int | None = None
        #: The level's own flythrough (a scene file's ``camera_path``); empty when it has none.
        self.camera_path: tuple[Keyframe, ...] = ()
        #: Entity -> the Euler angles (degrees) its rotation was given as, so a saved file keeps angles as angles.
        self.euler_deg: dict[int, tuple[float, float, float]] = {}
        self.world = f"aberrant-scene-{next(_world_ids)}"
        self._settings = settings or Settings()
        self._names: dict[str, int] = {}
        self._journal: list[Change] = []
        self._journal_base = 0
        self.activate()

    # --- world management ---------------------------------------------------

    def activate(self) -> None:
        """Make this scene's world the one esper (and its processors) act on."""
        if esper.current_world != self.world:
            esper.switch_world(self.world)

    def close(self) -> None:
        """Delete the esper world (a scene is unusable afterwards)."""
        if self.world in esper.list_worlds():
            if esper.current_world == self.world:
                esper.switch_world("default")
            esper.delete_world(self.world)

    # --- change journal -------------------------------------------------------

    @property
    def cursor(self) -> int:
        """The journal position after the latest change."""
        return self._journal_base + len(self._journal)

    def changes_since(self, cursor: int) -> list[Change] | None:
        """Changes after ``cursor``; ``None`` when they were compacted away (consumer must resync fully)."""
        if cursor < self._journal_base:
            return None
        return self._journal[cursor - self._journal_base :]

    def compact_journal(self, keep: int = 4096) -> None:
        """Drop old entries; consumers behind the new base resync fully."""
        if len(self._journal) > keep:
            drop = len(self._journal) - keep
            del self._journal[:drop]
            self._journal_base += drop

    def _record(self, entity: int, kind: str) -> None:
        self._journal.append(Change(entity, kind))
        if len(self._journal) > 65536:
            self.compact_journal()

    # --- settings and assets ------------------------------------------------

    @property
    def settings(self) -> Settings:
        return self._settings

    @settings.setter
    def settings(self, value: Settings) -> None:
        if value != self._settings:
            self._settings = value
            self._record(-1, SETTINGS)

    def add_asset(self, name: str, *, primitive: str | None = None, path: str | Path | None = None) -> str:
        """Register an asset name; mesh entities refer to assets by name."""
        try:
            spec = AssetSpec(primitive, None if path is None else str(path))
        except ValidationError as e:
            raise SceneError(e.message, entity=f"assets.{name}", field=e.field) from None
        if self.assets.get(name) != spec:
            self.assets[name] = spec
            self._record(-1, ASSETS)
        return name

    def asset_path(self, spec: AssetSpec) -> Path:
        assert spec.path is not None
        p = Path(spec.path).expanduser()
        return p if p.is_absolute() or self.base_dir is None else self.base_dir / p

    def asset(self, name: str) -> MeshAsset:
        """The geometry of a named asset (a primitive name works without registering it)."""
        spec = self.assets.get(name)
        if spec is None:
            if name in PRIMITIVES:
                return self.library.primitive(name)
            known = ", ".join(sorted(self.assets)) or "none registered"
            raise SceneError(f"unknown asset {name!r} (assets: {known}; primitives: {', '.join(PRIMITIVES)})")
        if spec.primitive is not None:
            return self.library.primitive(spec.primitive)
        return self.library.load(self.asset_path(spec))

    def texture(self, mesh: Mesh) -> TextureImage | None:
        """The image a mesh samples: its ``texture`` file (resolved like mesh assets), else its asset's own.

        None when it has neither, or when its file cannot be read (one warning line names the file).
        """
        if not mesh.texture:
            return self.asset(mesh.asset).image
        return self.library.textures.load(self.texture_path(mesh.texture))

    def texture_path(self, texture: str) -> Path:
        """A mesh's ``texture`` file, resolved like mesh assets (relative to the scene file's folder)."""
        p = Path(texture).expanduser()
        return p if p.is_absolute() or self.base_dir is None else self.base_dir / p

    # --- entities -----------------------------------------------------------

    def create_entity(self, name: str, *components: object) -> int:
        """A new named entity; names are unique."""
        try:
            Name(name)
        except ValidationError as e:
            raise SceneError(e.message, entity=str(name), field="name") from None
        if name in self._names:
            raise SceneError("an entity with this name already exists; names must be unique", entity=name, field="name")
        self.activate()
        entity = esper.create_entity(Name(name), *components)
        self._names[name] = entity
        self._record(entity, STRUCTURE)
        return entity

    def set(self, entity: int, component: object) -> None:
        """Add or replace a component (the only way to edit: it records the change)."""
        self.activate()
        if isinstance(component, Name):
            self.rename(entity, component.value)
            return
        existed = esper.has_component(entity, type(component))
        if existed and esper.component_for_entity(entity, type(component)) == component:
            return
        esper.add_component(entity, component)
        self._record(entity, _kind(component) if existed else STRUCTURE)

    def remove(self, entity: int, component_type: type) -> None:
        self.activate()
        esper.remove_component(entity, component_type)
        self._record(entity, STRUCTURE)

    def delete(self, entity: int) -> None:
        self.activate()
        self._names.pop(self.name_of(entity), None)
        esper.delete_entity(entity, immediate=True)
        self.euler_deg.pop(entity, None)
        if self.camera_entity == entity:
            self.camera_entity = None
        self._record(entity, STRUCTURE)

    def rename(self, entity: int, new_name: str) -> None:
        """Rename an entity, retargeting portals that named it."""
        old = self.name_of(entity)
        if new_name == old:
            return
        if new_name in self._names:
            raise SceneError("an entity with this name already exists", entity=new_name, field="name")
        Name(new_name)
        self.activate()
        esper.add_component(entity, Name(new_name))
        del self._names[old]
        self._names[new_name] = entity
        self._record(entity, "name")
        for other, portal in self.query(Portal):
            if portal.target == old:
                self.set(other, Portal(new_name, portal.color, portal.debug_draw))

    def get(self, entity: int, component_type: type[C]) -> C:
        self.activate()
        try:
            return esper.component_for_entity(entity, component_type)
        except KeyError:
            raise SceneError(f"has no {component_type.__name__} component", entity=self._label(entity)) from None

    def try_get(self, entity: int, component_type: type[C]) -> C | None:
        self.activate()
        return esper.try_component(entity, component_type)

    def has(self, entity: int, component_type: type) -> bool:
        self.activate()
        return esper.has_component(entity, component_type)

    def entity(self, name: str) -> int:
        try:
            return self._names[name]
        except KeyError:
            raise SceneError("no entity has this name", entity=name) from None

    def name_of(self, entity: int) -> str:
        self.activate()
        return esper.component_for_entity(entity, Name).value

    def _label(self, entity: int) -> str:
        self.activate()
        name = esper.try_component(entity, Name)
        return name.value if name is not None else f"#{entity}"

    def entities(self) -> list[int]:
        """Every entity, in creation order."""
        return sorted(self._names.values())

    def query(self, *component_types: type) -> list[tuple[int, Any]]:
        """``[(entity, component)]`` for one type or ``[(entity, (c1, c2, ...))]`` for several, in creation order."""
        self.activate()
        if len(component_types) == 1:
            rows: Iterator[tuple[int, Any]] = iter(esper.get_component(component_types[0]))
        else:
            rows = iter(esper.get_components(*component_types))
        return sorted(rows, key=lambda row: row[0])

    def components(self, entity: int) -> tuple[object, ...]:
        self.activate()
        return esper.components_for_entity(entity)
