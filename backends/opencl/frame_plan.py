"""What an OpenCL frame launches: one kernel over the image, or, for a frame with portals whose tiles without doors
can take the Euclidean variant's packets, two over the tile order (tile_order.py)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np

from backends import shared
from backends.opencl.tile_order import TileLaunch, tile_order
from backends.shared.frame_tiles import portal_free_tiles
from engine.camera_view import CameraView
from engine.packed import Features

#: A frame's launches: each kernel's defines and its part of the tile order (None: the image's grid).
Launches = list[tuple[dict[str, int], TileLaunch | None]]
#: The backend's defines of a frame of these features and view tiles (OpenClBackend._frame_defines).
DefinesOf = Callable[[Features, shared.FrameTiles | None], dict[str, int]]


def frame_launches(
    scene: shared.UploadedScene,
    defines_of: DefinesOf,
    local_size: tuple[int, int] | None,
    camera: CameraView,
    features: Features,
    tiles: shared.FrameTiles | None,
    width: int,
    height: int,
) -> tuple[Launches, np.ndarray | None]:
    """The frame's launches and the tile order they read (None for one launch): a frame with portals whose
    Euclidean variant takes packets traces the tiles that meet no portal with it; ``TILE_ORDER=0`` in the extra
    defines keeps one launch."""
    defines = defines_of(features, tiles)
    wanted = scene.extra_defines.get("TILE_ORDER", 1)
    free = portal_free_tiles(scene, camera, tiles, features, width, height) if wanted else None
    if free is None or tiles is None:
        return [(defines, None)], None
    euclidean = replace(tiles, portals=False, instances_only=True)
    plain = defines_of(replace(features, portals=False), euclidean)
    if not plain["PACKET_PRIMARY"]:
        return [(defines, None)], None
    local = None if local_size is None else local_size[0] * local_size[1]
    order, launches = tile_order([(np.flatnonzero(free), True), (np.flatnonzero(~free), False)], local)
    plain["TILE_ORDER"] = defines["TILE_ORDER"] = 1
    return [(plain, launches[0]), (defines, launches[1])], order
