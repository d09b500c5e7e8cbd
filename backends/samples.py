"""Several samples a pixel: where in the pixel each one starts, and the frame they average to.

Every backend traces the sample points the same way (``CameraView.subpixel``, the camera row's
``subpixel``), so the averaged colour is compared across backends exactly as one sample is. Sample 0 is
the pixel centre, so one sample a pixel is the plain frame, and the AOVs other than colour (depth,
instance, ...) always come from it: averaging an entity id or a path length would make values that no
ray saw.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import numpy as np

from backends.base import AOVS, Backend, Frame
from engine.camera_view import CameraView
from engine.errors import AberrantError

#: The most samples a pixel a frame may take.
MAX_SPP = 256
#: The R2 sequence's steps (1/g, 1/g^2 with g the plastic number): a low-discrepancy set of points for
#: any count, each prefix spread over the pixel, fixed so that frames are reproducible.
_PLASTIC = 1.324717957244746025960908854
_R2_STEP = np.array([1.0 / _PLASTIC, 1.0 / _PLASTIC**2])


def check_spp(spp: object) -> int:
    """``spp`` as an int from 1 to MAX_SPP, or one AberrantError that says what is allowed."""
    if isinstance(spp, bool) or not isinstance(spp, int | np.integer) or not 1 <= int(spp) <= MAX_SPP:
        raise AberrantError(f"spp (samples per pixel) must be a whole number from 1 to {MAX_SPP}, got {spp!r}")
    return int(spp)


def subpixel_offsets(spp: int) -> np.ndarray:
    """The first ``spp`` sample points (spp, 2) in the pixel, x right and y down in [0, 1); row 0 the centre."""
    k = np.arange(check_spp(spp), dtype=np.float64)[:, None]
    return np.mod(0.5 + k * _R2_STEP, 1.0)


def sample_camera(camera: CameraView, index: int) -> CameraView:
    """``camera`` tracing sample ``index`` of each pixel."""
    x, y = np.mod(0.5 + index * _R2_STEP, 1.0)
    return dataclasses.replace(camera, subpixel=(float(x), float(y)))


class ColorAccumulator:
    """A running sum of colour samples, whose mean is the anti-aliased colour (rounded to the nearest)."""

    def __init__(self, first: Frame) -> None:
        self.frame = first
        self.samples = 1
        self._sum = None if first.color is None else first.color[..., :3].astype(np.uint32)

    def add(self, color: np.ndarray) -> None:
        assert self._sum is not None
        self._sum += color[..., :3]
        self.samples += 1

    def mean(self) -> np.ndarray:
        """The averaged colour (H, W, 4) uint8, alpha 255."""
        assert self.frame.color is not None and self._sum is not None
        out = self.frame.color.copy()
        out[..., :3] = (self._sum + self.samples // 2) // self.samples
        return out


def render_samples(
    backend: Backend, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS, spp: int = 1
) -> Frame:
    """One frame of ``spp`` samples a pixel: the colour averaged, every other AOV from the centre sample.

    Samples after the first trace only colour. ``timings_ms`` are the samples' sums.
    """
    spp = check_spp(spp)
    frame = backend.render(camera, width, height, aovs)
    if spp == 1 or frame.color is None:
        return frame
    total = ColorAccumulator(frame)
    for index in range(1, spp):
        sample = backend.render(sample_camera(camera, index), width, height, ("color",))
        assert sample.color is not None
        total.add(sample.color)
        for key, ms in sample.timings_ms.items():
            frame.timings_ms[key] = frame.timings_ms.get(key, 0.0) + ms
    frame.color = total.mean()
    return frame
