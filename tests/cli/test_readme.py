"""The README's examples run (every Python block on its own, the scene file example) and its Conventions hold."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from components import Aberration, Mesh, Portal, Transform
from engine.scene import Scene
from engine.scene_file import load_scene

ROOT = Path(__file__).resolve().parents[2]
KNOT = ROOT / "demos" / "assets" / "knot.obj"


def _blocks(language: str) -> list[tuple[int, str]]:
    """``(line, code)`` of every fenced ``language`` block of the README, ``line`` the first line of code."""
    text = (ROOT / "README.md").read_text()
    return [
        (text.count("\n", 0, match.start(1)) + 1, match.group(1))
        for match in re.finditer(rf"```{language}\n(.*?)```", text, flags=re.S)
    ]


def _block(language: str, containing: str) -> str:
    for _, block in _blocks(language):
        if containing in block:
            return block
    raise AssertionError(f"README has no {language} block containing {containing!r}")


PYTHON_BLOCKS = _blocks("python")


@pytest.mark.parametrize(("line", "code"), PYTHON_BLOCKS, ids=[f"line-{line}" for line, _ in PYTHON_BLOCKS])
def test_python_block_runs(line: int, code: str, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """Each block alone, in a fresh namespace and an empty folder: the README promises no state between them."""
    monkeypatch.chdir(tmp_path)
    exec(compile("\n" * (line - 1) + code, str(ROOT / "README.md"), "exec"), {"__name__": "__readme__"})


def test_python_api_section_sits_before_the_gallery() -> None:
    text = (ROOT / "README.md").read_text()
    start, end = text.index("## Python API"), text.index("## Gallery")
    assert text.index("make test") < start < end
    assert text[start:end].count("```python\n") >= 4  # render, a headless test, two backends, save and load


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
    assert len(scene.query(Mesh)) == 4
    assert scene.get(scene.entity("sign"), Mesh).texture == "images/sign.png"
    assert scene.get(scene.entity("statue"), Mesh).smooth
    assert len(scene.query(Aberration)) == 1
    assert len(scene.query(Portal)) == 2
    assert scene.get(scene.entity("long_hall"), Aberration).deformation[2] < 0, "a long hall stretches z"
    floor = scene.entity("floor")
    assert scene.get(floor, Mesh).checker * scene.get(floor, Transform).scale[0] == pytest.approx(1.0), "1-unit cells"


def test_scene_file_example_loads(tmp_path: Path) -> None:
    path = _statue_dir(tmp_path) / "courtyard.json"
    path.write_text(_block("json", '"aberrant-scene"'))
    scene = load_scene(path)
    assert scene.name == "courtyard"
    assert scene.get(scene.entity("door_a"), Portal).target == "door_b"
    assert scene.get(scene.entity("long_hall"), Aberration).deformation == (0.0, 0.0, -0.5)


def test_gallery_shows_every_demo() -> None:
    from demos import demo_names

    text = (ROOT / "README.md").read_text()
    for name in demo_names():
        assert f"docs/gallery/{name}.png" in text, f"README gallery lacks {name}"
        assert (ROOT / "docs" / "gallery" / f"{name}.png").is_file(), f"run `make gallery`: {name}.png missing"


def test_conventions_section_holds() -> None:
    """The README's Conventions, checked on the code: quaternion order, the deformation's sign, portal sides, UVs."""
    import numpy as np

    from backends.reference.backend import ReferenceBackend
    from engine.maths import quat_from_euler_deg, rotate
    from systems.app import render_once

    quarter = quat_from_euler_deg((0, 90, 0))
    assert np.allclose(quarter, (0, 0.7071068, 0, 0.7071068))
    assert np.allclose(rotate(quarter, (0, 0, -1)), (-1, 0, 0))

    backend = ReferenceBackend()
    for deformation, inside in (((0, 0, 1), 3.0), ((0, 0, -0.5), 12.0)):
        scene = Scene("sign")
        scene.add_mesh("wall", "box", position=(0, 0, -20), scale=(50, 50, 1))
        scene.add_aberration("box", deformation, position=(0, 0, -8), scale=(4, 4, 6))
        scene.set_camera((0, 0, 0), look_at=(0, 0, -1))
        frame = render_once(scene, backend, size=(9, 9))
        scene.close()
        assert frame.depth[4, 4] == pytest.approx(19.5)  # the wall's near face, 6 of the way inside the box
        assert frame.perceived[4, 4] == pytest.approx(19.5 - 6.0 + inside)

    scene = Scene("sides")
    scene.add_portal_pair("A", "B", a=dict(position=(0, 0, -5)), b=dict(position=(100, 0, 0)))
    behind_b = scene.add_mesh("behind_B", "box", position=(100, 0, -10), scale=(10, 10, 1))
    scene.add_mesh("in_front_of_B", "box", position=(100, 0, 10), scale=(10, 10, 1))
    scene.set_camera((0, 0, 0), look_at=(0, 0, -1))  # in front of A (its +Z side), looking into it
    frame = render_once(scene, backend, size=(9, 9))
    assert frame.instance[4, 4] == behind_b
    assert scene.asset("plane").uvs is not None and scene.asset("sphere").uvs is None
    scene.close()
