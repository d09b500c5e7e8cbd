"""Generate ``knot.obj``: the decorative trefoil knot of the starter demo.

The mesh is a tube swept along a (2, 3) torus knot, with three ribs that twist
around the tube as it runs, closed on itself in both directions: a watertight,
consistently (outward) wound genus-1 surface of ``2 * SEGMENTS * SIDES``
triangles, centred at the origin and scaled to fit a sphere of diameter 1.

Regenerate with ``python -m demos.assets.make_knot`` (or run this file); the
output is deterministic, so an unchanged generator rewrites the same file.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import trimesh

P, Q = 2, 3  # the torus knot winds P times around the axis and Q times through the hole
KNOT_R, KNOT_r = 1.0, 0.42  # radii of the torus the knot lies on (before scaling)
TUBE_RADIUS = 0.2
RIBS, RIB_DEPTH, RIB_TWIST = 3, 0.18, 8  # ribs around the tube, their relief, their turns per loop
SEGMENTS, SIDES = 120, 12  # samples along the knot and around the tube: 2 * 120 * 12 = 2880 triangles
DIGITS = 6  # decimals written for each coordinate (the mesh fits in [-0.5, 0.5]^3)
OUT = Path(__file__).with_name("knot.obj")


def knot_curve(t: np.ndarray) -> np.ndarray:
    """Points of the (P, Q) torus knot at parameters ``t`` in [0, 2π)."""
    rho = KNOT_R + KNOT_r * np.cos(Q * t)
    return np.stack([rho * np.cos(P * t), KNOT_r * np.sin(Q * t), rho * np.sin(P * t)], axis=-1)


def closed_frames(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rotation-minimising frames (tangent, normal, binormal) along a closed polyline.

    Parallel transport does not close up after one loop; the leftover twist is
    spread evenly along the curve so that the last frame meets the first.
    """
    n = len(points)
    tangents = np.roll(points, -1, axis=0) - np.roll(points, 1, axis=0)
    tangents /= np.linalg.norm(tangents, axis=1, keepdims=True)
    normals = np.empty_like(points)
    seed = np.array([0.0, 1.0, 0.0]) if abs(tangents[0, 1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    normals[0] = np.cross(np.cross(tangents[0], seed), tangents[0])
    normals[0] /= np.linalg.norm(normals[0])
    for i in range(1, n + 1):
        t = tangents[i % n]
        v = normals[i - 1] - np.dot(normals[i - 1], t) * t
        v /= np.linalg.norm(v)
        if i == n:
            end = v
        else:
            normals[i] = v
    # Angle from the transported frame back to the starting frame, about the tangent.
    start_binormal = np.cross(tangents[0], normals[0])
    twist = np.arctan2(np.dot(end, start_binormal), np.dot(end, normals[0]))
    angles = -twist * np.arange(n) / n
    binormals = np.cross(tangents, normals)
    cos, sin = np.cos(angles)[:, None], np.sin(angles)[:, None]
    normals, binormals = cos * normals + sin * binormals, -sin * normals + cos * binormals
    return tangents, normals, binormals


def check_clearance(centre: np.ndarray) -> None:
    """The tube must not run into itself where the knot's strands pass close by."""
    gap = np.linalg.norm(centre[:, None, :] - centre[None, :, :], axis=-1)
    steps = np.arange(len(centre))
    along = np.abs(steps[:, None] - steps[None, :])
    along = np.minimum(along, len(centre) - along)
    # Points far apart along the knot (more than a quarter loop) are on different strands.
    closest = gap[along > len(centre) // 4].min()
    widest = 2.0 * TUBE_RADIUS * (1.0 + RIB_DEPTH)
    if closest <= 1.1 * widest:
        raise SystemExit(f"tube too thick: strands {closest:.3f} apart, tube {widest:.3f} wide")


def build_knot() -> trimesh.Trimesh:
    """The knot as a watertight trimesh, outward wound, centred, diameter 1."""
    t = np.linspace(0.0, 2.0 * np.pi, SEGMENTS, endpoint=False)
    centre = knot_curve(t)
    _, normals, binormals = closed_frames(centre)
    check_clearance(centre)

    theta = np.linspace(0.0, 2.0 * np.pi, SIDES, endpoint=False)
    # Ribs: the radius varies around the tube, and the pattern turns RIB_TWIST
    # times per loop (an integer, so the surface closes along the knot).
    radius = TUBE_RADIUS * (1.0 + RIB_DEPTH * np.cos(RIBS * theta[None, :] + RIB_TWIST * t[:, None]))
    ring = np.cos(theta)[None, :, None] * normals[:, None, :] + np.sin(theta)[None, :, None] * binormals[:, None, :]
    vertices = (centre[:, None, :] + radius[:, :, None] * ring).reshape(-1, 3)

    i = np.arange(SEGMENTS)[:, None]
    j = np.arange(SIDES)[None, :]
    a = i * SIDES + j
    b = ((i + 1) % SEGMENTS) * SIDES + j
    c = ((i + 1) % SEGMENTS) * SIDES + (j + 1) % SIDES
    d = i * SIDES + (j + 1) % SIDES
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([a, c, d], -1)], axis=1).reshape(-1, 3)

    mesh = trimesh.Trimesh(vertices, faces, process=False)
    if mesh.volume < 0:
        mesh.invert()
    bounds_centre = mesh.bounds.mean(axis=0)
    mesh.apply_translation(-bounds_centre)
    mesh.apply_scale(0.5 / np.linalg.norm(mesh.vertices, axis=1).max())
    return mesh


def check(mesh: trimesh.Trimesh) -> None:
    """Fail loudly if the mesh is not a clean closed surface."""
    problems = []
    if not mesh.is_watertight:
        problems.append("not watertight")
    if not mesh.is_winding_consistent:
        problems.append("inconsistent winding")
    if mesh.volume <= 0:
        problems.append("inward winding")
    if problems:
        raise SystemExit("knot mesh is broken: " + ", ".join(problems))


def main(out: Path = OUT) -> Path:
    """Build, check and write the knot; returns the path written."""
    mesh = build_knot()
    check(mesh)
    text = trimesh.exchange.obj.export_obj(
        mesh,
        include_normals=False,
        include_color=False,
        include_texture=False,
        digits=DIGITS,
        header=f"aberrant starter-demo knot, {len(mesh.faces)} triangles, from demos/assets/make_knot.py",
    )
    out.write_text(text)
    # Round trip: what was written must load as the same closed surface.
    loaded = trimesh.load(out, force="mesh")
    assert isinstance(loaded, trimesh.Trimesh)
    check(loaded)
    print(f"wrote {out} ({len(mesh.vertices)} vertices, {len(mesh.faces)} triangles)")
    return out


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else OUT)
