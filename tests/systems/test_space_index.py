"""The camera's walk and teleport among many portals and boxes (engine/space_index.py): through the index
they meet exactly the boxes and portals the loops over all of them meet, and a tick costs no rebuild."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scenes import crowded

from components import Transform
from engine.scene import Scene
from engine.space_index import SpaceIndex
from systems.camera_movement import SpeedBoxes, active_box, first_face_crossing, speed_boxes, walk
from systems.portal_teleport import PortalLinks, portal_links, teleport_path


def shuffle(scene: Scene, rng: np.random.Generator, prefix: str, count: int, moves: int) -> None:
    """Move a few of the scene's portals or boxes somewhere else in the view space."""
    for k in rng.integers(0, count, moves):
        entity = scene.entity(f"{prefix}{k}")
        t = scene.get(entity, Transform)
        scene.set(entity, replace(t, position=tuple(np.add(t.position, rng.normal(size=3)))))


def entity_of(box) -> int | None:
    return None if box is None else box.entity


@pytest.mark.parametrize("seed", range(4))
def test_walks_among_many_boxes_are_the_loops(seed):
    scene = crowded("boxes", 300, seed=seed)
    rng = np.random.default_rng(seed)
    index = SpeedBoxes(scene)
    try:
        for _ in range(5):
            shuffle(scene, rng, "a", 300, 3)
            boxes = speed_boxes(scene)
            near = index.sync()
            for _ in range(40):
                start = rng.uniform([-4.0, 0.2, -7.0], [4.0, 3.0, 0.5])
                v = rng.normal(size=3) * rng.uniform(0.5, 20.0)
                assert entity_of(active_box(near, start)) == entity_of(active_box(boxes, start))
                assert first_face_crossing(near, start, v * 0.1) == first_face_crossing(boxes, start, v * 0.1)
                expected = walk(boxes, start, v, 0.1)
                assert np.array_equal(np.array(walk(near, start, v, 0.1)), np.array(expected))
        assert index.index.rebuilds == 1
    finally:
        scene.close()


@pytest.mark.parametrize("seed", range(4))
def test_teleports_among_many_portals_are_the_loops(seed):
    scene = crowded("portals", 400, seed=seed)
    rng = np.random.default_rng(seed)
    index = PortalLinks(scene)
    crossed = 0
    try:
        for _ in range(5):
            shuffle(scene, rng, "p", 400, 3)
            links = portal_links(scene)
            near = index.sync()
            for _ in range(60):
                start = rng.uniform([-4.0, 0.2, -7.0], [4.0, 3.0, 0.5])
                path = [start, start + rng.normal(size=3) * rng.uniform(0.1, 3.0)]
                expected = teleport_path(links, path)
                result = teleport_path(near, path)
                assert np.array_equal(result.position, expected.position)
                assert np.array_equal(result.rotation, expected.rotation)
                assert [c.entity for c in result.crossings] == [c.entity for c in expected.crossings]
                crossed += bool(expected.crossings)
        assert crossed > 10  # the paths do cross portals
        assert index.index.rebuilds == 1
    finally:
        scene.close()


def test_one_index_serves_the_walk_and_the_teleport():
    """An app shares one index: the first system's sync refits, the second's finds nothing left to do, and
    the teleport still checks a retargeted portal."""
    scene = crowded("portals", 20, seed=1)
    index = SpaceIndex()
    boxes, links = SpeedBoxes(scene, index), PortalLinks(scene, index)
    boxes.sync()
    links.sync()
    shuffle(scene, np.random.default_rng(2), "p", 20, 2)
    boxes.sync()
    links.sync()
    assert index.rebuilds == 1
    scene.close()
