"""Editor picking and preview outlines among a thousand portals and boxes: through the space index they give
what the loops over every entity give, while looking at only the few a click ray or the view can reach."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from components import Aberration, Mesh, Portal, Transform
from editor.overlay import Outlines, preview_lines, view_planes
from editor.picking import _to_local, pick, ray_box, ray_quad, ray_triangles
from editor.view import EditorView, perspective, view_matrix
from engine.scene import Scene
from engine.space_index import SpaceIndex

#: Cells per side of the grid the portals and boxes stand in, and the grid's spacing.
SIDE = 10
SPACING = 3.0


def grid(seed: int = 0) -> Scene:
    """500 portals (250 pairs) and 500 aberration boxes, one per cell of a 10^3 grid, of random offset,
    turn and size, with a floor and a few meshes among them."""
    rng = np.random.default_rng(seed)
    scene = Scene(f"editor-grid-{seed}")
    scene.add_mesh("floor", "plane", position=(15.0, -1.0, 15.0), scale=(40.0, 1.0, 40.0))
    for k in range(8):
        scene.add_mesh(f"m{k}", "sphere", position=tuple(rng.uniform(0.0, 27.0, 3)), scale=0.8)
    cells = rng.permutation(SIDE**3)

    def place(cell: int) -> dict:
        centre = np.array(np.unravel_index(cell, (SIDE,) * 3), float) * SPACING
        return dict(
            position=tuple(centre + rng.uniform(-0.5, 0.5, 3)),
            euler_deg=tuple(rng.uniform(-180.0, 180.0, 3)),
            scale=tuple(rng.uniform(0.3, 1.0, 3)),
        )

    for k in range(0, 500, 2):
        scene.add_portal_pair(f"p{k}", f"p{k + 1}", a=place(cells[k]), b=place(cells[k + 1]))
    for k in range(500):
        scene.add_aberration(f"a{k}", tuple(rng.uniform(-0.5, 0.5, 3)), **place(cells[500 + k]))
    return scene


def pick_by_loop(scene: Scene, origin: np.ndarray, direction: np.ndarray) -> int | None:
    """Picking as a test of every mesh, portal and box (what :func:`editor.picking.pick` must agree with)."""
    best_t, best = np.inf, None
    for entity, (transform, mesh) in scene.query(Transform, Mesh):
        asset = scene.asset(mesh.asset)
        o, d = _to_local(transform, origin, direction)
        v = asset.vertices.astype(np.float64)
        t = ray_triangles(o, d, *(v[asset.faces[:, k]] for k in range(3)))
        if t < best_t:
            best_t, best = t, entity
    for entity, (transform, _) in scene.query(Transform, Portal):
        t = ray_quad(*_to_local(transform, origin, direction))
        if t < best_t:
            best_t, best = t, entity
    box_t, box = np.inf, None
    for entity, (transform, _) in scene.query(Transform, Aberration):
        enter, leave = ray_box(*_to_local(transform, origin, direction))
        if 0.0 < enter < box_t and leave < best_t:
            box_t, box = enter, entity
    return box if box is not None else best


class CountingIndex(SpaceIndex):
    """A space index that records how many candidates each ray query hands back."""

    def __init__(self) -> None:
        super().__init__()
        self.candidates: list[int] = []

    def portals_on_ray(self, origin: np.ndarray, direction: np.ndarray, t_max: float = np.inf) -> list[int]:
        found = super().portals_on_ray(origin, direction, t_max)
        self.candidates.append(len(found))
        return found

    def boxes_on_ray(self, origin: np.ndarray, direction: np.ndarray, t_max: float = np.inf) -> list[int]:
        found = super().boxes_on_ray(origin, direction, t_max)
        self.candidates[-1] += len(found)
        return found


def move_some(scene: Scene, rng: np.random.Generator, count: int) -> None:
    for k in rng.integers(0, 500, count):
        entity = scene.entity(f"{'pa'[k % 2]}{k}")
        t = scene.get(entity, Transform)
        scene.set(entity, replace(t, position=tuple(np.add(t.position, rng.normal(size=3)))))


@pytest.mark.parametrize("seed", range(2))
def test_picking_among_a_thousand_is_the_loop_and_looks_at_few(seed):
    scene = grid(seed)
    rng = np.random.default_rng(seed)
    index = CountingIndex()
    picked: dict[type, int] = {Portal: 0, Aberration: 0, Mesh: 0}
    try:
        for _ in range(3):
            move_some(scene, rng, 4)  # the index follows the journal between clicks
            for k in range(50):
                origin = rng.uniform(-3.0, 30.0, 3)
                if k % 2:  # aimed at a portal or a box, so that clicks do land on them
                    aim = np.array(
                        scene.get(scene.entity(f"{'pa'[k % 4 // 2]}{rng.integers(500)}"), Transform).position
                    )
                    direction = aim - origin
                else:
                    direction = rng.normal(size=3)
                direction /= np.linalg.norm(direction)
                expected = pick_by_loop(scene, origin, direction)
                assert pick(scene, origin, direction, index) == expected
                for kind in picked:
                    picked[kind] += expected is not None and scene.has(expected, kind)
        assert min(picked.values()) >= 10  # portals, boxes and meshes were all picked
        assert index.rebuilds == 1
        # A ray passes a handful of cells before it meets a surface: a few candidates, not the thousand.
        assert np.mean(index.candidates) < 10 and max(index.candidates) < 40
    finally:
        scene.close()


def segment_rows(segments: np.ndarray) -> set[bytes]:
    return {s.tobytes() for s in segments}


def test_outlines_are_the_lines_the_view_can_see_and_a_frame_touches_few():
    scene = grid(3)
    outlines = Outlines()
    size = (320, 240)
    try:
        view = EditorView(np.array([4.5, 4.5, -3.0]), yaw=180.0, fov_deg=40.0)
        view_proj = perspective(view.fov_deg, size[0] / size[1]) @ view_matrix(view)
        planes = view_planes(view_proj, size)
        segments, colors = outlines.lines(scene, show_camera=False, planes=planes)
        every, every_colors = preview_lines(scene, show_camera=False)
        shown = segment_rows(segments)
        colour_of = {s.tobytes(): c.tobytes() for s, c in zip(every, every_colors, strict=True)}
        assert [colour_of[s.tobytes()] for s in segments] == [c.tobytes() for c in colors]  # same lines, same colours
        # What was left out lies wholly outside one side of the frustum: it would draw no pixel.
        tight = view_planes(view_proj, size, width=0.0)
        for segment in every:
            if segment.tobytes() not in shown:
                sides = np.concatenate([segment, np.ones((2, 1))], axis=1) @ tight.T  # (2 ends, 6 planes)
                assert np.any(np.all(sides < 0.0, axis=0))
        visible = outlines.visited
        assert 20 < visible < 300  # a corner of the grid in view: about a fifth of it
        built = outlines.built
        assert built == visible

        outlines.lines(scene, show_camera=False, planes=planes)  # a still frame computes no outline
        assert outlines.built == built and outlines.visited == visible
        view.yaw += 3.0  # a turn of the view computes only what came into it
        view_proj = perspective(view.fov_deg, size[0] / size[1]) @ view_matrix(view)
        outlines.lines(scene, show_camera=False, planes=view_planes(view_proj, size))
        assert outlines.built - built < visible
        built = outlines.built
        seen = outlines.space.portals_in_planes(view_planes(view_proj, size))[0]
        t = scene.get(seen, Transform)
        scene.set(seen, replace(t, position=tuple(np.add(t.position, 0.01))))  # one portal moves: one outline
        outlines.lines(scene, show_camera=False, planes=view_planes(view_proj, size))
        assert outlines.built == built + 1
        assert outlines.space.rebuilds == 1
    finally:
        scene.close()
