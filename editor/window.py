"""The editor window: glfw, a moderngl context and Dear ImGui's glfw/OpenGL 3 backends around the UI.

The UI is :class:`editor.ui.EditorUi`, which needs no window (tests drive it headless).

One OpenGL context is shared by everything: moderngl wraps the window's
context (``moderngl.create_context()``), the GLSL tracer dispatches into it
and its colour texture is drawn by imgui as it is (no read-back), the
preview pass renders into a framebuffer of it, and imgui's own OpenGL 3
renderer draws the UI last. Other backends' frames are uploaded into a
texture. glfw comes from imgui-bundle's own library, so imgui's glfw backend
and the ``glfw`` module see the same windows.
"""

from __future__ import annotations

import ctypes
import os
import sys
import time
from pathlib import Path
from typing import TYPE_CHECKING, TypeAlias

import numpy as np
from imgui_bundle import imgui, implot  # first: points the glfw module at imgui-bundle's libglfw

from editor.backend_host import BackendHost
from editor.model import EditorModel
from editor.panels.viewport import Image, ViewRequest
from editor.preview import PreviewRenderer
from editor.reload import DocumentReload, LevelWatcher
from editor.ui import EditorUi
from engine.errors import AberrantError
from engine.scene import Scene

if TYPE_CHECKING:
    import glfw

    #: A glfw window handle (the stub names its pointer type only privately).
    Window: TypeAlias = glfw._GLFWwindowPointerT
else:
    Window = object  # what readers and docs tools see; glfw's module has no name for the handle's type

#: Backends the editor tries, in order, when none is named (GLSL first: it draws without a read-back).
PREFERRED_BACKENDS = ("glsl", "opencl", "reference")
DEFAULT_SIZE = (1600, 900)
FONT = "DroidSans.ttf"
FONT_SIZE = 16.0
#: Longest sleep of a still editor on the event queue (it then looks again; nothing is drawn without an event).
IDLE_WAIT_S = 0.5
#: Frames drawn after the last input or new image before the loop sleeps (imgui settles hover and layout over a few).
SETTLE_FRAMES = 3


class EditorUnavailable(AberrantError):
    """The editor cannot open a window here (no display, no OpenGL 3.3)."""


def display_problem(command: str = "editor") -> str | None:
    """Why no window can open here (no $DISPLAY or $WAYLAND_DISPLAY on Linux), or None."""
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return (
            f"the {command} needs a display (no $DISPLAY); run it under a desktop session or `xvfb-run aberrant "
            f"{'play' if command == 'player' else command}`"
        )
    return None


def create_gl_window(size: tuple[int, int], title: str) -> Window:
    """A glfw window with an OpenGL 4.3 core context (the GLSL tracer's compute shaders), else 3.3."""
    import glfw

    for major, minor in ((4, 3), (3, 3)):
        glfw.default_window_hints()
        glfw.window_hint(glfw.CONTEXT_VERSION_MAJOR, major)
        glfw.window_hint(glfw.CONTEXT_VERSION_MINOR, minor)
        glfw.window_hint(glfw.OPENGL_PROFILE, glfw.OPENGL_CORE_PROFILE)
        glfw.window_hint(glfw.OPENGL_FORWARD_COMPAT, True)
        window = glfw.create_window(size[0], size[1], title, None, None)
        if window:
            return window
    glfw.terminate()
    raise EditorUnavailable("a window needs OpenGL 3.3 or newer, and no such window could be created")


class EditorWindow:
    """A window running the editor; :meth:`run` loops until it is closed (or for a number of frames)."""

    def __init__(
        self,
        model: EditorModel,
        *,
        size: tuple[int, int] = DEFAULT_SIZE,
        backend: str | None = None,
        watcher: LevelWatcher | None = None,
    ) -> None:
        import glfw
        import moderngl

        problem = display_problem()
        if problem is not None:
            raise EditorUnavailable(problem)
        if not glfw.init():
            _, why = glfw.get_error()
            detail = f" ({why.decode(errors='replace') if isinstance(why, bytes) else why})" if why else ""
            raise EditorUnavailable(
                f"the editor needs a display: glfw cannot start{detail}; try `xvfb-run aberrant editor`"
            )
        self.glfw = glfw
        self.window = create_gl_window(size, "aberrant editor")
        glfw.make_context_current(self.window)
        glfw.swap_interval(1)  # an idle editor waits for the display instead of spinning
        try:
            self.ctx = moderngl.create_context()
        except Exception as e:
            glfw.terminate()
            raise EditorUnavailable(f"the editor cannot use the window's OpenGL context: {e}") from None
        self.imgui_context = imgui.create_context()
        self.plot_context = implot.create_context()
        io = imgui.get_io()
        io.config_flags |= imgui.ConfigFlags_.docking_enable.value | imgui.ConfigFlags_.nav_enable_keyboard.value
        io.set_ini_filename(None)  # the layout is built in code; a stale ini must not hide a panel
        io.config_error_recovery_enable_assert = False  # EditorUi.safe_draw recovers and reports instead
        self._load_font()
        imgui.style_colors_dark()
        #: glfw events seen (input, resize, focus, expose): a still editor sleeps until the next one.
        self.events = 0
        self._count_events()  # before imgui's callbacks, which chain to these
        address = ctypes.cast(self.window, ctypes.c_void_p).value
        assert address is not None  # a window glfw created is never the null pointer
        imgui.backends.glfw_init_for_opengl(address, True)
        imgui.backends.opengl3_init("#version 330")
        glfw.set_window_close_callback(self.window, self._on_close)
        self.model = model
        self.host = BackendHost(self.ctx, model.error)
        if backend is not None:
            self.host.select(backend)
        elif not self.host.select_first(PREFERRED_BACKENDS):
            model.error("no tracer backend can start here; the viewport shows the raster preview")
        self.preview = PreviewRenderer(self.ctx)
        self.ui = EditorUi(model, self.host, self.images)
        #: Hot reload of the document's file (or of the level module ``watcher`` watches).
        self.disk = DocumentReload(model, watcher)
        self._title = ""
        self._captured = False
        self._cursor: tuple[float, float] | None = None
        self.last_frame_ms = 0.0
        self._last = time.perf_counter()
        self.idle_wait_s = IDLE_WAIT_S
        #: Frames in a row with no input, no play tick and no new image; from SETTLE_FRAMES on the loop sleeps.
        self.still_frames = 0

    def _load_font(self) -> None:
        import imgui_bundle

        font = Path(imgui_bundle.__file__).resolve().parent / "assets" / "fonts" / FONT
        if font.is_file():
            imgui.get_io().fonts.add_font_from_file_ttf(str(font), FONT_SIZE)

    # --- glfw callbacks ----------------------------------------------------------------------

    def _count_events(self) -> None:
        glfw = self.glfw

        def seen(*_: object) -> None:
            self.events += 1

        for install in (
            glfw.set_cursor_pos_callback,
            glfw.set_cursor_enter_callback,
            glfw.set_mouse_button_callback,
            glfw.set_scroll_callback,
            glfw.set_key_callback,
            glfw.set_char_callback,
            glfw.set_window_size_callback,
            glfw.set_framebuffer_size_callback,
            glfw.set_window_focus_callback,
            glfw.set_window_refresh_callback,
            glfw.set_drop_callback,
        ):
            install(self.window, seen)

    def _on_close(self, window: Window) -> None:
        """The window's close button: with unsaved changes, ask first."""
        if self.model.dirty and not self.model.quit_requested:
            self.glfw.set_window_should_close(window, False)
            self.ui.request_quit()

    # --- the viewport's images ------------------------------------------------------------------

    def images(self, request: ViewRequest) -> list[Image]:
        """The traced frame (when there is one) and the preview pass over it, for this frame's viewport."""
        ui, host = self.ui, self.host
        play = ui.play
        scene = play.scene if play is not None else self.model.scene
        view = play.camera_view if play is not None else ui.view.camera()
        traced = False
        if request.mode == "traced" and not request.moving and host.backend is not None:
            if play is not None:
                traced = play.backend is not None and host.texture is not None
            else:
                w, h = request.size
                size = (max(int(w * host.scale), 8), max(int(h * host.scale), 8))
                traced = host.render_view(scene, view, size)
        out: list[Image] = []
        texture = host.texture
        if traced and texture is not None:
            out.append((texture.glo, (0.0, 0.0), (1.0, 1.0)))
        selected = None if play is not None else self.model.selected
        preview = self.preview.render(scene, view, request.size, shaded=not out, selected=selected)
        if play is None or not out:
            out.append((preview.glo, (0.0, 1.0), (1.0, 0.0)))  # a framebuffer texture: row 0 is the bottom
        return out

    # --- the loop ------------------------------------------------------------------------------------

    def frame(self, screenshot: Path | None = None) -> None:
        """Poll input, draw the UI, present; with ``screenshot``, save the finished frame as a PNG first."""
        glfw = self.glfw
        glfw.poll_events()
        self._measure_locked_mouse()
        now = time.perf_counter()
        dt, self._last = min(now - self._last, 0.25), now
        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        self.ui.safe_draw(dt)
        imgui.render()
        self.ctx.screen.use()
        width, height = glfw.get_framebuffer_size(self.window)
        self.ctx.viewport = (0, 0, width, height)
        self.ctx.clear(0.08, 0.08, 0.1)
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        if screenshot is not None:
            self.save_screenshot(screenshot)
        glfw.swap_buffers(self.window)
        self.last_frame_ms = (time.perf_counter() - now) * 1e3
        self.ui.frame_ms = self.last_frame_ms
        self._sync_window()

    def _measure_locked_mouse(self) -> None:
        """Mouse motion while the cursor is locked (imgui's glfw backend reports no position then)."""
        if not self._captured:
            self.ui.locked_mouse_delta = None
            self._cursor = None
            return
        x, y = self.glfw.get_cursor_pos(self.window)
        last = self._cursor
        self._cursor = (x, y)
        self.ui.locked_mouse_delta = (0.0, 0.0) if last is None else (x - last[0], y - last[1])

    def _sync_window(self) -> None:
        glfw = self.glfw
        title = self.model.title
        if title != self._title:
            glfw.set_window_title(self.window, title)
            self._title = title
        if self.ui.capture_mouse != self._captured:
            self._captured = self.ui.capture_mouse
            mode = glfw.CURSOR_DISABLED if self._captured else glfw.CURSOR_NORMAL
            glfw.set_input_mode(self.window, glfw.CURSOR, mode)
            if self._captured and glfw.raw_mouse_motion_supported():
                glfw.set_input_mode(self.window, glfw.RAW_MOUSE_MOTION, True)
        if self.model.quit_requested:
            glfw.set_window_should_close(self.window, True)

    def save_screenshot(self, path: Path) -> None:
        """The window's back buffer as a PNG (row 0 = top)."""
        from PIL import Image as PilImage

        width, height = self.glfw.get_framebuffer_size(self.window)
        data = self.ctx.screen.read(viewport=(0, 0, width, height), components=3, alignment=1)
        pixels = np.frombuffer(data, np.uint8).reshape(height, width, 3)[::-1]
        PilImage.fromarray(pixels).save(path)

    def watch_disk(self) -> None:
        """Take the document's file as changed on disk (when unmodified); a reload or its message is drawn."""
        messages = len(self.model.messages)
        if self.disk.poll(playing=self.ui.playing):
            self.ui.reloaded()
        if len(self.model.messages) != messages:
            self.still_frames = 0

    @property
    def busy(self) -> bool:
        """Whether the next frame may look different without new input: play ticks, typing, a drag, a new image."""
        io = imgui.get_io()
        held = any(imgui.is_mouse_down(button) for button in range(3))
        return self.ui.playing or io.want_text_input or held or self.still_frames < SETTLE_FRAMES

    def run(self, frames: int | None = None, screenshot: Path | None = None) -> None:
        """Loop until the window closes, or for ``frames`` iterations (the last drawn and saved to ``screenshot``).

        A still editor sleeps on glfw's event queue and draws nothing until an event arrives (the window keeps
        showing its last frame); the tracer and the preview redraw only when their image would change.
        """
        count = 0
        while not self.glfw.window_should_close(self.window):
            count += 1
            last = frames is not None and count >= frames
            self.watch_disk()
            before = (self.events, self.host.frames, self.host.samples, self.preview.renders)
            if not self.busy:
                self.glfw.wait_events_timeout(self.idle_wait_s)
                if self.events == before[0] and not last:
                    self.still_frames += 1
                    continue
            self.frame(screenshot if last else None)
            still = before == (self.events, self.host.frames, self.host.samples, self.preview.renders)
            self.still_frames = self.still_frames + 1 if still else 0
            if last:
                break

    def close(self) -> None:
        self.ui.close()
        self.preview.release()
        self.host.close()
        imgui.backends.opengl3_shutdown()
        imgui.backends.glfw_shutdown()
        implot.destroy_context(self.plot_context)
        imgui.destroy_context(self.imgui_context)
        self.ctx.release()
        self.glfw.destroy_window(self.window)
        self.glfw.terminate()


def load_target(target: str | Path | Scene | None) -> EditorModel:
    """The model for ``aberrant editor [SCENE|DEMO]``: a scene file, a demo name, a Scene, or a new scene."""
    from demos import build_demo, demo_names
    from engine.scene import Scene
    from engine.scene_file import load_scene

    if target is None:
        return EditorModel()
    if isinstance(target, Scene):
        return EditorModel(target)
    path = Path(target)
    if path.suffix.lower() == ".json" or path.is_file():
        return EditorModel(load_scene(path), path)
    demos = demo_names()
    if str(target) in demos:
        return EditorModel(build_demo(str(target)), demo=str(target))
    raise AberrantError(f"{str(target)!r} is neither a scene file nor a demo (demos: {', '.join(demos)})")


def run_editor(
    target: EditorModel | str | Path | Scene | None = None,
    *,
    backend: str | None = None,
    frames: int | None = None,
    screenshot: str | Path | None = None,
    size: tuple[int, int] = DEFAULT_SIZE,
    watcher: LevelWatcher | None = None,
) -> int:
    """Open the editor on ``target``; returns when its window closes (or after ``frames`` frames).

    The document reloads when its scene file changes on disk (``watcher``: a level module's instead).
    """
    model = target if isinstance(target, EditorModel) else load_target(target)
    window = EditorWindow(model, size=size, backend=backend, watcher=watcher)
    try:
        window.run(frames, Path(screenshot) if screenshot is not None else None)
    finally:
        window.close()
    return 0
