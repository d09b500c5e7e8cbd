"""The viewport: the traced frame with the preview lines on top, the gizmo, and the mouse/keyboard controls.

Edit mode: the right mouse button looks around and flies with the keys,
the wheel moves, the middle button pans, a left click selects; the gizmo's
keys pick move, rotate or scale. Play mode: the keys and mouse look drive
the played camera through the real systems. The keys are in
:mod:`editor.keys` (F1 shows them).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from imgui_bundle import imgui, imguizmo

from components import Transform
from editor.gizmo import MODES, OPERATIONS, GizmoSettings, matrix_to_transform, transform_matrix
from editor.keys import GIZMO, NAVIGATION, PLAY
from editor.panels import widgets as ui
from editor.panels.shell import EditorShell
from editor.picking import pick
from editor.play import Keys
from editor.view import column_major, perspective, view_matrix
from engine.space_index import SpaceIndex

gizmo = imguizmo.im_guizmo

#: An image to draw over the viewport: GL texture id, uv of the top-left and bottom-right corners.
Image = tuple[int, tuple[float, float], tuple[float, float]]
#: The gizmo's size as a fraction of the viewport (ImGuizmo's default, 0.1, is small on a large viewport).
GIZMO_SIZE = 0.16
#: Degrees turned per pixel while looking around with the right mouse button.
LOOK_SENSITIVITY = 0.2


@dataclass(frozen=True)
class ViewRequest:
    """What the viewport asks the GL side to draw this frame."""

    size: tuple[int, int]
    mode: str  # "traced" or "raster"
    moving: bool  # the view or the selection is being dragged: raster is enough
    playing: bool


#: Draws the viewport's images for a request (the GL side of the editor); None headless.
ImageSource = Callable[[ViewRequest], list[Image]]


def play_keys(mouse_delta: tuple[float, float] | None = None) -> Keys:
    """This frame's play-mode keys and mouse motion, read from imgui's input state.

    ``mouse_delta`` overrides imgui's: with the cursor locked for mouse look,
    imgui's glfw backend reports no mouse position, so the window measures it.
    """
    io = imgui.get_io()
    if mouse_delta is None:
        valid = io.mouse_delta.x > -1e6 and io.mouse_delta.y > -1e6 and imgui.is_mouse_pos_valid()
        mouse_delta = (io.mouse_delta.x, io.mouse_delta.y) if valid else (0.0, 0.0)
    return Keys(
        forward=PLAY["forward"].down(),
        back=PLAY["back"].down(),
        left=PLAY["left"].down(),
        right=PLAY["right"].down(),
        up=PLAY["up"].down(),
        down=PLAY["down"].down(),
        sprint=PLAY["sprint"].down(),
        mouse_dx=mouse_delta[0],
        mouse_dy=mouse_delta[1],
    )


class ViewportPanel:
    """Window "Viewport"."""

    def __init__(self) -> None:
        self.gizmo = GizmoSettings()
        self.mode = "traced"
        #: Show the raster preview while dragging (the tracer may be too slow to follow).
        self.fast_while_moving = True
        self.size = (640, 480)
        self.origin = (0.0, 0.0)
        self.hovered = False
        self._gizmo_at_press = False
        self._moving = False
        #: Mouse buttons (left, right, middle) pressed inside the viewport and not yet released.
        self._held = [False, False, False]
        self._released = [False, False, False]
        #: The scene's portals and boxes in trees, kept across clicks (a click syncs it: O(changes), not O(N)).
        self.space = SpaceIndex()

    # --- drawing -------------------------------------------------------------------------

    def draw(self, shell: EditorShell, images: ImageSource | None) -> None:
        imgui.push_style_var(imgui.StyleVar_.window_padding.value, (4, 4))
        flags = imgui.WindowFlags_.no_scrollbar | imgui.WindowFlags_.no_scroll_with_mouse | imgui.WindowFlags_.no_move
        visible = imgui.begin("Viewport", None, flags)
        imgui.pop_style_var()
        if visible:
            self._toolbar(shell)
            avail = imgui.get_content_region_avail()
            self.size = (max(int(avail.x), 16), max(int(avail.y), 16))
            pos = imgui.get_cursor_screen_pos()
            self.origin = (pos.x, pos.y)
            request = ViewRequest(self.size, self.mode, self._moving and self.fast_while_moving, shell.playing)
            drawn = images(request) if images is not None else []
            draw_list = imgui.get_window_draw_list()
            corner = (pos.x + self.size[0], pos.y + self.size[1])
            for texture, uv0, uv1 in drawn:
                draw_list.add_image(imgui.ImTextureRef(texture), pos, corner, uv0, uv1)
            if not drawn:
                draw_list.add_rect_filled(pos, corner, imgui.get_color_u32((0.1, 0.1, 0.12, 1.0)))
            imgui.dummy(self.size)  # not an interactive item: ImGuizmo only acts when no item is hovered
            ui.ITEMS.note("viewport")
            mouse = imgui.get_mouse_pos()
            inside = pos.x <= mouse.x < corner[0] and pos.y <= mouse.y < corner[1]
            self.hovered = inside and imgui.is_window_hovered()
            self._track_buttons()
            self._moving = False
            if shell.playing:
                self._overlay_play(shell, pos)
            else:
                self._controls(shell)
                self._gizmo(shell, pos)
                clicked = self._released[0] and not self._gizmo_at_press
                if clicked and imgui.get_io().mouse_drag_max_distance_sqr[0] < 16.0:
                    self._pick(shell)
        imgui.end()

    def _track_buttons(self) -> None:
        """Which buttons went down inside the viewport (a drag that leaves it keeps going)."""
        for button in range(3):
            self._released[button] = False
            if self.hovered and imgui.is_mouse_clicked(button):
                self._held[button] = True
                if button == 0:
                    self._gizmo_at_press = gizmo.is_over() or gizmo.is_using()
            elif self._held[button] and not imgui.is_mouse_down(button):
                self._held[button] = False
                self._released[button] = True

    def _toolbar(self, shell: EditorShell) -> None:
        if shell.playing:
            if ui.button("Stop (Esc)"):
                shell.stop_play()
        elif ui.button("Play"):
            shell.start_play()
        imgui.same_line()
        imgui.begin_disabled(shell.playing)
        for op in OPERATIONS:
            imgui.same_line()
            if ui.radio(op, self.gizmo.operation == op):
                self.gizmo.operation = op
        imgui.same_line()
        imgui.set_next_item_width(80)
        _, self.gizmo.mode = ui.combo("##space", self.gizmo.mode, list(MODES))
        imgui.same_line()
        _, self.gizmo.snap = ui.checkbox("snap", self.gizmo.snap)
        imgui.same_line()
        imgui.set_next_item_width(70)
        changed, step = imgui.drag_float("##step", self.gizmo.step, 0.01, 0.001, 1000.0, "%.3g")
        if changed:
            self.gizmo.steps[self.gizmo.operation] = max(float(step), 1e-3)
        imgui.end_disabled()
        imgui.same_line()
        imgui.set_next_item_width(90)
        _, self.mode = ui.combo("##view mode", self.mode, ["traced", "raster"])
        ui.tooltip("traced: the backend's frame with preview lines; raster: the fast preview only")

    def _overlay_play(self, shell: EditorShell, pos: imgui.ImVec2) -> None:
        session = shell.play
        if session is None:
            return
        stop = PLAY["stop"].label
        text = f"PLAY  {session.elapsed:6.1f} s  WASD move, mouse look, Shift sprint, {stop} stop, F1 keys"
        draw_list = imgui.get_window_draw_list()
        lines = [(text, (1.0, 0.85, 0.3, 1.0))]
        if session.error:
            lines.append((session.error, (1.0, 0.5, 0.45, 1.0)))
        y = pos.y + 6
        for line, color in lines:
            size = imgui.calc_text_size(line)
            backdrop = imgui.get_color_u32((0.0, 0.0, 0.0, 0.55))
            draw_list.add_rect_filled((pos.x + 4, y - 2), (pos.x + 12 + size.x, y + size.y + 2), backdrop, 3.0)
            draw_list.add_text((pos.x + 8, y), imgui.get_color_u32(color), line)
            y += size.y + 6

    # --- edit-mode controls -------------------------------------------------------------------

    def _controls(self, shell: EditorShell) -> None:
        io = imgui.get_io()
        view = shell.view
        if self._held[1]:
            view.look(io.mouse_delta.x * LOOK_SENSITIVITY, -io.mouse_delta.y * LOOK_SENSITIVITY)
            nav = NAVIGATION
            move = (
                float(nav["right"].down()) - float(nav["left"].down()),
                float(nav["up"].down()) - float(nav["down"].down()),
                float(nav["back"].down()) - float(nav["forward"].down()),
            )
            view.fly(move, io.delta_time, boost=nav["boost"].down())
            self._moving = True
        elif self._held[2]:
            scale = 0.01 * max(1.0, float(np.linalg.norm(view.position)) * 0.1)
            view.pan(-io.mouse_delta.x * scale, io.mouse_delta.y * scale)
            self._moving = True
        elif self.hovered and io.mouse_wheel != 0.0:
            view.fly((0.0, 0.0, -1.0), 0.25 * io.mouse_wheel, boost=NAVIGATION["boost"].down())
        if self.hovered and not imgui.is_mouse_down(1) and not io.want_text_input:
            for op, binding in GIZMO.items():
                if binding.pressed():
                    self.gizmo.operation = op
            if NAVIGATION["focus"].pressed():
                shell.focus_selection()

    def _pick(self, shell: EditorShell) -> None:
        mouse = imgui.get_mouse_pos()
        x, y = mouse.x - self.origin[0], mouse.y - self.origin[1]
        origin, direction = shell.view.ray(x, y, *self.size)
        shell.model.select(pick(shell.model.scene, origin, direction, self.space))

    def _gizmo(self, shell: EditorShell, pos: imgui.ImVec2) -> None:
        model = shell.model
        entity = model.selected
        transform = None if entity is None else model.scene.try_get(entity, Transform)
        if entity is None or transform is None:
            return
        gizmo.set_drawlist(imgui.get_window_draw_list())
        gizmo.set_rect(pos.x, pos.y, float(self.size[0]), float(self.size[1]))
        gizmo.set_orthographic(False)
        gizmo.set_gizmo_size_clip_space(GIZMO_SIZE)
        camera = shell.view.camera()
        view16 = gizmo.Matrix16(column_major(view_matrix(camera)))
        proj16 = gizmo.Matrix16(column_major(perspective(camera.fov_deg, self.size[0] / self.size[1])))
        matrix = gizmo.Matrix16(column_major(transform_matrix(transform)))
        op = {"translate": gizmo.OPERATION.translate, "rotate": gizmo.OPERATION.rotate}.get(
            self.gizmo.operation, gizmo.OPERATION.scale
        )
        mode = gizmo.MODE.world if self.gizmo.mode == "world" else gizmo.MODE.local
        snap = gizmo.Matrix3([self.gizmo.step] * 3) if self.gizmo.snap else None
        if gizmo.manipulate(view16, proj16, op, mode, matrix, None, snap):
            m = np.asarray(matrix.values, dtype=np.float64).reshape(4, 4).T
            edited = matrix_to_transform(m, transform, self.gizmo.operation)
            name = model.scene.name_of(entity)
            model.set_component(entity, edited, merge_key=("gizmo", name, self.gizmo.operation))
        if gizmo.is_using():
            self._moving = True
