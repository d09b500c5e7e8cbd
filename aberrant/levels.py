"""Where a level comes from: a demo name, a scene file or a level module, resolved the same way for every command.

``aberrant render|editor|bench`` take any of:

* a demo name (``aberrant demos`` lists them),
* a scene file, ``level.json`` (its optional ``camera_path`` is the level's flythrough),
* a glTF scene, ``level.gltf`` or ``level.glb`` (:mod:`aberrant.importers.gltf`: node extras carry the components),
* a level module, ``level.py`` or ``level.py:func``: Python that defines
  ``build() -> Scene`` (or the function named after the colon) and optionally
  ``camera_path() -> CameraPath``, e.g. made with :func:`systems.route.route`.

A demo is exactly such a module inside the ``demos`` package. Every mistake
in a level module (no file, no such function, a syntax error, ``build()``
raising or returning something else) is one :class:`LevelError` naming the
file and the function.
"""

from __future__ import annotations

import importlib.util
import itertools
import sys
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType, TracebackType

from engine.errors import AberrantError, shorten
from engine.scene import Scene
from systems.camera_path import CameraPath

#: The function a level module is built by when its name is not given after a colon.
DEFAULT_FUNCTION = "build"
_module_ids = itertools.count()


class LevelError(AberrantError):
    """A level cannot be opened; the one-line message names the file (or demo) and the function."""


@dataclass
class Level:
    """An opened level: its scene, where it came from, and its own camera path when it has one."""

    scene: Scene
    #: How messages name it: ``demo 'house'``, ``my_level.json``, ``my_level.py:build``.
    label: str
    #: ``"demo"``, ``"scene"`` (a scene file) or ``"code"`` (a level module).
    kind: str
    #: The scene file or level module (``None`` for a demo).
    file: Path | None = None
    #: The demo's name (``None`` for files).
    demo: str | None = None
    _path: Callable[[], object] | None = field(default=None, repr=False)

    def camera_path(self) -> CameraPath | None:
        """The level's ``camera_path()``, else the scene's keyframes (a scene file's ``camera_path``), else ``None``."""
        if self._path is not None:
            path = _call(self._path, self._where("camera_path"))
            if not isinstance(path, CameraPath):
                raise LevelError(f"{self._where('camera_path')}() returned {type(path).__name__}, not a CameraPath")
            return path
        if self.scene.camera_path:
            try:
                return CameraPath(self.scene.camera_path)
            except AberrantError as e:
                raise LevelError(f"{self.label}: camera_path: {e}") from None
        return None

    def _where(self, function: str) -> str:
        if self.kind == "demo":
            return f"demo {self.demo!r}: {function}"
        return f"{self.file}:{function}"

    def close(self) -> None:
        self.scene.close()

    def __enter__(self) -> Level:
        return self

    def __exit__(self, kind: type[BaseException] | None, value: BaseException | None, tb: TracebackType | None) -> None:
        self.close()


def split_source(source: str) -> tuple[Path, str] | None:
    """``"dir/level.py:func"`` -> ``(Path("dir/level.py"), "func")``; ``None`` when ``source`` is no ``.py`` level."""
    head, colon, tail = source.rpartition(":")
    if colon and head.lower().endswith(".py") and tail.isidentifier():
        return Path(head), tail
    if source.lower().endswith(".py"):
        return Path(source), DEFAULT_FUNCTION
    return None


def open_level(source: str | Path) -> Level:
    """The level ``source`` names: a scene file (``.json``), a glTF file, a level module (``.py[:func]``) or a demo."""
    from aberrant.importers.gltf import GLTF_SUFFIXES, load_gltf
    from demos import demo_module, demo_modules
    from engine.scene_file import load_scene

    text = str(source)
    code = split_source(text)
    if code is not None:
        return _open_module(*code)
    path = Path(text)
    try:
        is_file = path.is_file()
    except OSError:  # a name too long to be a path, say
        is_file = False
    if path.suffix.lower() in GLTF_SUFFIXES:
        return Level(load_gltf(path), shorten(path), "scene", file=path)
    if path.suffix.lower() == ".json" or is_file:
        return Level(load_scene(path), shorten(path), "scene", file=path)
    modules = demo_modules()
    if text in modules:
        module = demo_module(text)
        scene = module.build()
        return Level(scene, f"demo {text!r}", "demo", demo=text, _path=getattr(module, "camera_path", None))
    raise LevelError(
        f"{shorten(text)!r} is neither a scene file (.json), a level module (.py) nor a demo"
        f" (demos: {', '.join(modules)})"
    )


def _call(function: Callable[[], object], where: str) -> object:
    """``function()``, any exception it raises turned into one line naming ``where`` and the line that raised."""
    try:
        return function()
    except AberrantError as e:
        raise LevelError(f"{where}(): {e}") from None
    except Exception as e:
        frames = traceback.extract_tb(e.__traceback__)
        at = f" (line {frames[-1].lineno} of {Path(frames[-1].filename).name})" if len(frames) > 1 else ""
        raise LevelError(f"{where}() raised {type(e).__name__}: {e}{at}") from None


def load_module(file: Path) -> ModuleType:
    """Execute a level module's file as a fresh module (each call re-reads it); errors name the file."""
    if not file.is_file():
        raise LevelError(f"{file}: {'is a directory' if file.is_dir() else 'level file not found'}")
    name = f"aberrant_level_{next(_module_ids)}_{file.stem}"
    spec = importlib.util.spec_from_file_location(name, file)
    if spec is None or spec.loader is None:  # pragma: no cover - a .py file always has a source loader
        raise LevelError(f"{file}: cannot be loaded as Python")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # dataclasses and pickling look their module up here
    folder = str(file.resolve().parent)
    sys.path.insert(0, folder)  # so a level can import the helper modules beside it
    try:
        spec.loader.exec_module(module)
    except SyntaxError as e:
        sys.modules.pop(name, None)
        raise LevelError(f"{file}: line {e.lineno}: syntax error: {e.msg}") from None
    except Exception as e:
        sys.modules.pop(name, None)
        frames = [f for f in traceback.extract_tb(e.__traceback__) if Path(f.filename) == file.resolve()]
        at = f" (line {frames[-1].lineno})" if frames else ""
        raise LevelError(f"{file}: importing it raised {type(e).__name__}: {e}{at}") from None
    finally:
        if folder in sys.path:
            sys.path.remove(folder)
    return module


def _open_module(file: Path, function: str) -> Level:
    module = load_module(file)
    build = getattr(module, function, None)
    where = f"{file}:{function}"
    if build is None:
        found = sorted(
            k for k, v in vars(module).items() if callable(v) and getattr(v, "__module__", "") == module.__name__
        )
        raise LevelError(f"{file}: no function {function!r} (functions: {', '.join(found) or 'none'})")
    if not callable(build):
        raise LevelError(f"{where}: is a {type(build).__name__}, not a function")
    scene = _call(build, where)
    if not isinstance(scene, Scene):
        raise LevelError(f"{where}() returned {type(scene).__name__}, not a Scene")
    make_path = getattr(module, "camera_path", None)
    return Level(scene, where, "code", file=file, _path=make_path if callable(make_path) else None)
