"""The scene manager's operations: new, open a file, open a demo, save, save as, and the discard prompt.

Anything that would throw away unsaved changes first becomes a
:class:`Pending` action the UI shows as a modal prompt (save, discard or
cancel). Saving goes through :func:`engine.scene_file.save_scene`, which
writes a temporary file and renames it, so a failed save never damages the
old file.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

from engine.errors import AberrantError
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene
from engine.settings import Settings

if TYPE_CHECKING:
    pass

#: Actions that replace the scene (and so may discard changes).
ACTIONS = ("new", "open", "demo", "quit")


@dataclass(frozen=True)
class Pending:
    """An action waiting for the user to say what to do with unsaved changes."""

    action: str
    arg: str | None = None
    #: True once the user chose "Save" but the scene still needs a file name (the save-as dialog is up).
    after_save: bool = False

    @property
    def description(self) -> str:
        if self.action == "quit":
            return "quit"
        if self.action == "new":
            return "start a new scene"
        return f"open {self.arg}"


class DocumentsMixin:
    """File handling for :class:`editor.model.EditorModel`."""

    scene: Scene
    path: Path | None
    demo: str | None
    selected_name: str | None
    pending: Pending | None
    quit_requested: bool
    if TYPE_CHECKING:

        @property
        def dirty(self) -> bool: ...

        def info(self, text: str) -> None: ...

        def error(self, text: str) -> None: ...

        def mark_saved(self) -> None: ...

        def reset_history(self) -> None: ...

    #: Set when a save needs a file name: the UI opens its save-as dialog and clears it.
    save_as_requested: bool = False
    #: Bumped whenever the scene object is replaced (consumers drop what they cached for the old one).
    generation: int = 0
    #: Bumped by every successful save (a file watcher takes the file it just saw change as the editor's own).
    saves: int = 0

    @staticmethod
    def blank_scene() -> Scene:
        """What "New" gives: a lit, checkered floor and a camera looking at it, ready for the Add menu."""
        scene = Scene("untitled", settings=Settings(background=(0.14, 0.16, 0.21)))
        scene.add_mesh("floor", "plane", scale=(20.0, 1.0, 20.0), color=(0.75, 0.75, 0.72), checker=0.05)
        scene.set_camera((0.0, 2.0, 8.0), look_at=(0.0, 1.0, 0.0))
        return scene

    # --- the discard prompt ------------------------------------------------------------

    def request(self, action: str, arg: str | None = None) -> bool:
        """Do ``action`` now, or (with unsaved changes) raise the prompt; True when it was done."""
        if action not in ACTIONS:
            raise ValueError(f"unknown action {action!r}")
        if self.dirty:
            self.pending = Pending(action, arg)
            return False
        return self.perform(action, arg)

    def resolve_pending(self, choice: str) -> bool:
        """The prompt's answer: ``"save"``, ``"discard"`` or ``"cancel"``; True when the action ran."""
        pending = self.pending
        if pending is None:
            return False
        if choice == "cancel":
            self.pending = None
            return False
        if choice == "save":
            if self.path is None:
                self.pending = Pending(pending.action, pending.arg, after_save=True)
                self.save_as_requested = True
                return False
            if not self.save():
                self.pending = None
                return False
        elif choice != "discard":
            raise ValueError(f"unknown choice {choice!r}")
        self.pending = None
        return self.perform(pending.action, pending.arg)

    def perform(self, action: str, arg: str | None = None) -> bool:
        if action == "new":
            self.replace_scene(self.blank_scene(), None, None)
            self.info("new scene")
            return True
        if action == "open":
            assert arg is not None
            return self.open_path(arg)
        if action == "demo":
            assert arg is not None
            return self.open_demo(arg)
        self.quit_requested = True
        return True

    # --- opening -------------------------------------------------------------------------

    def replace_scene(self, scene: Scene, path: Path | None, demo: str | None) -> None:
        """Swap in another scene (the old one's world is deleted) with a fresh history."""
        old = self.scene
        self.scene = scene
        self.path = path
        self.demo = demo
        self.selected_name = None
        self.reset_history()
        self.mark_saved()
        self.generation += 1
        if old is not scene:
            old.close()
        self.scene.activate()

    def open_path(self, path: str | Path) -> bool:
        """Open a scene file; a file that cannot be read leaves the current scene as it was."""
        try:
            scene = load_scene(path)
        except (AberrantError, OSError) as e:
            self.error(f"cannot open {path}: {e}")
            return False
        self.replace_scene(scene, Path(path), None)
        self.info(f"opened {path}")
        return True

    def reload(self, scene: Scene) -> None:
        """Take ``scene``, the document's file as changed on disk, in place of an unmodified document."""
        selected = self.selected_name
        self.replace_scene(scene, self.path, self.demo)
        self.selected_name = selected  # ``selected`` is None if the new version has no such entity
        self.info(f"reloaded {self.path.name if self.path is not None else scene.name} (changed on disk)")

    def open_demo(self, name: str) -> bool:
        from demos import build_demo

        try:
            scene = build_demo(name)
        except AberrantError as e:
            self.error(f"cannot open demo {name!r}: {e}")
            return False
        self.replace_scene(scene, None, name)
        self.info(f"opened demo {name}")
        return True

    # --- saving --------------------------------------------------------------------------

    def save(self) -> bool:
        """Save to the scene's file; without one, ask the UI for a name (``save_as_requested``)."""
        if self.path is None:
            self.save_as_requested = True
            return False
        return self.save_as(self.path)

    def save_as(self, path: str | Path) -> bool:
        """Save atomically to ``path`` (``.json`` added when missing); finishes a prompt that waited for it."""
        target = Path(path).expanduser()
        if target.suffix.lower() != ".json":
            target = target.with_name(target.name + ".json")
        try:
            save_scene(self.scene, target)
        except (AberrantError, OSError) as e:
            self.error(f"cannot save {target}: {e}")
            return False
        self.path = target
        self.demo = None
        self.save_as_requested = False
        self.mark_saved()
        self.saves += 1
        self.info(f"saved {target}")
        pending = self.pending
        if pending is not None and pending.after_save:
            self.pending = None
            self.perform(pending.action, pending.arg)
        return True

    def cancel_save_as(self) -> None:
        """The save-as dialog was closed: a prompt waiting on it is cancelled too."""
        self.save_as_requested = False
        if self.pending is not None and self.pending.after_save:
            self.pending = None
