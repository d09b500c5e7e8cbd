"""Dear ImGui with no window: frames driven by hand, with simulated mouse and keyboard.

Tests (and scripts) run the real panels through this: it creates imgui and
ImPlot contexts, gives them a display size and a font atlas (marking the
"renderer" as one that handles textures, so imgui 1.92 never asks for an
upload), and offers ``click(label)``, ``type_text`` and ``press`` built on
the item log of :mod:`editor.panels.widgets`.
"""

from __future__ import annotations

from collections.abc import Callable

from imgui_bundle import imgui, implot

from editor.panels import widgets

Draw = Callable[[float], None]


class HeadlessImgui:
    """One imgui context (plus ImPlot) without a window; :meth:`close` destroys both."""

    def __init__(self, size: tuple[int, int] = (1280, 800), dt: float = 1.0 / 60.0) -> None:
        self.previous = imgui.get_current_context()
        self.context = imgui.create_context()
        imgui.set_current_context(self.context)
        self.plot = implot.create_context()
        implot.set_current_context(self.plot)
        io = imgui.get_io()
        io.display_size = imgui.ImVec2(*size)
        io.set_ini_filename(None)
        io.config_flags |= imgui.ConfigFlags_.docking_enable.value
        io.backend_flags |= imgui.BackendFlags_.renderer_has_textures.value
        self.dt = dt
        self.frames = 0
        widgets.ITEMS.enabled = True
        widgets.ITEMS.rects.clear()

    # --- frames --------------------------------------------------------------------------

    def frame(self, draw: Draw) -> None:
        """One frame: new_frame, ``draw(dt)``, render (the draw data is built and dropped)."""
        imgui.get_io().delta_time = self.dt
        imgui.new_frame()
        draw(self.dt)
        imgui.render()
        self.frames += 1

    def run(self, draw: Draw, n: int) -> None:
        """``n`` frames."""
        for _ in range(n):
            self.frame(draw)

    # --- input ---------------------------------------------------------------------------

    def move(self, x: float, y: float, draw: Draw) -> None:
        imgui.get_io().add_mouse_pos_event(x, y)
        self.frame(draw)

    def click(self, label: str, draw: Draw, button: int = 0, double: bool = False) -> None:
        """Click the widget drawn under ``label`` (KeyError when it was not drawn).

        The mouse follows the widget until it stops moving (a popup centres
        itself in its first frames), then presses and releases.
        """
        x, y = widgets.ITEMS.center(label)
        for _ in range(4):
            self.move(x, y, draw)
            if widgets.ITEMS.center(label) == (x, y):
                break
            x, y = widgets.ITEMS.center(label)
        self.click_at(x, y, draw, button, double)

    def click_at(self, x: float, y: float, draw: Draw, button: int = 0, double: bool = False) -> None:
        io = imgui.get_io()
        self.move(x, y, draw)
        for _ in range(2 if double else 1):
            io.add_mouse_button_event(button, True)
            self.frame(draw)
            io.add_mouse_button_event(button, False)
            self.frame(draw)

    def drag(self, start: tuple[float, float], end: tuple[float, float], draw: Draw, button: int = 0) -> None:
        io = imgui.get_io()
        self.move(*start, draw)
        io.add_mouse_button_event(button, True)
        self.frame(draw)
        steps = 4
        for i in range(1, steps + 1):
            t = i / steps
            io.add_mouse_pos_event(start[0] + (end[0] - start[0]) * t, start[1] + (end[1] - start[1]) * t)
            self.frame(draw)
        io.add_mouse_button_event(button, False)
        self.frame(draw)

    def type_text(self, text: str, draw: Draw) -> None:
        io = imgui.get_io()
        for ch in text:
            io.add_input_character(ord(ch))
        self.frame(draw)

    def press(self, key: imgui.Key, draw: Draw, *, ctrl: bool = False, shift: bool = False) -> None:
        """Press and release ``key`` (with modifiers) over two frames."""
        io = imgui.get_io()
        mods = [(imgui.Key.mod_ctrl, ctrl), (imgui.Key.mod_shift, shift)]
        for mod, held in mods:
            if held:
                io.add_key_event(mod, True)
        io.add_key_event(key, True)
        self.frame(draw)
        io.add_key_event(key, False)
        for mod, held in mods:
            if held:
                io.add_key_event(mod, False)
        self.frame(draw)

    def hold(self, key: imgui.Key, down: bool) -> None:
        imgui.get_io().add_key_event(key, down)

    def close(self) -> None:
        widgets.ITEMS.enabled = False
        widgets.ITEMS.rects.clear()
        implot.destroy_context(self.plot)
        imgui.destroy_context(self.context)
