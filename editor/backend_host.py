"""The viewport's tracer: which backend, at what precision and resolution, and the frames it renders.

A backend that cannot start, or cannot trace the scene, never takes the
editor down: the reason is kept in :attr:`BackendHost.error`, shown in the
backend panel and status bar, and the viewport falls back to the raster
preview. Edit-mode frames are rendered only when the scene, the view or the
size changed, so an idle editor does not keep a slow CPU tracer busy; while
nothing changes, a few more samples a pixel refine the still image (up to
STILL_SPP), then the tracer rests.
"""

from __future__ import annotations

import time
from collections import deque
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from backends.base import BACKENDS, Backend, Frame, backend_class, create_backend, probe
from backends.samples import ColorAccumulator, sample_camera
from backends.upload import SceneUploader
from engine.camera_view import CameraView
from engine.records import Precision
from engine.scene import Scene

if TYPE_CHECKING:
    import moderngl

#: Frames kept for the frame-time plot.
HISTORY = 240
#: Samples a pixel a still edit-mode view accumulates, one more each editor frame (moving: one).
STILL_SPP = 16


class BackendHost:
    """Owns the active backend and the uploader that feeds it in edit mode."""

    def __init__(self, ctx: moderngl.Context | None = None, log: Callable[[str], None] | None = None) -> None:
        self.ctx = ctx
        self.log = log or (lambda message: None)
        self.backend: Backend | None = None
        self.name: str | None = None
        self.error: str | None = None
        #: Fraction of the viewport's pixels traced (the image is stretched to fit).
        self.scale = 0.5
        self.frame_ms: deque[float] = deque(maxlen=HISTORY)
        self.mrays: deque[float] = deque(maxlen=HISTORY)
        self.frames = 0
        self._reasons: dict[str, str | None] | None = None
        self._uploader: SceneUploader | None = None
        self._key: tuple[Any, ...] | None = None
        self._texture: moderngl.Texture | None = None
        self.last_frame: Frame | None = None
        #: The still view's samples so far (None: one sample, the frame as rendered).
        self._samples: ColorAccumulator | None = None

    # --- choosing a backend ---------------------------------------------------------------

    def reasons(self, refresh: bool = False) -> dict[str, str | None]:
        """``name -> None`` (can run) or the reason it cannot, probed once."""
        if self._reasons is None or refresh:
            self._reasons = {name: probe(name) for name in BACKENDS}
        return self._reasons

    @staticmethod
    def precisions(name: str) -> tuple[Precision, ...]:
        try:
            return tuple(backend_class(name).precisions)
        except Exception:  # an unimportable backend: the panel shows its probe reason instead
            return ("f32",)

    @property
    def precision(self) -> Precision | None:
        return None if self.backend is None else self.backend.precision

    @property
    def aovs(self) -> tuple[str, ...]:
        """What to render: the GLSL backend's texture is drawn as it is, others need the colour read back."""
        return () if self._draws_in_place else ("color",)

    @property
    def _draws_in_place(self) -> bool:
        return self.backend is not None and self.ctx is not None and getattr(self.backend, "context", None) is self.ctx

    def select(self, name: str, precision: Precision | None = None) -> bool:
        """Start backend ``name`` (GLSL draws in the editor's own context); on failure keep the reason."""
        self.release()
        self.name = name
        try:
            if name == "glsl" and self.ctx is not None:
                from backends.glsl.backend import GlslBackend

                self.backend = GlslBackend(precision, context=self.ctx)
            else:
                self.backend = create_backend(name, precision=precision, fallback=False)
        except Exception as e:  # whatever a backend raises while starting, the editor must go on
            self.backend = None
            self.error = f"the {name} backend cannot start: {e}"
            self.log(self.error)
            return False
        self.error = None
        self.frame_ms.clear()
        self.mrays.clear()
        return True

    def select_first(self, preferred: Sequence[str]) -> bool:
        """The first of ``preferred`` that starts (the editor's default)."""
        return any(name in BACKENDS and self.reasons().get(name) is None and self.select(name) for name in preferred)

    def invalidate(self) -> None:
        """Forget what was uploaded (another scene ran on the backend, or the scene object changed)."""
        self._uploader = None
        self._key = None
        self._samples = None

    # --- rendering -----------------------------------------------------------------------------

    def render_view(self, scene: Scene, view: CameraView, size: tuple[int, int]) -> bool:
        """Trace ``scene`` from ``view`` if anything changed; True when a frame is ready to show."""
        if self.backend is None:
            return False
        key = (scene.world, scene.cursor, *view.position, *view.rotation.ravel(), view.fov_deg, size, id(self.backend))
        if key == self._key:
            if self.error is None and self.samples < STILL_SPP:
                self._refine(view, size)
            return self.error is None and self.texture is not None
        self._key = key
        try:
            if self._uploader is None:
                self._uploader = SceneUploader(self.backend)
            self._uploader.sync(scene, view.position)
            start = time.perf_counter()
            frame = self.backend.render(view, size[0], size[1], self.aovs)
            elapsed = (time.perf_counter() - start) * 1e3
        except Exception as e:  # a backend that cannot trace this scene: say so, show the raster preview
            self._uploader = None
            message = f"{self.backend.name}: {e}"
            if message != self.error:
                self.log(message)
            self.error = message
            return False
        self.error = None
        self.present(frame, elapsed)
        return True

    @property
    def samples(self) -> int:
        """Samples a pixel of the image shown (the window keeps drawing while it grows)."""
        return 1 if self._samples is None else self._samples.samples

    def _refine(self, view: CameraView, size: tuple[int, int]) -> None:
        """Trace one more sample of the still view and show the mean of all so far."""
        assert self.backend is not None
        try:
            if self._samples is None:
                first = self.last_frame
                if first is None:
                    return
                if first.color is None:  # drawn in place: the centre sample is in the backend's texture
                    texture = getattr(self.backend, "color_texture", None)
                    if texture is None:
                        return
                    color = np.frombuffer(texture.read(alignment=1), np.uint8).reshape(size[1], size[0], 4)
                    first = Frame(size[0], size[1], color=color.copy())
                self._samples = ColorAccumulator(first)
            sample = self.backend.render(sample_camera(view, self._samples.samples), size[0], size[1], ("color",))
            self._samples.add(sample.aov("color"))
        except Exception as e:  # refining is a nicety: a failure keeps the image shown and says why once
            self.log(f"{self.backend.name}: refining the still view: {e}")
            self._samples = None
            self._key = None
            return
        self._show(self._samples.mean())

    def _show(self, color: np.ndarray) -> None:
        """Write ``color`` (H, W, 4) into the editor's own texture."""
        if self.ctx is None:
            return
        size = (color.shape[1], color.shape[0])
        if self._texture is None or self._texture.size != size:
            if self._texture is not None:
                self._texture.release()
            self._texture = self.ctx.texture(size, 4)
        self._texture.write(np.ascontiguousarray(color).tobytes())

    def present(self, frame: Frame, elapsed_ms: float | None = None) -> None:
        """Record a frame (edit or play mode) for display and for the statistics."""
        ms = frame.timings_ms.get("render", elapsed_ms if elapsed_ms is not None else 0.0)
        self.frame_ms.append(ms)
        self.mrays.append(frame.width * frame.height / max(ms, 1e-6) / 1e3)
        self.frames += 1
        self.last_frame = frame
        self._samples = None
        if not self._draws_in_place and frame.color is not None:
            self._show(frame.color)

    @property
    def texture(self) -> moderngl.Texture | None:
        """The latest frame as a texture, row 0 = the image's top row."""
        if self._draws_in_place and self._samples is None:
            return getattr(self.backend, "color_texture", None)
        return self._texture

    def release(self) -> None:
        if self.backend is not None:
            self.backend.release()
        self.backend = None
        self.invalidate()
        self.last_frame = None

    def close(self) -> None:
        self.release()
        if self._texture is not None:
            self._texture.release()
            self._texture = None
