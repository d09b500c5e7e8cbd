"""Error metrics against the float64 reference, timing summaries and the Pareto front.

Errors are computed the way the parity tests judge a backend
(tests/backends/test_parity.py): instance ids compared on every pixel, lengths
compared only where both frames hit the same instance (elsewhere a length
error says nothing the mismatch does not already say).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import numpy as np

#: Parity thresholds the smoke test holds every supported cell to.
MISMATCH_MAX_EUCLIDEAN = 1e-3
MISMATCH_MAX_NON_EUCLIDEAN = 2e-3
DEPTH_P99_MAX = 1e-3


def instance_mismatch(fast: np.ndarray, ref: np.ndarray) -> float:
    """Fraction of pixels whose instance id differs from the reference's."""
    if fast.shape != ref.shape:
        raise ValueError(f"instance AOVs differ in shape: {fast.shape} vs {ref.shape}")
    return float(np.mean(fast != ref)) if fast.size else 0.0


def relative_error(fast: np.ndarray, ref: np.ndarray, mask: np.ndarray) -> tuple[float, float]:
    """Median and 99th percentile of ``|fast - ref| / |ref|`` over ``mask`` (0, 0 when the mask is empty).

    A non-finite value where the reference is finite counts as an infinite error, so
    it cannot hide; pixels where the reference itself is not finite (a miss) are skipped.
    """
    truth = ref[mask].astype(np.float64)
    value = fast[mask].astype(np.float64)
    keep = np.isfinite(truth)
    truth, value = truth[keep], value[keep]
    if truth.size == 0:
        return 0.0, 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        rel = np.abs(value - truth) / np.abs(truth)
    rel = np.sort(np.where(np.isfinite(value), np.where(np.isnan(rel), 0.0, rel), np.inf))
    return _quantile(rel, 0.5), _quantile(rel, 0.99)


def _quantile(ordered: np.ndarray, q: float) -> float:
    """Linear-interpolated quantile of sorted values (as ``np.percentile``), +inf once it reaches an infinity."""
    k = q * (len(ordered) - 1)
    lo, hi = math.floor(k), math.ceil(k)
    a, b = float(ordered[lo]), float(ordered[hi])
    if math.isinf(b):
        return math.inf if hi > lo or math.isinf(a) else a
    return a + (b - a) * (k - lo)


@dataclass(frozen=True)
class Errors:
    """One frame against the reference frame of the same scene, camera, size and max_events."""

    mismatch: float  # fraction of pixels
    depth_median: float
    depth_p99: float
    perceived_median: float
    perceived_p99: float
    nan_count: int  # NaN in depth and perceived
    compared: int  # pixels where both hit the same instance

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def compare(
    instance: np.ndarray, depth: np.ndarray, perceived: np.ndarray | None, ref: dict[str, np.ndarray]
) -> Errors:
    """:class:`Errors` of one frame's AOVs against a reference frame's (``perceived`` may be absent: Embree)."""
    mismatch = instance_mismatch(instance, ref["instance"])
    same = (instance == ref["instance"]) & (ref["instance"] >= 0)
    depth_median, depth_p99 = relative_error(depth, ref["depth"], same)
    nan = int(np.isnan(depth).sum())
    if perceived is not None:
        perceived_median, perceived_p99 = relative_error(perceived, ref["perceived"], same)
        nan += int(np.isnan(perceived).sum())
    else:
        perceived_median = perceived_p99 = math.nan
    return Errors(mismatch, depth_median, depth_p99, perceived_median, perceived_p99, nan, int(same.sum()))


def color_error(color: np.ndarray, target: np.ndarray) -> dict[str, float]:
    """Mean absolute error (0..255 levels) and PSNR (dB; +inf when equal) of an image's RGB against a target's."""
    if color.shape != target.shape:
        raise ValueError(f"colour images differ in shape: {color.shape} vs {target.shape}")
    diff = color[..., :3].astype(np.float64) - target[..., :3].astype(np.float64)
    mse = float(np.mean(diff * diff)) if diff.size else 0.0
    psnr = 10.0 * math.log10(255.0**2 / mse) if mse > 0 else math.inf
    return {"mae": float(np.mean(np.abs(diff))) if diff.size else 0.0, "psnr": psnr}


@dataclass(frozen=True)
class Timing:
    """Frame times of the timed runs (milliseconds)."""

    median_ms: float
    min_ms: float
    max_ms: float
    runs: int

    @staticmethod
    def of(samples_ms: Sequence[float]) -> Timing:
        if not samples_ms:
            raise ValueError("no timed runs")
        values = np.asarray(samples_ms, dtype=np.float64)
        return Timing(float(np.median(values)), float(values.min()), float(values.max()), len(values))

    def mrays_per_s(self, rays: int) -> float:
        """Primary rays per second at the median frame time, in millions."""
        return rays / (self.median_ms * 1e-3) / 1e6 if self.median_ms > 0 else math.inf

    def as_dict(self) -> dict[str, float | int]:
        return asdict(self)


def pareto_front(points: Sequence[tuple[float, float]]) -> list[int]:
    """Indices of the points no other point beats in both coordinates (both minimised), by the first.

    A point is dominated when another is no worse in both and better in one;
    duplicates are all kept. NaN points are never on the front.
    """
    finite = [(x, y, i) for i, (x, y) in enumerate(points) if not (math.isnan(x) or math.isnan(y))]
    finite.sort(key=lambda p: (p[0], p[1]))
    front: list[int] = []
    best_y = math.inf
    last: tuple[float, float] | None = None
    for x, y, i in finite:
        if y < best_y or (last is not None and (x, y) == last):
            front.append(i)
            best_y = min(best_y, y)
            last = (x, y)
    return front


def geometric_mean(values: Sequence[float]) -> float:
    """The geometric mean of positive values (NaN for none): averages frame times across scenes fairly."""
    positive = [v for v in values if v > 0 and math.isfinite(v)]
    return math.exp(sum(math.log(v) for v in positive) / len(positive)) if positive else math.nan
