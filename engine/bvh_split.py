"""Pre-splitting of long triangles: several tight boxes for a triangle whose box dwarfs it.

A long diagonal triangle (a plank, a strip of lawn) has a box far bigger than its
area; every ray through that box tests it, and its box inflates its node's. Early
split clipping (Ernst & Greiner) cuts such a triangle's box in halves at the
midpoint of its longest axis, each half bounding only the part of the triangle in
it, before the tree is built. The tree then holds references: a triangle may sit in
several leaves, always as itself (the same vertices), so a ray finds the same hit.

How many pieces a triangle gets follows Karras & Aila's rule: the excess of its box's
area over what its own area warrants, shared out of a fixed budget of references.
"""

from __future__ import annotations

import numpy as np

__all__ = ["half_area", "split_references"]


def half_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes, xyz on the FIRST axis; empty boxes (lo > hi) give 0."""
    d = np.maximum(hi.astype(np.float64) - lo, 0.0)
    return d[0] * d[1] + d[1] * d[2] + d[2] * d[0]


def _pieces(box_area: np.ndarray, tri_area: np.ndarray, ratio: float, budget: float) -> np.ndarray:
    """Pieces per triangle (>= 1): extra references out of ``budget * m`` in proportion to the excess area."""
    m = box_area.size
    # A zero-area triangle is never hit (the watertight test rejects it): splitting it would only add references.
    excess = np.where((box_area > ratio * tri_area) & (tri_area > 0.0), box_area - ratio * tri_area, 0.0)
    total = excess.sum()
    extra = int(budget * m)
    if total <= 0 or extra < 1:
        return np.ones(m, np.int64)
    share = np.floor(np.cumsum(extra * excess / total) + 1e-9).astype(np.int64)  # whole pieces, remainders carried
    return 1 + np.diff(share, prepend=0)


def _half(corners: np.ndarray, axis: np.ndarray, plane: np.ndarray, below: bool) -> tuple[np.ndarray, np.ndarray]:
    """Bounds (R, 3) float64 of each triangle's part on one side of ``plane`` along ``axis``: its corners on
    that side and where its edges cross the plane (lo > hi where no part is on that side)."""
    r = np.arange(len(corners))
    c = corners  # (R, 3 corners, xyz)
    x = c[r, :, axis]  # (R, 3) the corners' coordinate along the axis
    side = x <= plane[:, None] if below else x >= plane[:, None]
    pts = [np.where(side[:, :, None], c, np.nan)]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        xa, xb = x[:, a], x[:, b]
        crosses = (xa - plane) * (xb - plane) < 0
        with np.errstate(divide="ignore", invalid="ignore"):
            s = np.where(crosses, (plane - xa) / (xb - xa), np.nan)
        p = c[:, a] + s[:, None] * (c[:, b] - c[:, a])
        p[r, axis] = np.where(crosses, plane, np.nan)
        pts.append(p[:, None, :])
    allp = np.concatenate(pts, axis=1)
    return np.fmin.reduce(allp, axis=1), np.fmax.reduce(allp, axis=1)


def split_references(
    corners: np.ndarray, lo: np.ndarray, hi: np.ndarray, ratio: float, budget: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(triangle, lo, hi)`` of the references of triangles with corners ``corners`` (M, 3, 3) float32 and
    boxes ``lo``/``hi`` (M, 3) float32: one per triangle unless its box's half area exceeds ``ratio`` times
    its area, at most ``budget * M`` more in all. Every reference's box holds its part of the triangle
    (rounded outward to float32) and lies inside the triangle's box; references are grouped by triangle."""
    m = len(corners)
    c64 = corners.astype(np.float64)
    tri_area = 0.5 * np.linalg.norm(np.cross(c64[:, 1] - c64[:, 0], c64[:, 2] - c64[:, 0]), axis=1)
    pieces = _pieces(half_area(lo.T, hi.T), tri_area, ratio, budget)
    tri = np.arange(m, dtype=np.int64)
    rlo, rhi = lo.astype(np.float64), hi.astype(np.float64)
    want = pieces.copy()
    done_t, done_lo, done_hi = [], [], []
    while True:
        go = want > 1
        done_t.append(tri[~go])
        done_lo.append(rlo[~go])
        done_hi.append(rhi[~go])
        if not go.any():
            break
        tri, rlo, rhi, want = tri[go], rlo[go], rhi[go], want[go]
        axis = np.argmax(rhi - rlo, axis=1)
        r = np.arange(tri.size)
        plane = 0.5 * (rlo[r, axis] + rhi[r, axis])
        parts = []
        for below, share in ((True, want // 2), (False, want - want // 2)):
            plo, phi = _half(c64[tri], axis, plane, below)
            plo, phi = np.maximum(plo, rlo), np.minimum(phi, rhi)  # inside the piece being cut
            if below:
                phi[r, axis] = np.minimum(phi[r, axis], plane)
            else:
                plo[r, axis] = np.maximum(plo[r, axis], plane)
            parts.append((plo, phi, share))
        (alo, ahi, an), (blo, bhi, bn) = parts
        a_ok, b_ok = (alo <= ahi).all(axis=1), (blo <= bhi).all(axis=1)
        # A side holding none of the triangle hands its pieces to the other; neither (rounding): keep the piece.
        an, bn = np.where(b_ok, an, an + bn), np.where(a_ok, bn, an + bn)
        neither = ~a_ok & ~b_ok
        alo[neither], ahi[neither], an[neither], a_ok[neither] = rlo[neither], rhi[neither], 1, True
        tri = np.concatenate([tri[a_ok], tri[b_ok]])
        rlo, rhi = np.concatenate([alo[a_ok], blo[b_ok]]), np.concatenate([ahi[a_ok], bhi[b_ok]])
        want = np.concatenate([an[a_ok], bn[b_ok]])
    tri = np.concatenate(done_t)
    out_lo = np.nextafter(np.concatenate(done_lo).astype(np.float32), np.float32(-np.inf))
    out_hi = np.nextafter(np.concatenate(done_hi).astype(np.float32), np.float32(np.inf))
    # Never past the triangle's own (exact) box: rounding outward must not grow it.
    out_lo, out_hi = np.maximum(out_lo, lo[tri]), np.minimum(out_hi, hi[tri])
    keep = np.argsort(tri, kind="stable")
    return tri[keep], out_lo[keep], out_hi[keep]
