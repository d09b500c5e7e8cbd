"""Hot reload: watch a level's file and the mesh and texture files it loads; rebuild the scene when one changes.

Display-free so tests drive it on temporary files: :meth:`LevelWatcher.poll`
looks at the files' modification times and sizes at most once every
``period`` seconds of its ``clock`` (no file-watching dependency, nothing
read while nothing changed). A change rebuilds the scene through the
``load`` callable the caller gives (the player and the editor pass the same
opener the command line used, so a scene file and a level module reload
alike). A build that fails leaves :attr:`LevelWatcher.error` set to one line
naming the file and returns nothing: the caller keeps its last good scene,
and the next good save clears the error.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING

from components import Mesh, Transform
from engine.errors import AberrantError
from engine.scene import Scene
from engine.scene_file import load_scene

if TYPE_CHECKING:
    from editor.model import EditorModel

#: Seconds between two looks at the files (a few times a second is quick enough for a save to feel immediate).
POLL_PERIOD_S = 0.25

#: What a file looks like from outside: ``(mtime_ns, size)``, or ``None`` while it is missing.
Stamp = tuple[int, int] | None


def stamp(path: Path) -> Stamp:
    try:
        st = path.stat()
    except OSError:
        return None
    return st.st_mtime_ns, st.st_size


def mesh_files(scene: Scene) -> list[Path]:
    """The files ``scene``'s assets and mesh textures load (primitives have none), each once."""
    files = [scene.asset_path(spec) for spec in scene.assets.values() if spec.path is not None]
    files += [scene.texture_path(mesh.texture) for _, mesh in scene.query(Mesh) if mesh.texture]
    return list(dict.fromkeys(files))


def keep_camera(old: Scene, new: Scene) -> None:
    """Put ``new``'s camera where ``old``'s is now, so a reload does not move the viewer."""
    if old.camera_entity is None or new.camera_entity is None:
        return
    new.set(new.camera_entity, old.get(old.camera_entity, Transform))
    new.euler_deg.pop(new.camera_entity, None)  # the remembered angles described the file's pose, not this one


class LevelWatcher:
    """Watches ``file`` and ``scene``'s mesh files; :meth:`poll` returns a freshly built scene after a change."""

    def __init__(
        self,
        file: str | Path,
        load: Callable[[], Scene],
        scene: Scene,
        *,
        period: float = POLL_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.file = Path(file)
        self.load = load
        self.period = period
        self.clock = clock
        #: One line naming the file while the last change on disk could not be loaded; ``None`` otherwise.
        self.error: str | None = None
        self._next = clock() + period
        self._watch(scene)

    def _watch(self, scene: Scene) -> None:
        self.files = [self.file, *mesh_files(scene)]
        self.stamps = [stamp(f) for f in self.files]

    def changed(self) -> bool:
        """Whether any watched file differs from when it was last looked at (and remember how it is now)."""
        now = [stamp(f) for f in self.files]
        if now == self.stamps:
            return False
        self.stamps = now
        return True

    def rebase(self, scene: Scene | None = None) -> None:
        """Take the files as they are now as seen (after the caller wrote them itself, say)."""
        if scene is not None:
            self._watch(scene)
        else:
            self.stamps = [stamp(f) for f in self.files]

    def due(self) -> bool:
        """Whether a ``period`` has passed since the last look (and start the next one)."""
        now = self.clock()
        if now < self._next:
            return False
        self._next = now + self.period
        return True

    def poll(self) -> Scene | None:
        """The rebuilt scene when a watched file changed since the last look (at most once a ``period``), else None."""
        return self.rebuild() if self.due() and self.changed() else None

    def rebuild(self) -> Scene | None:
        """The level built from the files as they are now and watched from here on; None (and :attr:`error`)
        when that fails."""
        try:
            scene = self.load()
        except (AberrantError, OSError, SyntaxError) as e:
            self.report(e)
            return None
        try:
            for name in scene.assets:  # a broken mesh is the save's error now, not the renderer's later
                scene.asset(name)
        except (AberrantError, OSError) as e:
            scene.close()
            self.report(e)
            return None
        self.error = None
        self._watch(scene)
        return scene

    def report(self, error: BaseException) -> None:
        """Show ``error`` as the reload's one line, naming the file (a level's own errors usually do already)."""
        text = " ".join(str(error).split()) or type(error).__name__
        self.error = text if self.file.name in text else f"{self.file}: {text}"


class DocumentReload:
    """The editor's hot reload: its document follows its file on disk, but never over unsaved edits.

    The file watched is the document's scene file (it follows Open and Save As), else the level module the
    editor was started on (``watcher``). A change while the document has unsaved edits (or while playing)
    only says "changed on disk" in the status line; the reload waits until the document is unmodified again.
    The editor's own saves are not changes.
    """

    def __init__(
        self,
        model: EditorModel,
        watcher: LevelWatcher | None = None,
        *,
        period: float = POLL_PERIOD_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.model = model
        self.watcher = watcher
        self.period = period
        self.clock = clock
        #: The file changed on disk and the document has not taken that version yet.
        self.stale = False
        self._generation = model.generation
        self._saves = model.saves
        self._told = False

    def _follow(self) -> LevelWatcher | None:
        """The watcher for the document's file now (a new one after Open, New or Save As)."""
        model, path = self.model, self.model.path
        if model.generation != self._generation:  # another scene was opened, or a new one started
            self._generation = model.generation
            self.stale = False
            self.watcher = None
        if path is not None and (self.watcher is None or self.watcher.file != path):
            self.watcher = LevelWatcher(
                path, lambda: load_scene(path), model.scene, period=self.period, clock=self.clock
            )
        if model.saves != self._saves:
            self._saves = model.saves
            self.stale = False
            if self.watcher is not None:
                self.watcher.rebase(model.scene)  # the editor wrote it: what is on disk is the document
        return self.watcher

    def poll(self, *, playing: bool = False) -> bool:
        """Look at the files (at most once a ``period``); True when the document was replaced by its new version."""
        watcher = self._follow()
        if watcher is None or not watcher.due():
            return False
        if watcher.changed():
            self.stale, self._told = True, False
        if not self.stale:
            return False
        if self.model.dirty or playing:
            if not self._told:
                self._told = True
                what = "unsaved edits" if self.model.dirty else "play mode"
                self.model.error(f"{watcher.file.name} changed on disk; not reloaded over {what}")
            return False
        self.stale = False
        scene = watcher.rebuild()
        if scene is None:
            self.model.error(f"not reloaded: {watcher.error}")
            return False
        self.model.reload(scene)
        self._generation = self.model.generation
        return True
