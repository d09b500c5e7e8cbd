"""The README's examples run: the level-as-code snippet and the scene file example."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

from components import Aberration, Mesh, Portal
from engine.scene import Scene
from engine.scene_file import load_scene

ROOT = Path(__file__).resolve().parents[2]
KNOT = ROOT / "demos" / "assets" / "knot.obj"


def _block(language: str, containing: str) -> str:
    text = (ROOT / "README.md").read_text()
    for block in re.findall(rf"```{language}\n(.*?)```", text, flags=re.S):
        if containing in block:
            return block
    raise AssertionError(f"README has no {language} block containing {containing!r}")


def _statue_dir(tmp_path: Path) -> Path:
    (tmp_path / "meshes").mkdir()
    shutil.copy(KNOT, tmp_path / "meshes" / "statue.obj")
    return tmp_path


def test_level_as_code_example_builds(tmp_path: Path) -> None:
    namespace: dict[str, object] = {}
    exec(compile(_block("python", "def build()"), "README.md", "exec"), namespace)
    build = namespace["build"]
    assert callable(build)
    scene = build()
    assert isinstance(scene, Scene)
    scene.base_dir = _statue_dir(tmp_path)
    scene.validate()
    assert scene.asset("statue").triangle_count > 100
    assert len(scene.query(Mesh)) == 3
    assert len(scene.query(Aberration)) == 1
    assert len(scene.query(Portal)) == 2


def test_scene_file_example_loads(tmp_path: Path) -> None:
    path = _statue_dir(tmp_path) / "courtyard.json"
    path.write_text(_block("json", '"aberrant-scene"'))
    scene = load_scene(path)
    assert scene.name == "courtyard"
    assert scene.get(scene.entity("door_a"), Portal).target == "door_b"
    assert scene.get(scene.entity("long_hall"), Aberration).deformation == (0.0, 0.0, 1.0)


def test_gallery_shows_every_demo() -> None:
    from demos import demo_names

    text = (ROOT / "README.md").read_text()
    for name in demo_names():
        assert f"docs/gallery/{name}.png" in text, f"README gallery lacks {name}"
        assert (ROOT / "docs" / "gallery" / f"{name}.png").is_file(), f"run `make gallery`: {name}.png missing"
