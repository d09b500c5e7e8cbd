"""The scene: an esper world, its assets and settings, and a builder API for levels as code.

esper 3 keeps worlds in module state; each Scene owns a uniquely named world
and switches to it before touching components, so several scenes (an edited
one and a play-mode copy, a test's fixtures) live side by side.

Components are frozen: every edit goes through :meth:`Scene.set`, which
appends to a change journal. Consumers (the GPU packer, the editor) keep a
cursor into the journal and re-pack only what changed.
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, TypeVar

import esper
import numpy as np

from components import MAX_LIGHTS, Aberration, Camera, Light, Mesh, Name, Portal, Transform, ValidationError
from components.validation import MAX_MAGNITUDE
from engine.assets import PRIMITIVES, AssetLibrary, MeshAsset
from engine.errors import AberrantError, SceneError
from engine.keyframes import Keyframe
from engine.maths import look_at_quat, quat_from_euler_deg
from engine.settings import Settings
from engine.textures import TextureImage

C = TypeVar("C")

_world_ids = itertools.count()

#: Journal kinds besides component type names.
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


def _looking(
    name: str,
    key: str,
    position: Sequence[float],
    look_at: Sequence[float] | None,
    rotation: Sequence[float] | None,
    euler_deg: Sequence[float] | None,
) -> Sequence[float] | None:
    """``rotation``, or the one that turns local -Z from ``position`` towards ``look_at`` (then the only one given)."""
    if look_at is None:
        return rotation
    if rotation is not None or euler_deg is not None:
        raise SceneError("give one of rotation, euler_deg or look_at", entity=name, field=f"{key}.look_at")
    try:
        return tuple(float(c) for c in look_at_quat(position, look_at))
    except ValueError:
        raise SceneError(f"look_at equals the {key}'s position", entity=name, field=f"{key}.look_at") from None


def make_transform(
    position: Sequence[float] = (0.0, 0.0, 0.0),
    rotation: Sequence[float] | None = None,
    euler_deg: Sequence[float] | None = None,
    scale: Sequence[float] | float = (1.0, 1.0, 1.0),
) -> Transform:
    """A Transform from the builder's keyword forms (rotation quaternion *or* Euler degrees; scalar scale)."""
    if rotation is not None and euler_deg is not None:
        raise ValidationError("rotation", "give either 'rotation' (quaternion) or 'euler_deg', not both")
    if euler_deg is not None:
        q = tuple(float(c) for c in quat_from_euler_deg(euler_deg))
    elif rotation is not None:
        q = tuple(rotation)
    else:
        q = (0.0, 0.0, 0.0, 1.0)
    if isinstance(scale, bool):  # an int to the type system, but no scale
        raise ValidationError("scale", f"expected a number or 3 numbers, got {scale!r}")
    if isinstance(scale, int | float):
        scale = (float(scale),) * 3
    return Transform(tuple(position), q, tuple(scale))


class Scene:
    """An esper world plus everything else a level needs."""

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

    # --- builder API ------------------------------------------------------------

    def _entity_with(self, name: str, transform_kwargs: dict[str, Any], component: object | None) -> int:
        try:
            transform = make_transform(**transform_kwargs)
        except ValidationError as e:
            raise SceneError(e.message, entity=name, field=f"transform.{e.field}") from None
        parts = [transform] if component is None else [transform, component]
        entity = self.create_entity(name, *parts)
        self._remember_angles(entity, transform_kwargs.get("euler_deg"))
        return entity

    def _remember_angles(self, entity: int, euler_deg: Sequence[float] | None) -> None:
        if euler_deg is not None:
            x, y, z = (float(a) for a in euler_deg)
            self.euler_deg[entity] = (x, y, z)

    @staticmethod
    def _component(name: str, key: str, factory: type[C], **fields: Any) -> C:
        try:
            return factory(**fields)
        except ValidationError as e:
            raise SceneError(e.message, entity=name, field=f"{key}.{e.field}") from None

    def add_mesh(
        self,
        name: str,
        asset: str,
        *,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        rotation: Sequence[float] | None = None,
        euler_deg: Sequence[float] | None = None,
        scale: Sequence[float] | float = 1.0,
        color: Sequence[float] = (0.8, 0.8, 0.8),
        checker: float = 0.0,
        cull_backfaces: bool = False,
        texture: str = "",
        smooth: bool = False,
        crease_deg: float = 30.0,
    ) -> int:
        """A mesh entity; ``asset`` is a registered asset name or a primitive name; ``texture`` an image file."""
        if asset not in self.assets and asset not in PRIMITIVES:
            raise SceneError(
                f"unknown asset {asset!r}; add_asset() it first or use a primitive", entity=name, field="mesh.asset"
            )
        mesh = self._component(
            name, "mesh", Mesh, asset=asset, color=tuple(color), checker=checker, cull_backfaces=cull_backfaces,
            texture=texture, smooth=smooth, crease_deg=crease_deg,
        )  # fmt: skip
        return self._entity_with(
            name, dict(position=position, rotation=rotation, euler_deg=euler_deg, scale=scale), mesh
        )

    def add_aberration(
        self,
        name: str,
        deformation: Sequence[float],
        *,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        rotation: Sequence[float] | None = None,
        euler_deg: Sequence[float] | None = None,
        scale: Sequence[float] | float = 1.0,
        mode: str = "metric",
        exit: str = "restore",
        priority: int = 0,
        debug_draw: bool = True,
        color: Sequence[float] = (1.0, 0.55, 0.1),
    ) -> int:
        """A box of deformed space; ``scale`` is the box's size."""
        aberration = self._component(
            name, "aberration", Aberration, deformation=tuple(deformation), mode=mode, exit=exit,
            priority=priority, debug_draw=debug_draw, color=tuple(color),
        )  # fmt: skip
        return self._entity_with(
            name, dict(position=position, rotation=rotation, euler_deg=euler_deg, scale=scale), aberration
        )

    def add_portal(
        self,
        name: str,
        *,
        target: str | None = None,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        rotation: Sequence[float] | None = None,
        euler_deg: Sequence[float] | None = None,
        scale: Sequence[float] | float = 1.0,
        color: Sequence[float] = (0.2, 0.6, 1.0),
        debug_draw: bool = True,
    ) -> int:
        """One portal quad ([-1, 1]^2 in local XY, scaled); ``target`` may name a portal added later."""
        portal = self._component(name, "portal", Portal, target=target, color=tuple(color), debug_draw=debug_draw)
        return self._entity_with(
            name, dict(position=position, rotation=rotation, euler_deg=euler_deg, scale=scale), portal
        )

    def add_portal_pair(
        self,
        name_a: str,
        name_b: str,
        *,
        a: dict[str, Any],
        b: dict[str, Any],
        color: Sequence[float] = (0.2, 0.6, 1.0),
        debug_draw: bool = True,
    ) -> tuple[int, int]:
        """Two portals that lead into each other; ``a`` and ``b`` hold position/rotation/euler_deg/scale."""
        ea = self.add_portal(name_a, target=name_b, color=color, debug_draw=debug_draw, **a)
        eb = self.add_portal(name_b, target=name_a, color=color, debug_draw=debug_draw, **b)
        return ea, eb

    def add_light(
        self,
        name: str,
        kind: str = "sun",
        *,
        position: Sequence[float] = (0.0, 0.0, 0.0),
        rotation: Sequence[float] | None = None,
        euler_deg: Sequence[float] | None = None,
        look_at: Sequence[float] | None = None,
        color: Sequence[float] = (1.0, 1.0, 1.0),
        intensity: float = 1.0,
        shadows: bool = True,
        range: float | None = None,
    ) -> int:
        """A sun (shining along its local -Z; ``look_at`` a world point it shines towards) or a point light."""
        rotation = _looking(name, "light", position, look_at, rotation, euler_deg)
        light = self._component(
            name, "light", Light, kind=kind, color=tuple(color), intensity=intensity, shadows=shadows, range=range
        )
        return self._entity_with(name, dict(position=position, rotation=rotation, euler_deg=euler_deg), light)

    def set_camera(
        self,
        position: Sequence[float],
        *,
        rotation: Sequence[float] | None = None,
        look_at: Sequence[float] | None = None,
        euler_deg: Sequence[float] | None = None,
        fov_deg: float = 60.0,
        speed: float = 3.0,
        name: str = "camera",
    ) -> int:
        """Create or move the active camera (``look_at`` is a world point)."""
        rotation = _looking(name, "camera", position, look_at, rotation, euler_deg)
        camera = self._component(name, "camera", Camera, fov_deg=fov_deg, speed=speed)
        try:
            transform = make_transform(position, rotation, euler_deg)
        except ValidationError as e:
            raise SceneError(e.message, entity=name, field=f"camera.{e.field}") from None
        if self.camera_entity is not None and self.camera_entity in self._names.values():
            self.set(self.camera_entity, transform)
            self.set(self.camera_entity, camera)
            if self.name_of(self.camera_entity) != name:
                self.rename(self.camera_entity, name)
        else:
            self.camera_entity = self.create_entity(name, transform, camera)
        self.euler_deg.pop(self.camera_entity, None)
        self._remember_angles(self.camera_entity, euler_deg)
        return self.camera_entity

    # --- whole-scene checks -------------------------------------------------

    def check_mesh_sizes(self) -> None:
        """Every mesh's world-space size (its scale times its vertices' reach) within MAX_MAGNITUDE: the
        product of two valid numbers can still overflow what the tracers hold."""
        reaches: dict[str, float] = {}
        for entity, (mesh, transform) in self.query(Mesh, Transform):
            if mesh.asset not in reaches:
                try:
                    vertices = self.asset(mesh.asset).vertices
                except AberrantError:  # an unreadable file: its loader reports it, naming the entity
                    continue
                reaches[mesh.asset] = float(np.max(np.abs(vertices))) if vertices.size else 0.0
            scale, reach = max(abs(s) for s in transform.scale), reaches[mesh.asset]
            if scale * reach <= MAX_MAGNITUDE:
                continue
            raise SceneError(
                f"the mesh's world-space size, scale x its farthest vertex ({scale:g} x {reach:g}), is beyond "
                f"{MAX_MAGNITUDE:g}: it overflows the tracers' float32 ranges; scale it down",
                entity=self.name_of(entity),
                field="transform.scale",
            )

    def check_lights(self) -> None:
        """At most MAX_LIGHTS lights (the kernels' fixed loop); the error names the first one past it."""
        lights = self.query(Light)
        if len(lights) > MAX_LIGHTS:
            raise SceneError(
                f"a scene holds at most {MAX_LIGHTS} lights, this one {len(lights)}; remove one",
                entity=self.name_of(lights[MAX_LIGHTS][0]),
                field="light",
            )

    def validate(self) -> None:
        """Cross-entity checks the components cannot make alone."""
        if self.camera_entity is None:
            raise SceneError("the scene has no camera; call set_camera() or add a 'camera' block", field="camera")
        for entity, portal in self.query(Portal):
            if portal.target is None:
                continue
            target = self._names.get(portal.target)
            if target is None:
                raise SceneError(
                    f"no entity is named {portal.target!r}", entity=self.name_of(entity), field="portal.target"
                )
            if not self.has(target, Portal):
                raise SceneError(
                    f"{portal.target!r} is not a portal (a portal's target must be another portal)",
                    entity=self.name_of(entity),
                    field="portal.target",
                )
        self.check_lights()
        for entity, mesh in self.query(Mesh):
            if mesh.asset not in self.assets and mesh.asset not in PRIMITIVES:
                raise SceneError(f"unknown asset {mesh.asset!r}", entity=self.name_of(entity), field="mesh.asset")
        self.check_mesh_sizes()
