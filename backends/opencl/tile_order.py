"""Frames with portals traced in two launches by view tile (``TILE_ORDER``): the tiles whose camera rays meet
no portal (:func:`backends.shared.frame_tiles.portal_free_tiles`) with the frame's Euclidean variant, eight
rays a work-item where it takes packets, and the others with the frame's own variant, one ray a work-item.

Most of a level seen through its doors is walls: 68-92 % of the hotel's tiles at 800x800 list no portal, and
their pixels then cost what the doors-shut frame's do. Both launches read one list of tile indices, each part
padded with -1 to whole work-groups; the second starts at its part through the launch's global offset.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from backends.opencl.packets import PACKET
from engine.view_tiles import TILE_LOG2

#: Pixels in a view tile.
TILE_PIXELS = 1 << (2 * TILE_LOG2)


@dataclass(frozen=True)
class TileLaunch:
    """One launch over a part of the tile order: its first row, its rows (padding included), work-items per tile
    and tiles per work-group (None: the driver's choice)."""

    offset: int
    rows: int
    items: int
    group: int | None

    @property
    def global_size(self) -> tuple[int, int]:
        return (self.items, self.rows)

    @property
    def local_size(self) -> tuple[int, int] | None:
        return None if self.group is None else (self.items, self.group)

    @property
    def global_offset(self) -> tuple[int, int]:
        return (0, self.offset)


def items_per_tile(packets: bool) -> int:
    """Work-items a tile takes: one a pixel, or one a packet's block."""
    return TILE_PIXELS // (PACKET[0] * PACKET[1]) if packets else TILE_PIXELS


def tile_order(parts: list[tuple[np.ndarray, bool]], local_items: int | None) -> tuple[np.ndarray, list[TileLaunch]]:
    """The order buffer and a launch per part (tile indices, whether in packets), each part padded to whole
    work-groups of about ``local_items`` work-items (None: no padding, the driver's groups)."""
    chunks: list[np.ndarray] = []
    launches: list[TileLaunch] = []
    offset = 0
    for rows, packets in parts:
        items = items_per_tile(packets)
        group = None if local_items is None else max(1, local_items // items)
        padded = len(rows) if group is None else -(-len(rows) // group) * group
        chunk = np.full(padded, -1, np.int32)
        chunk[: len(rows)] = rows
        chunks.append(chunk)
        launches.append(TileLaunch(offset, padded, items, group))
        offset += padded
    return np.concatenate(chunks) if chunks else np.zeros(1, np.int32), launches
