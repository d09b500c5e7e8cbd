"""What the main menu and the viewport need from the editor UI around them, and nothing more.

The other panels take only the model; these two also read the editor's view
and play session and trigger its dialogs and play mode. They depend on this
protocol, not on :class:`editor.ui.EditorUi`, so the UI imports its panels
and no panel imports the UI back.
"""

from __future__ import annotations

from typing import Protocol

from editor.model import EditorModel
from editor.play import PlaySession
from editor.view import EditorView


class EditorShell(Protocol):
    """The model being edited, the editor's view, the play session, and the actions menus and toolbar trigger."""

    model: EditorModel
    view: EditorView
    play: PlaySession | None
    show_help: bool

    @property
    def playing(self) -> bool: ...

    def start_play(self) -> bool: ...

    def stop_play(self) -> None: ...

    def spawn_point(self) -> tuple[float, float, float]: ...

    def focus_selection(self) -> None: ...

    def view_from_camera(self) -> None: ...

    def rename_selection(self) -> None: ...

    def toggle_help(self) -> None: ...

    def show_open_dialog(self) -> None: ...

    def show_save_dialog(self) -> None: ...

    def show_import_dialog(self) -> None: ...

    def request_quit(self) -> None: ...
