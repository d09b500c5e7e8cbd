"""The whole editor UI for one frame: dock layout, menus, panels, dialogs, shortcuts, status bar, play mode.

It needs an imgui context but no window: the caller runs ``new_frame()``,
:meth:`EditorUi.draw` and ``render()``. The GL side (textures for the
viewport) comes in as an :data:`editor.panels.viewport.ImageSource`, so
headless tests drive the very same code with simulated input.
"""

from __future__ import annotations

import traceback
from collections.abc import Callable
from pathlib import Path

import numpy as np
from imgui_bundle import imgui, imguizmo

from components import Camera, Mesh, Transform
from editor.backend_host import BackendHost
from editor.keys import COMMANDS, PLAY, help_lines
from editor.model import EditorModel
from editor.panels.backend import draw_backend_panel
from editor.panels.dialogs import FileDialog, draw_discard_prompt
from editor.panels.hierarchy import HierarchyPanel
from editor.panels.inspector import InspectorPanel
from editor.panels.menus import draw_main_menu
from editor.panels.viewport import ImageSource, ViewportPanel, play_keys
from editor.play import PlaySession, input_state
from editor.view import EditorView
from engine.errors import AberrantError

#: How far in front of the view new entities appear.
SPAWN_DISTANCE = 5.0
STATUS_HEIGHT = 24.0
INFO_COLOR = (0.75, 0.8, 0.85, 1.0)
ERROR_COLOR = (1.0, 0.45, 0.4, 1.0)


def initial_view(model: EditorModel) -> EditorView:
    """The view starts where the scene's camera is (or looks at the origin from above and behind)."""
    camera = model.scene.camera_entity
    if camera is not None:
        return EditorView.from_transform(model.scene.get(camera, Transform), model.scene.get(camera, Camera).fov_deg)
    return EditorView(np.array([0.0, 3.0, 8.0]), 0.0, -15.0)


class EditorUi:
    """Panels and the state between frames; owns the play session. The menus and the viewport see it as
    their :class:`editor.panels.shell.EditorShell`."""

    def __init__(self, model: EditorModel, host: BackendHost | None = None, images: ImageSource | None = None) -> None:
        self.model = model
        self.host = host or BackendHost(None, model.error)
        self.images = images
        self.view = initial_view(model)
        self.hierarchy = HierarchyPanel()
        self.inspector = InspectorPanel()
        self.viewport = ViewportPanel()
        self.files = FileDialog()
        self.play: PlaySession | None = None
        self._generation = model.generation
        self._layout_built = False
        #: Read by the window: hide and lock the cursor for mouse look (play mode).
        self.capture_mouse = False
        #: The window's last frame time (UI + preview + trace), shown in the status bar.
        self.frame_ms = 0.0
        #: Set by the window while the cursor is locked: this frame's mouse motion in pixels.
        self.locked_mouse_delta: tuple[float, float] | None = None
        #: The key-binding overlay (F1, Help menu).
        self.show_help = False

    # --- state the panels ask for -------------------------------------------------------------

    @property
    def playing(self) -> bool:
        return self.play is not None

    def spawn_point(self) -> tuple[float, float, float]:
        p = self.view.position - self.view.rotation[:, 2] * SPAWN_DISTANCE
        return (float(p[0]), float(p[1]), float(p[2]))

    def focus_selection(self) -> None:
        entity = self.model.selected
        transform = None if entity is None else self.model.scene.try_get(entity, Transform)
        if transform is None:
            return
        size = float(np.max(np.abs(transform.scale)))
        if entity is not None and self.model.scene.has(entity, Mesh):
            lo, hi = self.model.scene.asset(self.model.scene.get(entity, Mesh).asset).bounds()
            size *= float(np.max(hi - lo))
        self.view.focus(transform.position, 1.5 * size + 1.0)

    def view_from_camera(self) -> None:
        self.view = initial_view(self.model)

    def rename_selection(self) -> None:
        self.hierarchy.start_rename(self.model)

    def toggle_help(self) -> None:
        self.show_help = not self.show_help

    # --- dialogs ------------------------------------------------------------------------------

    def _folder(self) -> Path | None:
        return self.model.path.resolve().parent if self.model.path is not None else None

    def show_open_dialog(self) -> None:
        self.files.show("open", self._folder(), "", self._open_chosen)

    def _open_chosen(self, path: Path) -> bool:
        self.model.request("open", str(path))
        return True

    def show_save_dialog(self) -> None:
        name = self.model.path.name if self.model.path is not None else f"{self.model.scene.name}.json"
        self.files.show("save", self._folder(), name, self.model.save_as)

    def show_import_dialog(self) -> None:
        self.files.show("import", self._folder(), "", self._import_chosen)

    def _import_chosen(self, path: Path) -> bool:
        return self.model.add_mesh_file(str(path), self.spawn_point()) is not None

    def request_quit(self) -> None:
        if self.playing:
            self.stop_play()
        self.model.request("quit")

    # --- play mode ----------------------------------------------------------------------------

    def play_size(self) -> tuple[int, int]:
        w, h = self.viewport.size
        return max(int(w * self.host.scale), 8), max(int(h * self.host.scale), 8)

    def start_play(self) -> bool:
        if self.play is not None:
            return True
        try:
            self.play = PlaySession(self.model.scene, self.host.backend, self.play_size(), self.host.aovs)
        except AberrantError as e:
            self.model.error(f"cannot play: {e}")
            return False
        self.capture_mouse = True
        self.model.info(f"playing: WASD to move, mouse to look, Shift to sprint, {PLAY['stop'].label} to stop")
        return True

    def stop_play(self) -> None:
        if self.play is None:
            return
        self.play.stop()
        self.play = None
        self.capture_mouse = False
        self.host.invalidate()  # the backend holds the played copy's tables now
        self.model.scene.activate()
        self.model.info("stopped: the edited scene is as it was before Play")

    def _step_play(self, dt: float) -> None:
        session = self.play
        if session is None:
            return
        if PLAY["stop"].pressed():
            self.stop_play()
            return
        keys = play_keys(self.locked_mouse_delta)
        session.resize(self.play_size())
        frame = session.step(dt, input_state(keys))
        if frame is not None:
            self.host.present(frame)

    # --- the frame ----------------------------------------------------------------------------

    def safe_draw(self, dt: float) -> None:
        """:meth:`draw`, but an unexpected error becomes a status-bar message instead of closing the editor."""
        state = imgui.internal.ErrorRecoveryState()
        imgui.internal.error_recovery_store_state(state)
        try:
            self.draw(dt)
        except Exception as e:  # a bug in a panel must not lose the user's unsaved level
            imgui.internal.error_recovery_try_to_recover_state(state)
            traceback.print_exc()
            self.model.error(f"internal editor error ({type(e).__name__}: {e}); please report it")

    def draw(self, dt: float) -> None:
        """Everything between ``imgui.new_frame()`` and ``imgui.render()``."""
        imguizmo.im_guizmo.begin_frame()
        if self._generation != self.model.generation:  # another scene was opened
            self._generation = self.model.generation
            self.stop_play()
            self.view = initial_view(self.model)
            self.host.invalidate()
        self._step_play(dt)
        self._status_bar()
        self._dockspace()
        draw_main_menu(self, self.viewport)
        self.hierarchy.draw(self.model)
        self.inspector.draw(self.model)
        draw_backend_panel(self.host, playing=self.playing)
        self.viewport.draw(self, self.images)
        if self.model.save_as_requested and self.files.mode is None:
            self.model.save_as_requested = False
            self.show_save_dialog()
        self.files.draw(on_cancel=self.model.cancel_save_as)
        draw_discard_prompt(self.model)
        self._help_overlay()
        self._shortcuts()
        if not imgui.is_any_item_active() and not imguizmo.im_guizmo.is_using():
            self.model.close_merge()

    def _dockspace(self) -> None:
        dock = imgui.dock_space_over_viewport(0, imgui.get_main_viewport())
        if self._layout_built:
            return
        self._layout_built = True
        internal = imgui.internal
        internal.dock_builder_remove_node(dock)
        internal.dock_builder_add_node(dock, internal.DockNodeFlagsPrivate_.dock_space.value)
        internal.dock_builder_set_node_size(dock, imgui.get_main_viewport().work_size)
        split = internal.dock_builder_split_node
        left = split(dock, imgui.Dir.left, 0.18)
        right = split(left.id_at_opposite_dir, imgui.Dir.right, 0.27)
        backend = split(right.id_at_dir, imgui.Dir.down, 0.4)
        internal.dock_builder_dock_window("Hierarchy", left.id_at_dir)
        internal.dock_builder_dock_window("Inspector", backend.id_at_opposite_dir)
        internal.dock_builder_dock_window("Backend", backend.id_at_dir)
        internal.dock_builder_dock_window("Viewport", right.id_at_opposite_dir)
        internal.dock_builder_finish(dock)

    def reloaded(self) -> None:
        """The model took its file's new version: drop what was cached for the old scene, keep the view."""
        self._generation = self.model.generation
        self.stop_play()
        self.host.invalidate()

    def _status_bar(self) -> None:
        flags = imgui.WindowFlags_.no_scrollbar | imgui.WindowFlags_.no_saved_settings | imgui.WindowFlags_.menu_bar
        viewport = imgui.get_main_viewport()
        opened = imgui.internal.begin_viewport_side_bar("##status", viewport, imgui.Dir.down, STATUS_HEIGHT, flags)
        if opened and imgui.begin_menu_bar():
            message = self.model.last_message  # backend failures are logged here too
            if message is not None:
                imgui.text_colored(ERROR_COLOR if message.level == "error" else INFO_COLOR, message.text)
            if self.frame_ms > 0.0:
                stats = f"frame {self.frame_ms:.1f} ms"
                imgui.same_line(imgui.get_window_width() - imgui.calc_text_size(stats).x - 16.0)
                imgui.text_disabled(stats)
            imgui.end_menu_bar()
        imgui.end()

    def _on_selection(self, action: Callable[[int], object]) -> None:
        if self.model.selected is not None:
            action(self.model.selected)

    def _help_overlay(self) -> None:
        """The key bindings, from the table the handlers use, in a window over the viewport."""
        if not self.show_help:
            return
        viewport = imgui.get_main_viewport()
        imgui.set_next_window_pos(viewport.get_center(), imgui.Cond_.always.value, (0.5, 0.5))
        imgui.set_next_window_bg_alpha(0.9)
        flags = imgui.WindowFlags_.always_auto_resize | imgui.WindowFlags_.no_saved_settings
        opened, keep = imgui.begin("Keys (F1 closes)", True, flags)
        self.show_help = bool(keep)
        if opened and imgui.begin_table("##keys", 2):
            for keys, does in help_lines():
                imgui.table_next_row()
                imgui.table_next_column()
                if does:
                    imgui.text(keys)
                    imgui.table_next_column()
                    imgui.text_disabled(does)
                else:
                    imgui.text_colored(INFO_COLOR, keys)
            imgui.end_table()
        imgui.end()

    def _shortcuts(self) -> None:
        io = imgui.get_io()
        if io.want_text_input:
            return
        if COMMANDS["help"].pressed():
            self.toggle_help()
        if self.playing:
            return
        model = self.model
        actions: dict[str, Callable[[], object]] = {
            "undo": model.undo,
            "redo": model.redo,
            "save": model.save,
            "save_as": self.show_save_dialog,
            "open": self.show_open_dialog,
            "new": lambda: model.request("new"),
            "quit": self.request_quit,
            "duplicate": lambda: self._on_selection(model.duplicate),
            "delete": lambda: self._on_selection(model.delete),
            "rename": self.rename_selection,
            "play": self.start_play,
        }
        for name, action in actions.items():
            if COMMANDS[name].pressed():
                action()
                return

    def close(self) -> None:
        self.stop_play()
