"""The scene: the store of :mod:`engine.scene_world` with a builder API for levels as code and the
whole-scene checks the components cannot make alone."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, TypeVar

import numpy as np

from components import MAX_LIGHTS, Aberration, Camera, Light, Mesh, Portal, Transform, ValidationError
from components.validation import MAX_MAGNITUDE
from engine.assets import PRIMITIVES
from engine.errors import AberrantError, SceneError
from engine.maths import look_at_quat, quat_from_euler_deg
from engine.scene_world import SceneWorld

C = TypeVar("C")


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


class Scene(SceneWorld):
    """A level: its world, built by the calls below (or read from a scene file) and checked as a whole."""

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
