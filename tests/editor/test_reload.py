"""Hot reload, headless on temporary files: the watcher, the player's camera kept, the editor's unsaved edits kept."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

from aberrant.levels import open_level
from components import Mesh, Transform
from editor.model import EditorModel
from editor.reload import DocumentReload, LevelWatcher, keep_camera
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene


class Clock:
    """A clock the test moves by hand (the watcher looks at most once a period of it)."""

    def __init__(self) -> None:
        self.now = 0.0

    def __call__(self) -> float:
        return self.now

    def tick(self, s: float = 1.0) -> None:
        self.now += s


def touch(path: Path, text: str) -> None:
    """Write ``text`` and move the file's mtime on, so the change is seen however coarse the filesystem clock is."""
    stat = path.stat() if path.exists() else None
    path.write_text(text)
    if stat is not None:
        os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns + 1_000_000_000))


def triangle_obj(path: Path, height: float) -> Path:
    touch(path, f"v 0 0 0\nv 1 0 0\nv 0 {height} 0\nf 1 2 3\n")
    return path


def level_file(tmp_path: Path, box_x: float) -> Path:
    """A scene file with a mesh file beside it and a box at ``box_x``."""
    mesh = tmp_path / "tri.obj"
    if not mesh.exists():
        triangle_obj(mesh, 1.0)
    scene = Scene("reloaded")
    scene.add_asset("tri", path=mesh)
    scene.add_mesh("tri", "tri")
    scene.add_mesh("box", "box", position=(box_x, 0.0, 0.0))
    scene.set_camera((0.0, 1.0, 5.0), look_at=(0.0, 0.0, 0.0))
    path = tmp_path / "level.json"
    old = path.stat() if path.exists() else None
    save_scene(scene, path)
    scene.close()
    if old is not None:
        os.utime(path, ns=(old.st_atime_ns, old.st_mtime_ns + 1_000_000_000))
    return path


def box_x(scene: Scene) -> float:
    return float(scene.get(scene.entity("box"), Transform).position[0])


def watcher_for(path: Path, clock: Clock) -> tuple[LevelWatcher, Scene]:
    scene = load_scene(path)
    return LevelWatcher(path, lambda: open_level(path).scene, scene, clock=clock), scene


def test_a_save_reloads_and_the_camera_stays_where_it_is(tmp_path):
    clock = Clock()
    path = level_file(tmp_path, 1.0)
    watcher, scene = watcher_for(path, clock)
    clock.tick()
    assert watcher.poll() is None  # nothing changed
    camera = scene.get(scene.camera_entity, Transform)
    moved = Transform(position=(3.0, 2.0, 1.0), rotation=camera.rotation)
    scene.set(scene.camera_entity, moved)  # the player walked
    level_file(tmp_path, 2.0)
    assert watcher.poll() is None  # not a period since the last look
    clock.tick()
    new = watcher.poll()
    assert new is not None and box_x(new) == 2.0 and watcher.error is None
    keep_camera(scene, new)
    assert new.get(new.camera_entity, Transform) == moved
    clock.tick()
    assert watcher.poll() is None  # seen once, reloaded once
    scene.close()
    new.close()


def test_a_broken_save_keeps_the_last_good_scene_and_fixing_it_reloads(tmp_path):
    clock = Clock()
    path = level_file(tmp_path, 1.0)
    watcher, scene = watcher_for(path, clock)
    good = path.read_text()
    touch(path, good[: len(good) // 2])  # saved half-way: malformed JSON
    clock.tick()
    assert watcher.poll() is None
    assert watcher.error is not None and "level.json" in watcher.error and "\n" not in watcher.error
    clock.tick()
    assert watcher.poll() is None and watcher.error is not None  # still broken, not retried until it changes
    level_file(tmp_path, 4.0)
    clock.tick()
    new = watcher.poll()
    assert new is not None and box_x(new) == 4.0 and watcher.error is None
    scene.close()
    new.close()


def test_a_changed_mesh_file_reloads(tmp_path):
    clock = Clock()
    path = level_file(tmp_path, 1.0)
    watcher, scene = watcher_for(path, clock)
    assert (tmp_path / "tri.obj").resolve() in [f.resolve() for f in watcher.files]
    triangle_obj(tmp_path / "tri.obj", 3.0)
    clock.tick()
    new = watcher.poll()
    assert new is not None
    assert float(new.asset("tri").vertices[:, 1].max()) == pytest.approx(3.0)
    touch(tmp_path / "tri.obj", "this is not a mesh\n")
    clock.tick()
    assert watcher.poll() is None and watcher.error is not None and "tri.obj" in watcher.error
    scene.close()
    new.close()


def test_a_changed_texture_file_reloads_with_the_new_texels(tmp_path):
    from PIL import Image

    clock = Clock()
    image = tmp_path / "paint.png"
    Image.new("RGB", (2, 2), (255, 0, 0)).save(image)
    scene = Scene("textured")
    scene.add_mesh("sign", "quad", texture=str(image))
    scene.set_camera((0.0, 0.0, 3.0))
    path = tmp_path / "level.json"
    save_scene(scene, path)
    scene.close()
    watcher, scene = watcher_for(path, clock)
    assert image.resolve() in [f.resolve() for f in watcher.files]
    Image.new("RGB", (2, 2), (0, 0, 255)).save(image)
    os.utime(image, ns=(image.stat().st_atime_ns, image.stat().st_mtime_ns + 1_000_000_000))
    clock.tick()
    new = watcher.poll()
    assert new is not None
    texture = new.texture(new.get(new.entity("sign"), Mesh))
    assert texture is not None and tuple(texture.pixels[0, 0]) == (0, 0, 255, 255)
    scene.close()
    new.close()


LEVEL = """
from engine.scene import Scene

def build():
    scene = Scene("code")
    scene.add_mesh("box", "box", position=({x}, 0.0, 0.0))
    scene.set_camera((0.0, 1.0, 5.0), look_at=(0.0, 0.0, 0.0))
    return scene
"""


def test_a_level_module_reloads_and_one_that_raises_is_one_line(tmp_path):
    clock = Clock()
    path = tmp_path / "level.py"
    touch(path, LEVEL.format(x=1.0))
    level = open_level(path)
    watcher = LevelWatcher(path, lambda: open_level(path).scene, level.scene, clock=clock)
    touch(path, LEVEL.format(x="1.0 / 0"))
    clock.tick()
    assert watcher.poll() is None
    assert watcher.error is not None and "level.py" in watcher.error and "ZeroDivisionError" in watcher.error
    touch(path, LEVEL.format(x=5.0))
    clock.tick()
    new = watcher.poll()
    assert new is not None and box_x(new) == 5.0 and watcher.error is None
    level.close()
    new.close()


def test_the_editor_reloads_an_unmodified_document_and_keeps_unsaved_edits(tmp_path):
    clock = Clock()
    path = level_file(tmp_path, 1.0)
    model = EditorModel(load_scene(path), path)
    disk = DocumentReload(model, clock=clock)
    clock.tick()
    assert not disk.poll()
    level_file(tmp_path, 2.0)
    clock.tick()
    assert disk.poll() and box_x(model.scene) == 2.0 and not model.dirty
    assert model.last_message is not None and "reloaded" in model.last_message.text

    model.edit(model.scene.entity("box"), Transform, position=(7.0, 0.0, 0.0))  # an unsaved edit
    level_file(tmp_path, 3.0)
    clock.tick()
    assert not disk.poll() and box_x(model.scene) == 7.0
    assert model.last_message is not None and "changed on disk" in model.last_message.text
    clock.tick()
    assert not disk.poll()  # told once, still waiting
    model.undo()  # unmodified again: the version on disk comes in
    clock.tick()
    assert disk.poll() and box_x(model.scene) == 3.0

    model.edit(model.scene.entity("box"), Transform, position=(8.0, 0.0, 0.0))
    assert model.save()
    clock.tick()
    assert not disk.poll() and box_x(model.scene) == 8.0  # its own save is no change on disk
    model.scene.close()
