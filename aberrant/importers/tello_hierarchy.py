"""TelloEngine game objects and their hierarchy: the document's flat list of objects read and checked, each
object's local ``T R S`` composed with its parents' into a world pose (exact under uniform scales), every
error naming the file, the object and the field.

:mod:`aberrant.importers.tello` maps the objects and poses onto our scene.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from aberrant.importers.tello_format import COMPONENT_NAMES, TRANSFORM, TelloError
from components import Transform, ValidationError
from components.validation import real, vector
from engine.maths import quat_from_matrix, quat_multiply, quat_normalize, quat_to_matrix, trs_matrix


@dataclass
class Pose:
    """A world pose ``T(p) R(q) S(s)``, kept as its parts so that plain hierarchies stay exact."""

    p: np.ndarray
    q: np.ndarray
    s: np.ndarray

    @property
    def matrix(self) -> np.ndarray:
        return trs_matrix(self.p, self.q, self.s)

    def transform(self, offset: np.ndarray | None = None) -> Transform:
        """Our Transform of this pose, its origin moved to the local point ``offset``."""
        position = self.p if offset is None else self.p + quat_to_matrix(self.q) @ (self.s * offset)
        q = self.q if self.q[3] >= 0.0 else -self.q

        def clean(values: np.ndarray) -> tuple[float, ...]:
            return tuple(float(c) + 0.0 for c in values)  # + 0.0 turns -0.0 into 0.0

        return Transform(clean(position), clean(q), clean(self.s))


@dataclass
class GameObject:
    """One game object as read: its components as ``(index in its list, type, fields)``."""

    uuid: int
    parent: int
    name: str
    components: list[tuple[int, int, dict[str, Any]]]

    @property
    def label(self) -> str:
        return f"game object {self.uuid} {self.name!r}"

    def first(self, kind: int) -> tuple[int, dict[str, Any]] | None:
        for i, t, c in self.components:
            if t == kind:
                return i, c
        return None


class TelloHierarchy:
    """The game objects of one document and their world poses, read once; errors name ``file``."""

    def __init__(self, file: str) -> None:
        self.file = file
        self.objects: dict[int, GameObject] = {}
        self.world: dict[int, Pose] = {}
        self.warnings: list[str] = []

    def fail(self, message: str, obj: GameObject | None = None, field: str | None = None) -> TelloError:
        return TelloError(self.file, message, entity=obj.label if obj else None, field=field, kind=None)

    # --- parsing -------------------------------------------------------------------

    def parse(self, doc: dict[str, Any]) -> list[GameObject]:
        order: list[GameObject] = []
        for index, item in enumerate(doc["game_objects"]):
            where = f"game_objects[{index}]"
            if not isinstance(item, dict):
                raise self.fail("expected an object", field=where)
            uuid = self.uuid_field(item.get("uuid"), f"{where}.uuid")
            parent = self.uuid_field(item.get("parent", 0), f"{where}.parent")
            name = item.get("name")
            name = name.strip() if isinstance(name, str) and name.strip() else f"object_{uuid}"
            obj = GameObject(uuid, parent, name, [])
            if uuid in self.objects:
                raise self.fail(f"uuid {uuid} is used twice (also by {self.objects[uuid].label})", obj, "uuid")
            comps = item.get("components", [])
            if not isinstance(comps, list):
                raise self.fail("expected a list", obj, "components")
            for i, comp in enumerate(comps):
                kind = comp.get("type") if isinstance(comp, dict) else None
                if isinstance(kind, bool) or not isinstance(kind, int) or not 0 <= kind < len(COMPONENT_NAMES):
                    raise self.fail(
                        f"unknown component type {kind!r} (known: 0-7, {', '.join(COMPONENT_NAMES)})",
                        obj,
                        f"components[{i}].type",
                    )
                obj.components.append((i, kind, comp))
            self.objects[uuid] = obj
            order.append(obj)
        return order

    def uuid_field(self, value: object, field: str) -> int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(f"expected an integer uuid, got {value!r}", field=field)
        return value

    def number(
        self, obj: GameObject, comp: tuple[int, dict[str, Any]], key: str, default: float | None = None
    ) -> float:
        i, fields = comp
        if key not in fields and default is not None:
            return default
        try:
            return real(fields.get(key), key)
        except ValidationError as e:
            raise self.fail(e.message, obj, f"components[{i}].{key}") from None

    def local_pose(self, obj: GameObject) -> Pose:
        comp = obj.first(TRANSFORM)
        if comp is None:
            return Pose(np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]), np.ones(3))
        i, fields = comp
        try:
            position = vector(fields.get("position", [0, 0, 0]), 3, "position")
            rotation = vector(fields.get("rotation", [0, 0, 0, 1]), 4, "rotation")
            scale = vector(fields.get("scale", [1, 1, 1]), 3, "scale")
            with np.errstate(all="ignore"):  # a length that overflows is reported below
                q = quat_normalize(rotation)
        except ValidationError as e:
            raise self.fail(e.message, obj, f"components[{i}].{e.field}") from None
        except ValueError:
            raise self.fail("the rotation quaternion is zero", obj, f"components[{i}].rotation") from None
        if not np.all(np.isfinite(q)) or abs(float(np.linalg.norm(q)) - 1.0) > 1e-6:  # its length overflowed
            raise self.fail("the rotation quaternion cannot be normalised", obj, f"components[{i}].rotation")
        if min(abs(c) for c in scale) < 1e-12:
            raise self.fail("a scale component is zero (the object collapses)", obj, f"components[{i}].scale")
        return Pose(np.array(position), q, np.array(scale))

    def world_pose(self, obj: GameObject, seen: tuple[int, ...] = ()) -> Pose:
        """The object's world pose, ``M_parent_world · M_local``, memoised."""
        if obj.uuid in self.world:
            return self.world[obj.uuid]
        if obj.uuid in seen:
            raise self.fail("the parent chain loops back to this object", obj, "parent")
        pose = self.local_pose(obj)
        if obj.parent != 0:
            parent = self.objects.get(obj.parent)
            if parent is None:
                raise self.fail(f"no game object has uuid {obj.parent}", obj, "parent")
            pose = self.compose(obj, self.world_pose(parent, (*seen, obj.uuid)), pose)
            if not all(np.all(np.isfinite(a)) for a in (pose.p, pose.q, pose.s)) or np.min(np.abs(pose.s)) < 1e-12:
                raise self.fail(
                    "its world transform overflows or collapses (the hierarchy's positions or scales are too large "
                    "or too small)",
                    obj,
                    "parent",
                )
        self.world[obj.uuid] = pose
        return pose

    def compose(self, obj: GameObject, parent: Pose, child: Pose) -> Pose:
        """``parent · child``: exact on (p, q, s) under a uniform parent scale, else via the matrix."""
        with np.errstate(all="ignore"):  # huge or tiny values: the caller rejects a non-finite result
            return self._compose(obj, parent, child)

    def _compose(self, obj: GameObject, parent: Pose, child: Pose) -> Pose:
        """:meth:`compose` without the errstate; a NaN pose when the product overflows (SVD would not converge)."""
        nan = Pose(np.full(3, np.nan), np.full(4, np.nan), np.full(3, np.nan))
        if not np.all(np.isfinite(parent.s * child.s)) or not np.all(np.isfinite(parent.s * child.p)):
            return nan
        if np.ptp(parent.s) <= 1e-12 * float(np.max(np.abs(parent.s))):
            position = parent.p + quat_to_matrix(parent.q) @ (parent.s * child.p)
            return Pose(position, quat_normalize(quat_multiply(parent.q, child.q)), parent.s * child.s)
        m = parent.matrix @ child.matrix
        if not np.all(np.isfinite(m)):
            return nan
        linear = m[:3, :3]
        scale = np.linalg.norm(linear, axis=0)
        if not np.all(np.isfinite(scale)) or np.min(scale) < 1e-300:
            return nan
        if np.linalg.det(linear) < 0.0:
            scale[0] = -scale[0]
        rotation = linear / scale
        if np.max(np.abs(rotation.T @ rotation - np.eye(3))) > 1e-6:
            self.warnings.append(f"{obj.label}: its parents' non-uniform scale shears it; kept the nearest rotation")
            u, _, vt = np.linalg.svd(rotation)
            rotation = u @ vt
        return Pose(m[:3, 3].copy(), quat_from_matrix(rotation), scale)
