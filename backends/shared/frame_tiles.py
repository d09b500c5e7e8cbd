"""The per-frame view tiles' rule (engine/view_tiles.py, engine/portal_legs.py): which sections of the table a
frame of an uploaded scene builds and which defines its kernel reads them with."""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from engine.camera_view import CameraView
from engine.packed import Features
from engine.portal_legs import portal_legs, quad_corners
from engine.view_tiles import TILE_LOG2, quad_tiles, view_tiles

if TYPE_CHECKING:
    from backends.shared import UploadedScene

#: Frames with fewer instances keep the instance tree for every search (a list gains nothing over a short walk).
INSTANCE_TILE_MIN = 4
#: ... and beside the portal tree, fewer than this keep it too (its walk is short; the lists' second copy of the
#: instance code is not).
INSTANCE_TILE_MIN_BESIDE = 64
#: A tile listing more instances than this leaves its rays to the tree (a ray slabs every listed box it passes
#: before its hit, a walk only the nodes it enters).
INSTANCE_TILE_MAX = 16


@dataclass(frozen=True)
class FrameTiles:
    """A frame's view tiles: the table and which of its sections the kernels read (an empty one is not)."""

    table: np.ndarray
    portals: bool
    instances: bool
    #: Whether the instances' lists serve every mesh search of the frame (INSTANCE_TILES_ONLY).
    instances_only: bool = False
    #: Whether the table holds the portal legs' lists (PORTAL_LEGS) ...
    portal_legs: bool = False
    #: ... and whether they prove that no later leg meets a portal (PORTAL_LEGS_FREE).
    portal_legs_free: bool = False


def view_tile_defines(tiles: FrameTiles | None) -> dict[str, int]:
    """The defines of a frame's view tiles, after the backend's extra defines (which ask for the tiles: the
    frame decides whether its kernel reads them)."""
    if tiles is None:
        return {"VIEW_TILES": 0, "INSTANCE_TILES": 0, "INSTANCE_TILES_ONLY": 0, "PORTAL_LEGS": 0, "PORTAL_LEGS_FREE": 0}
    return {
        "VIEW_TILES": int(tiles.portals),
        "INSTANCE_TILES": int(tiles.instances),
        "INSTANCE_TILES_ONLY": int(tiles.instances_only),
        "PORTAL_LEGS": int(tiles.portal_legs),
        "PORTAL_LEGS_FREE": int(tiles.portal_legs_free),
        "VIEW_TILE_LOG2": TILE_LOG2,
    }


def frame_view_tiles(
    scene: UploadedScene, camera: CameraView, width: int, height: int, features: Features, row: np.ndarray
) -> FrameTiles | None:
    """The frame's view tiles (engine/view_tiles.py) where its camera rays' first legs can use them: a first
    leg that starts at the camera in no box (``size.z`` -1, so its direction is the primary ray's); portals
    found through their tree, instances through theirs with at least :data:`INSTANCE_TILE_MIN` of them;
    else None, and the trees serve every leg."""
    if not scene.view_tiles:
        return None
    if features.aberration_modes and int(row["size"][0, 2]) != -1:
        return None
    portals = (
        scene.extra_defines.get("VIEW_TILES", 1)
        and features.portals
        and scene._space["PORTAL_TREE"]
        and scene._portal_root is not None
    )
    # Beside portals or boxes the lists are a second copy of the instance code (later legs keep the tree),
    # which llvmpipe runs for every lane; by default it is used only where most first legs search the
    # meshes: with the portal tree's many doors (most first legs end on walls), not where a box or a few
    # portals fill the view and the clearances prove their first legs free (ten-boxes-aberration and
    # -portals on GLSL: 1.19x the time with the lists). INSTANCE_TILES in the extra defines decides alone.
    # Beside the portal tree they pay in a deep instance tree only (the hotel's 833 instances: 0.83x the time),
    # not a shallow one (a floor and 30 boxes among 16 to 1,024 portals in view: 1.05-1.2x).
    beside = features.portals and not (portals and scene._counts.get("instances", 0) >= INSTANCE_TILE_MIN_BESIDE)
    wanted = scene.instance_tiles and not (features.aberration_modes or beside)
    instances = (
        scene.extra_defines.get("INSTANCE_TILES", int(wanted))
        and scene._bounds is not None
        and len(scene._bounds[0]) >= INSTANCE_TILE_MIN
    )
    # The legs after the first portals (engine/portal_legs.py), kept where they prove every mesh search of the
    # frame a first or second leg with its list: the tree's walk is then compiled out (ten-boxes-portals on
    # GLSL: 0.91x the time). Not beside the portal tree: the hotel's 55-93 portals in view cost 35-75 ms of
    # host time a frame, and its rooms' further doors leave the proof short. PORTAL_LEGS in the extra defines asks.
    legs = None
    if (
        scene.extra_defines.get("PORTAL_LEGS", int(scene.portal_legs))
        and scene.extra_defines.get("INSTANCE_TILES", 1)
        and features.portals
        and not (features.aberration_modes or features.shadows or scene._space["PORTAL_TREE"])
        and scene._bounds is not None
        and scene._portals is not None
        and len(scene._bounds[0]) >= INSTANCE_TILE_MIN
    ):
        legs = portal_legs(
            camera, width, height, scene._origin, scene._portals, (scene._instance_lanes(), *scene._bounds), TILE_LOG2
        )
        legs = legs if legs.complete else None
        instances = instances or legs is not None
    if not (portals or instances):
        return None
    # A Euclidean frame without shadows searches the meshes only on its camera rays' first legs (or, its portal
    # legs complete, on their second ones): the lists serve every search (none too long to list), and the
    # tree's walk is compiled out.
    only = bool(instances) and not (features.aberration_modes or features.shadows)
    only = only and (not features.portals or legs is not None)
    only = only and bool(scene.extra_defines.get("INSTANCE_TILES_ONLY", 1))
    # In two dispatches (GLSL's split_frame) a ray of a tile too long to list would wait for the second one's
    # event loop: listed whole, it ends in the first (the hotel's views on GLSL: 0.89-0.97x the time uncapped).
    # Beside boxes and few portals two dispatches with the lists cost as one without them (space-count in view,
    # 320x320: 0.99-1.01x), where one with them costs 1.12-1.23x: the lists stay off there.
    cap = 1 << 30 if scene.split_frame(features) else INSTANCE_TILE_MAX
    instance_max = 1 << 30 if only else scene.extra_defines.get("INSTANCE_TILE_MAX", cap)
    seen = scene._seen_portals  # the portal leaves, where the frame's features walked them for this camera
    table = view_tiles(
        camera,
        width,
        height,
        scene._origin,
        portals=(scene._space_nodes, scene._portal_root) if portals and scene._portal_root is not None else None,
        instances=(scene._instance_lanes(), *scene._bounds) if instances and scene._bounds is not None else None,
        instance_max=instance_max,
        legs=(legs, len(scene._portals)) if legs is not None and scene._portals is not None else None,
        portal_leaves=seen[2] if seen is not None and seen[0] is camera and seen[1] == width / height else None,
    )
    free = legs is not None and bool(scene.extra_defines.get("PORTAL_LEGS_FREE", 1))
    return FrameTiles(table, bool(portals), bool(instances), only, legs is not None, free)


def portal_free_tiles(
    scene: UploadedScene, camera: CameraView, tiles: FrameTiles | None, features: Features, width: int, height: int
) -> np.ndarray | None:
    """Per view tile, whether its camera rays' first legs meet no portal and take their instances from the tile's
    list: the frame's Euclidean variant gives those pixels to the bit (one leg, the same list, no event), so a
    frame with portals may trace them with it (OpenCL's TILE_ORDER). A tile meets no portal where no quad the
    camera sees covers it (:func:`engine.view_tiles.quad_tiles`: the tiles' portal lists, from the quads' boxes,
    hold 1.4x the hotel's tiles). None where the frame cannot split: no portal lists, boxes or shadow rays
    (which may meet what no camera ray does), or no such tile."""
    if tiles is None or not (tiles.portals and tiles.instances) or tiles.portal_legs:
        return None
    seen = scene._seen_portals
    if not features.portals or features.aberration_modes or features.shadows or scene._portals is None:
        return None
    if seen is None or seen[0] is not camera or seen[1] != width / height:
        return None
    rows = scene._space_nodes["first"][seen[2]]
    corners = quad_corners(scene._portals["world_to_local"][rows].astype(np.float64))
    covered = quad_tiles(camera, width, height, scene._origin, corners)
    free = ~covered & (tiles.table["entry"][: len(covered), 3] >= 0)
    return free if free.any() else None
