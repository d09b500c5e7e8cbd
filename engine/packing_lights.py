"""Packing the Light entities into the ``lights`` table (layout in :data:`engine.layout.LIGHT`)."""

from __future__ import annotations

import numpy as np

from components import Light, Transform
from engine import layout
from engine.maths import normalize, rotate
from engine.records import Precision
from engine.scene import Scene


def light_entities(scene: Scene) -> list[int]:
    """The entities the ``lights`` table holds, one row each, in creation order."""
    return [entity for entity, _ in scene.query(Light, Transform)]


def pack_lights(scene: Scene, origin: np.ndarray, precision: Precision) -> tuple[np.ndarray, int]:
    """The ``lights`` table (at least one row) and its live row count; point positions camera-relative."""
    rows = scene.query(Light, Transform)
    table = np.zeros(max(1, len(rows)), dtype=layout.light_dtype(precision))
    for row, (entity, (light, transform)) in enumerate(rows):
        if light.kind == "sun":  # shines along its local -Z: the direction towards it is +Z
            table["vector"][row, :3] = normalize(rotate(transform.rotation, (0.0, 0.0, 1.0)))
        else:
            table["vector"][row, :3] = np.asarray(transform.position, np.float64) - origin
        table["color"][row, :3] = np.asarray(light.color, np.float64) * light.intensity
        table["color"][row, 3] = light.range or 0.0
        table["meta"][row] = (layout.LIGHT_KINDS[light.kind], int(light.shadows), entity, 0)
    return table, len(rows)


def shadowing(scene: Scene) -> bool:
    """Whether any light casts shadows (the kernels' HAS_SHADOWS)."""
    return any(light.shadows for _, light in scene.query(Light))
