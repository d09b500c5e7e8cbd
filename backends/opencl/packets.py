"""Which OpenCL frames trace their camera rays eight at a time (``PACKET_PRIMARY``, ``packet.cl``), and their
work size.

A packet frame is a float Euclidean one without shadows over 8-wide trees of triangle blocks, on a device
without the double edge-function fallback, whose every mesh search is a camera ray's first leg with its view
tile's instance list (``INSTANCE_TILES_ONLY``) or a search of a scene of one instance (``USE_TLAS`` 0): there
a 4x2 block of neighbouring rays shares nearly every node and leaf it visits, and a node load serves all eight.
"""

from __future__ import annotations

import math

#: Pixels per work-item of a packet frame (``PACKET_W`` x ``PACKET_H`` in ``packet.cl``).
PACKET: tuple[int, int] = (4, 2)


def packet_frame(defines: dict[str, int], wanted: int = 1) -> bool:
    """Whether a frame of these kernel defines qualifies (``wanted`` 0: never, for A/B)."""
    return bool(
        wanted
        and defines.get("REAL_IS_DOUBLE") == 0
        and defines.get("BVH_WIDTH") == 8
        and (
            (defines.get("INSTANCE_TILES_ONLY") == 1 and defines.get("VIEW_TILE_LOG2", 0) >= 2)
            or (not defines.get("INSTANCE_TILES") and defines.get("USE_TLAS") == 0)
        )
        and not defines.get("HAS_PORTALS")
        and not defines.get("HAS_ABERRATIONS")
        and not defines.get("HAS_SHADOWS")
        and not defines.get("EDGE_FALLBACK_FP64")
        and not defines.get("BRUTE_FORCE")
    )


def work_size(width: int, height: int, packets: bool) -> tuple[int, int]:
    """Work-items of a frame: one a pixel, or one a packet's block."""
    if not packets:
        return (width, height)
    return (math.ceil(width / PACKET[0]), math.ceil(height / PACKET[1]))
