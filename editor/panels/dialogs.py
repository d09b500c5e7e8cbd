"""Modal dialogs: a small file browser (open, save as, import mesh) and the "unsaved changes" prompt.

The browser is drawn with imgui itself (no native dialog, which may not
exist on a bare Linux box): a folder listing filtered by suffix, a file
name field, OK and Cancel.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from pathlib import Path

from imgui_bundle import imgui

from editor.model import EditorModel
from editor.panels import widgets as ui
from engine.mesh_files import MESH_SUFFIXES

#: Dialog modes: title, suffixes listed, OK button label.
MODES: dict[str, tuple[str, tuple[str, ...], str]] = {
    "open": ("Open scene", (".json",), "Open"),
    "save": ("Save scene as", (".json",), "Save"),
    "import": ("Import mesh", MESH_SUFFIXES, "Import"),
}
PROMPT = "Unsaved changes"


class FileDialog:
    """One modal file browser; :meth:`show` opens it, :meth:`draw` runs it and calls back with the chosen path."""

    def __init__(self) -> None:
        self.mode: str | None = None
        self.folder = Path.cwd()
        self.name = ""
        self._open_next = False
        self.on_choose: Callable[[Path], bool] | None = None

    def show(self, mode: str, folder: Path | None, name: str, on_choose: Callable[[Path], bool]) -> None:
        self.mode = mode
        self.folder = (folder or Path.cwd()).resolve()
        self.name = name
        self.on_choose = on_choose
        self._open_next = True

    def close(self) -> None:
        self.mode = None
        self.on_choose = None

    def entries(self) -> tuple[list[str], list[str]]:
        """Sub-folders and files (with this mode's suffixes) of the current folder, sorted, hidden ones left out."""
        assert self.mode is not None
        suffixes = MODES[self.mode][1]
        folders, files = [], []
        try:
            with os.scandir(self.folder) as listing:
                for entry in listing:
                    if entry.name.startswith("."):
                        continue
                    if entry.is_dir():
                        folders.append(entry.name)
                    elif entry.name.lower().endswith(suffixes):
                        files.append(entry.name)
        except OSError:
            pass
        return sorted(folders, key=str.lower), sorted(files, key=str.lower)

    def draw(self, on_cancel: Callable[[], None] | None = None) -> None:
        if self.mode is None:
            return
        title, _, ok_label = MODES[self.mode]
        popup = f"{title}###file dialog"
        if self._open_next:
            imgui.open_popup(popup)
            self._open_next = False
        imgui.set_next_window_size((560, 420), imgui.Cond_.appearing.value)
        opened, _ = imgui.begin_popup_modal(popup, None)
        if not opened:
            return
        imgui.text_wrapped(str(self.folder))
        folders, files = self.entries()
        if imgui.begin_child("##listing", (0, -70), imgui.ChildFlags_.borders.value):
            if ui.selectable("../", False, imgui.SelectableFlags_.no_auto_close_popups.value):
                self.folder = self.folder.parent
            for folder in folders:
                if ui.selectable(f"{folder}/", False, imgui.SelectableFlags_.no_auto_close_popups.value):
                    self.folder = self.folder / folder
            for file in files:
                flags = (
                    imgui.SelectableFlags_.no_auto_close_popups.value | imgui.SelectableFlags_.allow_double_click.value
                )
                if ui.selectable(file, file == self.name, flags):
                    self.name = file
                    if imgui.is_mouse_double_clicked(0):
                        self._choose()
        imgui.end_child()
        imgui.set_next_item_width(-1)
        entered, self.name = imgui.input_text("##file name", self.name, imgui.InputTextFlags_.enter_returns_true.value)
        ui.ITEMS.note("file name")
        if (ui.button(ok_label, bool(self.name.strip())) or entered) and self.name.strip():
            self._choose()
        imgui.same_line()
        if ui.button("Cancel") or imgui.is_key_pressed(imgui.Key.escape):
            self.close()
            if on_cancel is not None:
                on_cancel()
        if self.mode is None:
            imgui.close_current_popup()
        imgui.end_popup()

    def _choose(self) -> None:
        path = Path(self.name).expanduser()
        if not path.is_absolute():
            path = self.folder / path
        if path.is_dir():
            self.folder, self.name = path.resolve(), ""
            return
        callback = self.on_choose
        if callback is None or callback(path):
            self.close()


def draw_discard_prompt(model: EditorModel) -> None:
    """The modal asking what to do with unsaved changes before the pending action."""
    pending = model.pending
    if pending is None or pending.after_save:
        return
    if not imgui.is_popup_open(PROMPT):
        imgui.open_popup(PROMPT)
    opened, _ = imgui.begin_popup_modal(PROMPT, None, imgui.WindowFlags_.always_auto_resize.value)
    if not opened:
        return
    imgui.text(f"{model.scene.name} has unsaved changes.")
    imgui.text(f"Save them before you {pending.description}?")
    imgui.spacing()
    choice = None
    if ui.button("Save"):
        choice = "save"
    imgui.same_line()
    if ui.button("Discard"):
        choice = "discard"
    imgui.same_line()
    if ui.button("Cancel##prompt") or imgui.is_key_pressed(imgui.Key.escape):
        choice = "cancel"
    if choice is not None:
        imgui.close_current_popup()
        model.resolve_pending(choice)
    imgui.end_popup()
