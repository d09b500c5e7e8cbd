"""``aberrant play``: a level in a window with no panels, walked (gravity, collision) or flown.

The frame is the tracer's, drawn over the whole window; a line of text over
it gives the frame rate, the backend and the mode. The record key starts and
stops recording the camera as the level's camera path
(:class:`systems.camera_recording.RecordingSession`). Walking is
:class:`systems.walking.Walker`; flying is the tick loop's own camera movement
(:class:`systems.app.App`), which also teleports, uploads and renders. The
keys are :data:`editor.keys.PLAYER`.
"""

from __future__ import annotations

import ctypes
import time
from collections import deque
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from imgui_bundle import imgui  # first: points the glfw module at imgui-bundle's libglfw

from editor.backend_host import BackendHost
from editor.keys import PLAYER
from editor.play import Keys, LiveInput, input_state
from editor.reload import LevelWatcher, keep_camera
from editor.window import PREFERRED_BACKENDS, EditorUnavailable, create_gl_window, display_problem
from engine.errors import AberrantError
from engine.input import NO_INPUT, InputState
from engine.scene import Scene
from systems.app import App
from systems.camera_recording import RecordingSession
from systems.walking import Walker

DEFAULT_SIZE = (1280, 720)
#: Degrees a second the arrow keys turn (and Page Up/Down tilt) the view.
TURN_SPEED = 120.0
#: Fraction of the window's pixels traced (the image is stretched to fit).
SCALE = 0.5
TEXT = (1.0, 0.9, 0.5, 1.0)
ERROR_TEXT = (1.0, 0.45, 0.4, 1.0)
RECORD_TEXT = (1.0, 0.3, 0.3, 1.0)


def player_keys(dt: float, mouse: tuple[float, float]) -> InputState:
    """This frame's movement from :data:`editor.keys.PLAYER`'s keys, the mouse's motion and the turning keys."""
    down = {name: binding.down() for name, binding in PLAYER.items() if not binding.mouse}
    keys = Keys(
        forward=down["forward"], back=down["back"], left=down["left"], right=down["right"],
        up=down["up"], down=down["down"], sprint=down["sprint"], mouse_dx=mouse[0], mouse_dy=mouse[1],
    )  # fmt: skip
    state = input_state(keys)
    turn = (float(down["turn_left"]) - float(down["turn_right"])) * TURN_SPEED * dt
    tilt = (float(down["look_up"]) - float(down["look_down"])) * TURN_SPEED * dt
    look = (state.look[0] + turn, state.look[1] + tilt)
    return InputState(move=state.move, look=look, sprint=state.sprint)


class PlayerWindow:
    """A window playing one scene; :meth:`run` loops until Esc or the window closes."""

    def __init__(
        self,
        scene: Scene,
        *,
        size: tuple[int, int] = DEFAULT_SIZE,
        backend: str | None = None,
        fly: bool = False,
        watcher: LevelWatcher | None = None,
        record: Path | None = None,
        record_template: Mapping[str, Any] | None = None,
    ) -> None:
        """``record``: the scene file the record key saves the camera path into (``record_template``: the
        document saved with it; ``None``: the file's own)."""
        import glfw
        import moderngl

        problem = display_problem("player")
        if problem is not None:
            raise EditorUnavailable(problem)
        if not glfw.init():
            raise EditorUnavailable("the player needs a display: glfw cannot start; try `xvfb-run aberrant play`")
        scene.validate()
        self.glfw = glfw
        self.scene = scene
        self._given = scene  # the caller's to close; scenes swapped in by a reload are the player's
        #: Rebuilds the level when its file or meshes change on disk (None: no hot reload).
        self.watcher = watcher
        self.window = create_gl_window(size, f"aberrant play: {scene.name}")
        glfw.make_context_current(self.window)
        glfw.swap_interval(1)
        try:
            self.ctx = moderngl.create_context()
        except Exception as e:
            glfw.terminate()
            raise EditorUnavailable(f"the player cannot use the window's OpenGL context: {e}") from None
        self.imgui_context = imgui.create_context()
        imgui.get_io().set_ini_filename(None)
        address = ctypes.cast(self.window, ctypes.c_void_p).value
        assert address is not None
        imgui.backends.glfw_init_for_opengl(address, True)
        imgui.backends.opengl3_init("#version 330")
        self.errors: list[str] = []
        self.host = BackendHost(self.ctx, self.errors.append)
        started = self.host.select(backend) if backend is not None else self.host.select_first(PREFERRED_BACKENDS)
        if not started or self.host.backend is None:
            self.close()
            raise EditorUnavailable(self.host.error or "no tracer backend can start here")
        self.input = LiveInput()
        self.app = App(scene, self.host.backend, size=self._trace_size(), aovs=self.host.aovs, input_source=self.input)
        self.walker = Walker.of(scene)
        #: Starting over nothing, the player flies (walking would fall for ever) and says so.
        self.flying = fly or not self.walker.ground_below()
        self.notice = "" if self.flying == fly else "nothing below to stand on: flying"
        self.recording = RecordingSession(scene, record, record_template)
        self.frame_times: deque[float] = deque(maxlen=30)
        self._windowed: tuple[int, int, int, int] | None = None
        self._cursor: tuple[float, float] | None = None
        self._last = time.perf_counter()
        glfw.set_input_mode(self.window, glfw.CURSOR, glfw.CURSOR_DISABLED)

    def reload(self) -> bool:
        """Swap in the level as rebuilt from disk, the camera kept where it is; a broken one leaves an error."""
        scene = self.watcher.poll() if self.watcher is not None else None
        if scene is None:
            return False
        assert self.watcher is not None and self.host.backend is not None
        keep_camera(self.scene, scene)
        try:
            scene.validate()
            app = App(scene, self.host.backend, size=self._trace_size(), aovs=self.host.aovs, input_source=self.input)
        except AberrantError as e:
            scene.close()
            self.watcher.report(e)
            self.scene.activate()
            return False
        old, self.scene = self.scene, scene
        self.notice = self.recording.rebind(scene) or self.notice
        self.app.close()
        self.walker.close()
        self.app, self.walker = app, Walker.of(scene)
        if old is not self._given:
            old.close()
        scene.activate()
        return True

    def _trace_size(self) -> tuple[int, int]:
        w, h = self.glfw.get_framebuffer_size(self.window)
        return max(int(w * SCALE), 8), max(int(h * SCALE), 8)

    def _mouse(self) -> tuple[float, float]:
        x, y = self.glfw.get_cursor_pos(self.window)
        last, self._cursor = self._cursor, (x, y)
        return (0.0, 0.0) if last is None else (x - last[0], y - last[1])

    @property
    def fps(self) -> float:
        return len(self.frame_times) / max(sum(self.frame_times), 1e-9) if self.frame_times else 0.0

    def toggle_fullscreen(self) -> None:
        glfw = self.glfw
        if self._windowed is None:
            monitor = glfw.get_primary_monitor()
            mode = glfw.get_video_mode(monitor) if monitor else None
            if not monitor or mode is None:
                return
            x, y = glfw.get_window_pos(self.window)
            w, h = glfw.get_window_size(self.window)
            self._windowed = (x, y, w, h)
            glfw.set_window_monitor(self.window, monitor, 0, 0, mode.size.width, mode.size.height, mode.refresh_rate)
        else:
            x, y, w, h = self._windowed
            self._windowed = None
            glfw.set_window_monitor(self.window, None, x, y, w, h, 0)

    def frame(self) -> None:
        """Input, one tick (walk or fly, teleport, upload, render), the image and its overlay, present."""
        glfw = self.glfw
        glfw.poll_events()
        now = time.perf_counter()
        dt, self._last = min(now - self._last, 0.1), now
        self.frame_times.append(dt)
        self.reload()
        imgui.backends.opengl3_new_frame()
        imgui.backends.glfw_new_frame()
        imgui.new_frame()
        if PLAYER["quit"].pressed():
            glfw.set_window_should_close(self.window, True)
        if PLAYER["mode"].pressed():
            self.flying, self.notice = not self.flying, ""
            self.walker.vertical_speed = 0.0
        if PLAYER["fullscreen"].pressed():
            self.toggle_fullscreen()
        if PLAYER["record"].pressed():
            self.notice = self.recording.toggle()
        state = player_keys(dt, self._mouse())
        if self.flying:
            self.input.state = state
        else:
            self.input.state = NO_INPUT
            self.walker.step(dt, state)
        self.app.size = self._trace_size()
        frame = self.app.tick(dt)
        self.recording.update(dt)
        if frame is not None:
            self.host.present(frame)
        width, height = glfw.get_framebuffer_size(self.window)
        texture = self.host.texture
        draw = imgui.get_background_draw_list()
        if texture is not None:
            draw.add_image(imgui.ImTextureRef(texture.glo), (0, 0), (width, height), (0.0, 0.0), (1.0, 1.0))
        mode = "fly" if self.flying else "walk"
        text = f"{self.fps:5.1f} fps  {self.host.name}  {mode} ({PLAYER['mode'].label})  {PLAYER['quit'].label} quits"
        draw.add_rect_filled((4, 4), (12 + imgui.calc_text_size(text).x, 26), imgui.get_color_u32((0, 0, 0, 0.55)))
        draw.add_text((8, 6), imgui.get_color_u32(TEXT), text)
        if self.notice:
            draw.add_text((8, 28), imgui.get_color_u32(TEXT), self.notice)
        if self.recording.recording:
            draw.add_text((width - 170, 6), imgui.get_color_u32(RECORD_TEXT), f"REC {self.recording.status()}")
        if self.watcher is not None and self.watcher.error:
            draw.add_text((8, 50), imgui.get_color_u32(ERROR_TEXT), f"not reloaded: {self.watcher.error}")
        imgui.render()
        self.ctx.screen.use()
        self.ctx.viewport = (0, 0, width, height)
        self.ctx.clear(0.0, 0.0, 0.0)
        imgui.backends.opengl3_render_draw_data(imgui.get_draw_data())
        glfw.swap_buffers(self.window)

    def run(self, frames: int | None = None) -> int:
        """Loop until Esc or the window closes (or for ``frames`` frames); the frames drawn."""
        count = 0
        while not self.glfw.window_should_close(self.window) and (frames is None or count < frames):
            self.frame()
            count += 1
        return count

    def close(self) -> None:
        if getattr(self, "recording", None) is not None:
            self.recording.finish()  # closing the window mid-recording keeps what was recorded
        if getattr(self, "app", None) is not None:
            self.app.close()
            self.walker.close()
            if self.scene is not self._given:
                self.scene.close()
        self.host.close()
        imgui.backends.opengl3_shutdown()
        imgui.backends.glfw_shutdown()
        imgui.destroy_context(self.imgui_context)
        self.ctx.release()
        self.glfw.destroy_window(self.window)
        self.glfw.terminate()


def run_player(
    scene: Scene,
    *,
    size: tuple[int, int] = DEFAULT_SIZE,
    backend: str | None = None,
    fly: bool = False,
    frames: int | None = None,
    watcher: LevelWatcher | None = None,
    record: Path | None = None,
    record_template: Mapping[str, Any] | None = None,
) -> int:
    """Play ``scene`` in a window until it is closed (reloading it on a change ``watcher`` sees); returns 0."""
    window = PlayerWindow(
        scene, size=size, backend=backend, fly=fly, watcher=watcher, record=record, record_template=record_template
    )
    try:
        window.run(frames)
    finally:
        window.close()
    return 0
