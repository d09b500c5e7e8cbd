"""The one place that orders the systems of a tick (docs/design.md section 6).

esper runs processors with a higher priority first, so the values fall in
tick order. Every processor is registered with one of these names; no other
module uses a bare number.
"""

from __future__ import annotations

from enum import IntEnum


class Priority(IntEnum):
    """Per-tick order: move the camera, teleport it, upload what changed, render."""

    CAMERA_MOVEMENT = 400
    PORTAL_TELEPORT = 300
    GPU_UPLOAD = 200
    RENDER = 100


#: The priorities in the order the systems run each tick.
TICK_ORDER: tuple[Priority, ...] = tuple(sorted(Priority, reverse=True))
