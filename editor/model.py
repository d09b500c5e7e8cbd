"""The editor's state and every edit it can make, with no imgui in sight (so all of it is testable headless).

:class:`EditorModel` holds the edited scene, its file, the selection and the
undo/redo history. Panels and gizmos never touch the scene directly: every
change is a :class:`editor.commands.Command`, so each one can be undone and
the title can tell whether there are unsaved changes. File operations live
in :mod:`editor.documents` (a mixin), entity creation in :mod:`editor.adding`.
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from components import Portal, ValidationError
from editor.adding import AddingMixin
from editor.commands import (
    Command,
    DeleteOp,
    Op,
    RenameOp,
    SceneNameOp,
    SetOp,
    SettingsOp,
    capture,
)
from editor.documents import DocumentsMixin
from engine.errors import AberrantError
from engine.scene import Scene

#: How many commands undo remembers.
UNDO_LIMIT = 500


@dataclass(frozen=True)
class Message:
    """A line for the status bar: ``level`` is ``"info"`` or ``"error"``."""

    level: str
    text: str


class EditorModel(DocumentsMixin, AddingMixin):
    """The edited scene plus selection, history and file state."""

    def __init__(self, scene: Scene | None = None, path: Path | None = None, *, demo: str | None = None) -> None:
        self.scene: Scene = scene if scene is not None else self.blank_scene()
        self.path: Path | None = Path(path) if path is not None else None
        #: The demo the scene was built from (saving it asks for a file).
        self.demo = demo
        self.selected_name: str | None = None
        self.undo_stack: list[Command] = []
        self.redo_stack: list[Command] = []
        self._open_merge: object | None = None
        self._saved_key: tuple[int, int] | None = None
        self.messages: list[Message] = []
        self.pending: Any = None  # a DocumentsMixin.Pending while the discard prompt is up
        self.quit_requested = False

    # --- messages -----------------------------------------------------------------

    def info(self, text: str) -> None:
        self.messages.append(Message("info", text))

    def error(self, text: str) -> None:
        """Show ``text`` in the status bar and on stderr (the user sees it even if the UI is hidden)."""
        self.messages.append(Message("error", text))
        print(f"aberrant editor: {text}", file=sys.stderr)

    @property
    def last_message(self) -> Message | None:
        return self.messages[-1] if self.messages else None

    # --- title and dirty state -----------------------------------------------------

    def _top_key(self) -> tuple[int, int] | None:
        top = self.undo_stack[-1] if self.undo_stack else None
        return None if top is None else (top.id, top.version)

    @property
    def dirty(self) -> bool:
        """Whether the scene differs from the last save (or open)."""
        return self._top_key() != self._saved_key

    def mark_saved(self) -> None:
        self._saved_key = self._top_key()

    @property
    def title(self) -> str:
        where = self.path.name if self.path is not None else (f"demo {self.demo}" if self.demo else "unsaved")
        return f"{'*' if self.dirty else ''}{self.scene.name} ({where}) - aberrant editor"

    # --- selection ------------------------------------------------------------------

    @property
    def selected(self) -> int | None:
        """The selected entity's id (``None`` when nothing, or something since deleted, is selected)."""
        if self.selected_name is None:
            return None
        try:
            return self.scene.entity(self.selected_name)
        except AberrantError:
            return None

    def select(self, entity: int | None) -> None:
        self.selected_name = None if entity is None else self.scene.name_of(entity)

    # --- history --------------------------------------------------------------------

    def execute(self, command: Command) -> bool:
        """Apply and record ``command``; on a bad value nothing changes and the error is shown."""
        merge = command.merge_key is not None and command.merge_key == self._open_merge and self.undo_stack
        try:
            command.apply(self.scene)
        except (AberrantError, ValidationError) as e:
            self.error(str(e))
            return False
        if merge:
            top = self.undo_stack[-1]
            top.ops = _merged(top.ops, command.ops)
            top.version += 1
        else:
            self.undo_stack.append(command)
            del self.undo_stack[:-UNDO_LIMIT]
            self._open_merge = command.merge_key
        self.redo_stack.clear()
        return True

    def close_merge(self) -> None:
        """End a continuous edit: the next change starts a new undo step."""
        self._open_merge = None

    @property
    def can_undo(self) -> bool:
        return bool(self.undo_stack)

    @property
    def can_redo(self) -> bool:
        return bool(self.redo_stack)

    def undo(self) -> bool:
        if not self.undo_stack:
            return False
        command = self.undo_stack.pop()
        command.revert(self.scene)
        self.redo_stack.append(command)
        self._open_merge = None
        self.info(f"undid {command.label}")
        return True

    def redo(self) -> bool:
        if not self.redo_stack:
            return False
        command = self.redo_stack.pop()
        command.apply(self.scene)
        self.undo_stack.append(command)
        self._open_merge = None
        self.info(f"redid {command.label}")
        return True

    def reset_history(self) -> None:
        self.undo_stack.clear()
        self.redo_stack.clear()
        self._open_merge = None
        self._saved_key = None

    # --- edits ----------------------------------------------------------------------

    def set_component(self, entity: int, component: object, *, merge_key: object | None = None) -> bool:
        """Replace a component of ``entity`` (one undo step, or folded into an open continuous edit)."""
        kind = type(component)
        before = self.scene.try_get(entity, kind)
        if before == component:
            return True
        name = self.scene.name_of(entity)
        label = f"edit {name}.{kind.__name__.lower()}"
        return self.execute(Command(label, [SetOp(name, kind, before, component)], merge_key=merge_key))

    def edit(self, entity: int, kind: type, *, merge_key: object | None = None, **changes: Any) -> str | None:
        """Change fields of a component; returns ``None`` or the validation error (nothing is changed then)."""
        current: Any = self.scene.get(entity, kind)  # whichever component dataclass ``kind`` names
        try:
            updated = dataclasses.replace(current, **changes)
        except ValidationError as e:
            message = f"{self.scene.name_of(entity)}: {kind.__name__.lower()}.{e.field}: {e.message}"
            self.error(message)
            return message
        except (TypeError, ValueError) as e:
            self.error(str(e))
            return str(e)
        return None if self.set_component(entity, updated, merge_key=merge_key) else self.last_error()

    def last_error(self) -> str:
        for message in reversed(self.messages):
            if message.level == "error":
                return message.text
        return "the edit was refused"

    def rename(self, entity: int, new_name: str) -> str | None:
        """Rename an entity (portals that target it follow); returns an error message or ``None``."""
        old = self.scene.name_of(entity)
        new_name = new_name.strip()
        if new_name == old:
            return None
        if not new_name:
            self.error("a name must not be empty")
            return self.last_error()
        affected = tuple((self.scene.name_of(e), p) for e, p in self.scene.query(Portal) if p.target in (old, new_name))
        if not self.execute(Command(f"rename {old} to {new_name}", [RenameOp(old, new_name, affected)])):
            return self.last_error()
        if self.selected_name == old:
            self.selected_name = new_name
        return None

    def delete(self, entity: int) -> bool:
        """Delete an entity; portals that led to it become inert (and come back linked on undo)."""
        name = self.scene.name_of(entity)
        ops: list[Op] = []
        for other, portal in self.scene.query(Portal):
            if portal.target == name and other != entity:
                ops.append(SetOp(self.scene.name_of(other), Portal, portal, dataclasses.replace(portal, target=None)))
        index = self.scene.entities().index(entity)
        ops.append(DeleteOp(capture(self.scene, entity), index))
        done = self.execute(Command(f"delete {name}", ops))
        if done and self.selected_name == name:
            self.selected_name = None
        return done

    def portal_targets(self, entity: int) -> list[str]:
        """Names a portal may lead to: every other portal (``None``, inert, is offered separately)."""
        return [self.scene.name_of(e) for e, _ in self.scene.query(Portal) if e != entity]

    def set_portal_target(self, entity: int, target: str | None) -> str | None:
        """Point a portal at another portal (or at nothing); anything else is refused."""
        if target is not None and target not in self.portal_targets(entity):
            message = f"{target!r} is not another portal; a portal can only lead to a portal"
            self.error(message)
            return message
        return self.edit(entity, Portal, target=target)

    def set_settings(self, *, merge_key: object | None = None, **changes: Any) -> str | None:
        """Change scene-wide settings (background, light, ambient, max events)."""
        before = self.scene.settings
        try:
            after = dataclasses.replace(before, **changes)
        except ValidationError as e:
            self.error(f"settings.{e.field}: {e.message}")
            return self.last_error()
        if after == before:
            return None
        return None if self.execute(Command("edit settings", [SettingsOp(before, after)], merge_key)) else "refused"

    def set_scene_name(self, name: str) -> None:
        name = name.strip()
        if name and name != self.scene.name:
            self.execute(Command("rename scene", [SceneNameOp(self.scene.name, name)]))


def _merged(old: list[Op], new: list[Op]) -> list[Op]:
    """Fold a continuous edit's latest step into the open command: first ``before``, latest ``after``."""
    if len(old) == len(new) == 1:
        a, b = old[0], new[0]
        if isinstance(a, SetOp) and isinstance(b, SetOp) and (a.name, a.kind) == (b.name, b.kind):
            return [SetOp(a.name, a.kind, a.before, b.after)]
        if isinstance(a, SettingsOp) and isinstance(b, SettingsOp):
            return [SettingsOp(a.before, b.after)]
    return [*old, *new]
