"""The window commands, ``editor`` and ``play`` (a display and ``pip install 'aberrant[editor]'``): a level
read from a file is watched and rebuilt when it changes."""

from __future__ import annotations

import argparse
import os
from pathlib import Path
from typing import TYPE_CHECKING

from aberrant.arguments import UsageError, check_target, parse_size
from engine.errors import shorten

if TYPE_CHECKING:
    from aberrant.levels import Level
    from editor.reload import LevelWatcher


def cmd_editor(args: argparse.Namespace) -> int:
    """``editor``: the level editor with play mode (needs a display and ``pip install 'aberrant[editor]'``)."""
    try:
        from editor.model import EditorModel
        from editor.window import EditorUnavailable, display_problem, run_editor
    except ImportError as e:
        raise UsageError(f"the editor needs imgui-bundle and glfw: pip install 'aberrant[editor]' ({e})") from None
    size = parse_size(args.size) if args.size is not None else None
    problem = display_problem()
    if problem is not None:
        raise UsageError(problem)
    from aberrant.levels import open_level

    model = EditorModel()
    watcher = None
    if args.scene is not None:  # a bad file, module or name fails here, before a window opens
        level = open_level(args.scene)
        model = EditorModel(level.scene, level.file if level.kind == "scene" else None, demo=level.demo or level.label)
        watcher = level_watcher(args.scene, level) if level.kind == "code" else None  # a scene file is the model's
    try:
        if size is None:
            return run_editor(model, backend=args.backend, watcher=watcher)
        return run_editor(model, backend=args.backend, size=size, watcher=watcher)
    except EditorUnavailable as e:
        raise UsageError(str(e)) from None


def level_watcher(source: str, level: Level) -> LevelWatcher | None:
    """Hot reload for a level read from a file (a demo has none to watch): rebuilt the way it was opened."""
    from aberrant.levels import open_level
    from editor.reload import LevelWatcher

    if level.file is None:
        return None
    return LevelWatcher(level.file, lambda: open_level(source).scene, level.scene)


def cmd_play(args: argparse.Namespace) -> int:
    """``play``: walk (or fly through) a level in a window with no panels (needs a display and the editor extra)."""
    try:
        from editor.player import DEFAULT_SIZE, run_player
        from editor.window import EditorUnavailable, display_problem
    except ImportError as e:
        raise UsageError(f"the player needs imgui-bundle and glfw: pip install 'aberrant[editor]' ({e})") from None
    size = parse_size(args.size) if args.size is not None else DEFAULT_SIZE
    problem = display_problem("player")
    if problem is not None:
        raise UsageError(problem)
    from aberrant.levels import open_level
    from engine.scene_writer import scene_document

    record = Path(args.record) if args.record else None
    if record is not None:
        if record.suffix.lower() != ".json":
            raise UsageError(f"--record {shorten(record)}: the camera path is saved in a scene file (.json)")
        check_target("--record", record)
    with open_level(args.scene) as level:
        watcher = level_watcher(args.scene, level)
        template = None  # the recording goes into the level's own scene file, as it is on disk then
        if record is not None:
            template = scene_document(level.scene, Path(os.path.abspath(record)).parent)  # before play moves it
        elif level.kind == "scene" and level.file is not None and level.file.suffix.lower() == ".json":
            record = level.file
        try:
            return run_player(
                level.scene, size=size, backend=args.backend, fly=args.fly, frames=args.frames, watcher=watcher,
                record=record, record_template=template,
            )  # fmt: skip
        except EditorUnavailable as e:
            raise UsageError(str(e)) from None
