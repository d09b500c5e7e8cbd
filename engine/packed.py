"""What the packer hands a backend: the packed tables, and which rows of them changed.

Kept apart from :mod:`engine.packing` (how tables are filled) so backends and the
app depend only on these records, never on the packer.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.records import Precision

__all__ = ["Features", "PackedScene", "TableUpdate"]


@dataclass(frozen=True)
class Features:
    """What the scene contains: picks the kernel variant (compile-time defines)."""

    portals: bool = False
    aberration_modes: frozenset[str] = frozenset()
    max_events: int = 16
    #: Light entities exist (else the implicit sun along the settings' light_dir).
    lights: bool = False
    #: A light casts shadows: shadow rays travel the journey.
    shadows: bool = False
    #: Some instance samples a texture / shades with vertex normals: without, their code compiles out.
    textures: bool = False
    smooth: bool = False
    #: Some material has a checker (cell > 0): without, the checker's code compiles out.
    checker: bool = False

    def defines(self) -> dict[str, int]:
        return {
            "HAS_LIGHTS": int(self.lights),
            "HAS_SHADOWS": int(self.shadows),
            "HAS_PORTALS": int(self.portals),
            "HAS_ABERRATIONS": int(bool(self.aberration_modes)),
            "HAS_METRIC": int("metric" in self.aberration_modes),
            "HAS_RADIAL": int("radial" in self.aberration_modes),
            "HAS_ADDITIVE": int("additive" in self.aberration_modes),
            "MAX_EVENTS": self.max_events,
            "HAS_TEXTURES": int(self.textures),
            "HAS_SMOOTH": int(self.smooth),
            "HAS_CHECKER": int(self.checker),
        }


@dataclass(frozen=True)
class TableUpdate:
    """Rows of a table to upload; ``rows is None`` means the whole table (reallocate)."""

    table: str
    rows: range | None = None


@dataclass
class PackedScene:
    """The tables, their live row counts (tables never have zero rows), origin and features."""

    precision: Precision
    origin: np.ndarray
    tables: dict[str, np.ndarray]
    counts: dict[str, int]
    features: Features
    #: Entity id of each instance row (to map the ``instance`` AOV back, and for tests).
    instance_entities: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    #: Per-table version, bumped on every update of the table.
    versions: dict[str, int] = field(default_factory=dict)

    def update_bytes(self, updates: list[TableUpdate]) -> int:
        """Bytes an upload of ``updates`` transfers."""
        total = 0
        for u in updates:
            table = self.tables[u.table]
            total += table.nbytes if u.rows is None else len(u.rows) * table.dtype.itemsize
        return total
