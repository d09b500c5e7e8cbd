"""The real imgui panels, headless: clicks and keys simulated on an imgui context with no window."""

from __future__ import annotations

from pathlib import Path

import pytest

pytest.importorskip("imgui_bundle", reason="the editor extra is not installed: pip install 'aberrant[editor]'")

from imgui_bundle import imgui

from components import Aberration, Light, Mesh, Portal, Transform
from demos import build_demo
from editor.backend_host import BackendHost
from editor.headless import HeadlessImgui
from editor.model import EditorModel
from editor.panels.widgets import ITEMS
from editor.ui import EditorUi
from engine.scene_file import scene_to_json

KNOT = Path(__file__).resolve().parents[2] / "demos" / "assets" / "knot.obj"


class Harness:
    """An EditorUi on a headless imgui context, with the clicks a user would make."""

    def __init__(self, model: EditorModel) -> None:
        self.gui = HeadlessImgui((1400, 900))
        self.model = model
        self.ui = EditorUi(model, BackendHost(None, model.error))
        self.draw = self.ui.draw
        self.gui.run(self.draw, 3)  # the dock layout settles in the first frames

    def click(self, *labels: str, double: bool = False) -> None:
        for label in labels:
            self.gui.click(label, self.draw, double=double)

    def menu(self, *path: str) -> None:
        """Open the menus along ``path`` and click its last item."""
        for label in path:
            self.gui.click(label, self.draw)

    def type(self, text: str, enter: bool = True) -> None:
        self.gui.type_text(text, self.draw)
        if enter:
            self.gui.press(imgui.Key.enter, self.draw)

    def key(self, key: imgui.Key, **mods: bool) -> None:
        self.gui.press(key, self.draw, **mods)

    def frames(self, n: int = 1) -> None:
        self.gui.run(self.draw, n)

    def close(self) -> None:
        self.ui.close()
        self.gui.close()
        self.model.scene.close()


@pytest.fixture
def h():
    harness = Harness(EditorModel(build_demo("starter"), demo="starter"))
    yield harness
    harness.close()


def names(model: EditorModel) -> list[str]:
    return [model.scene.name_of(e) for e in model.scene.entities()]


def test_add_each_kind_of_entity_from_the_menu(h):
    h.menu("Add", "Mesh primitive", "sphere")
    assert h.model.scene.get(h.model.scene.entity("sphere"), Mesh).asset == "sphere"
    assert h.model.selected_name == "sphere"
    h.menu("Add", "Aberration")
    assert h.model.scene.has(h.model.scene.entity("aberration"), Aberration)
    h.menu("Add", "Portal pair")
    assert h.model.scene.get(h.model.scene.entity("portal_a"), Portal).target == "portal_b"
    h.menu("Add", "Point light")
    assert h.model.scene.get(h.model.scene.entity("lamp"), Light).kind == "point"
    h.frames()
    h.click("Light.shadows")  # the inspector shows the new light's fields
    assert h.model.scene.get(h.model.scene.entity("lamp"), Light).shadows is False
    h.menu("Add", "Sun")
    assert h.model.scene.get(h.model.scene.entity("sun"), Light).kind == "sun"
    h.menu("Add", "Camera to view")
    camera = h.model.scene.get(h.model.scene.camera_entity, Transform)
    assert camera.position == pytest.approx(tuple(h.ui.view.position))
    h.menu("Add", "Mesh from file...")
    assert h.ui.files.mode == "import"
    h.click("file name")
    h.type(str(KNOT))  # Enter in the name field chooses the file
    assert h.ui.files.mode is None
    assert names(h.model)[-1] == "knot_2" and h.model.scene.get(h.model.scene.entity("knot_2"), Mesh).asset == "knot"
    assert h.model.title.startswith("*")


def test_select_edit_undo_redo(h):
    h.click("entity crate")
    crate = h.model.scene.entity("crate")
    assert h.model.selected == crate
    h.menu("Add", "Aberration")  # selects the new box; its inspector shows the Aberration fields
    box = h.model.scene.entity("aberration")
    h.frames()
    h.click("Aberration.debug_draw")
    assert h.model.scene.get(box, Aberration).debug_draw is False
    h.click("Aberration.mode")
    h.click("radial##mode")
    assert h.model.scene.get(box, Aberration).mode == "radial"
    h.key(imgui.Key.z, ctrl=True)
    assert h.model.scene.get(box, Aberration).mode == "metric"
    h.menu("Edit", "Undo")
    assert h.model.scene.get(box, Aberration).debug_draw is True
    h.key(imgui.Key.y, ctrl=True)
    assert h.model.scene.get(box, Aberration).debug_draw is False
    h.menu("Edit", "Redo")
    assert h.model.scene.get(box, Aberration).mode == "radial"


def test_a_dragged_number_is_one_undo_step(h):
    h.click("entity crate")
    crate = h.model.scene.entity("crate")
    before = h.model.scene.get(crate, Transform).position
    steps = len(h.model.undo_stack)
    x0, y0, _, y1 = ITEMS.rects["Mesh.checker"]
    h.gui.drag((x0 + 20, (y0 + y1) / 2), (x0 + 120, (y0 + y1) / 2), h.draw)
    h.frames(2)
    assert h.model.scene.get(crate, Mesh).checker > 0.0
    assert len(h.model.undo_stack) == steps + 1
    h.model.undo()
    assert h.model.scene.get(crate, Mesh).checker == 0.0
    assert h.model.scene.get(crate, Transform).position == before


def test_rename_duplicate_delete_from_the_hierarchy(h):
    h.click("entity ball", double=True)
    assert h.ui.hierarchy.renaming == "ball"
    h.key(imgui.Key.a, ctrl=True)
    h.type("moon")
    assert "moon" in names(h.model) and "ball" not in names(h.model)
    h.click("Duplicate")
    assert names(h.model)[-1] == "moon_2" and h.model.selected_name == "moon_2"
    h.click("Delete")
    assert "moon_2" not in names(h.model)
    h.click("entity crate")
    h.key(imgui.Key.delete)
    assert "crate" not in names(h.model)
    h.key(imgui.Key.z, ctrl=True)
    assert "crate" in names(h.model)


def test_pick_a_portal_target_from_portals_only(h):
    h.menu("Add", "Portal pair")
    h.menu("Add", "Portal pair")
    h.click("entity portal_a")
    h.frames()
    h.click("target")
    offered = {label.split("##")[0] for label in ITEMS.rects if label.endswith("##target")}
    assert offered == {"(none: inert)", "portal_b", "portal_a_2", "portal_b_2"}
    h.click("portal_b_2##target")
    assert h.model.scene.get(h.model.scene.entity("portal_a"), Portal).target == "portal_b_2"
    h.click("target")
    h.click("(none: inert)##target")
    assert h.model.scene.get(h.model.scene.entity("portal_a"), Portal).target is None


def test_save_as_then_reload(h, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    h.menu("Add", "Aberration")
    h.menu("File", "Save")  # a demo has no file yet: the save-as dialog opens
    h.frames()
    assert h.ui.files.mode == "save"
    h.click("file name")
    h.key(imgui.Key.a, ctrl=True)
    h.type("level", enter=False)
    h.click("Save")
    path = tmp_path / "level.json"
    assert path.is_file() and h.model.path == path and not h.model.dirty
    saved = path.read_text()
    assert not h.model.title.startswith("*")
    h.menu("Add", "Mesh primitive", "box")
    h.menu("File", "Open...")
    h.click("level.json")
    h.click("Open")  # unsaved changes: the prompt comes up
    h.frames()
    assert h.model.pending is not None
    h.click("Discard")
    h.frames()
    assert "box" not in names(h.model) and scene_to_json(h.model.scene, tmp_path) == saved


def test_play_then_stop_leaves_the_scene_byte_for_byte(h, tmp_path):
    h.model.save_as(tmp_path / "before.json")
    before = (tmp_path / "before.json").read_bytes()
    h.click("Play")
    assert h.ui.playing
    h.gui.hold(imgui.Key.w, True)
    h.frames(20)
    h.gui.hold(imgui.Key.w, False)
    played = h.ui.play.camera_view.position
    edited = h.model.scene.get(h.model.scene.camera_entity, Transform).position
    assert played[2] < edited[2] - 0.5  # walked forward (the starter camera looks towards -z)
    h.key(imgui.Key.escape)
    assert not h.ui.playing
    h.model.save_as(tmp_path / "after.json")
    assert (tmp_path / "after.json").read_bytes() == before
    assert not h.model.dirty


def test_discard_prompt_on_new(h):
    h.menu("Add", "Aberration")
    h.menu("File", "New")
    h.frames()
    assert h.model.pending is not None
    h.click("Cancel##prompt")
    assert "aberration" in names(h.model) and h.model.pending is None
    h.menu("File", "New")
    h.frames()
    h.click("Discard")
    assert names(h.model) == ["floor", "camera"]


def test_backend_panel_switches_and_reports_failures(h):
    h.ui.host.select("reference")
    h.frames()
    assert h.ui.host.backend is not None and h.ui.host.error is None
    assert not h.ui.host.select("no-such-backend")
    h.frames(2)
    assert "no-such-backend" in h.ui.host.error and h.ui.host.backend is None
    h.click("backend")
    h.click("reference##backend")
    assert h.ui.host.name == "reference" and h.ui.host.error is None


def _screen(h: Harness, point) -> tuple[float, float]:
    """Where a world point appears in the headless viewport."""
    import numpy as np

    from editor.view import perspective, view_matrix

    camera = h.ui.view.camera()
    w, hh = h.ui.viewport.size
    clip = perspective(camera.fov_deg, w / hh) @ view_matrix(camera) @ np.array([*point, 1.0])
    ndc = clip[:3] / clip[3]
    x0, y0 = h.ui.viewport.origin
    return x0 + (ndc[0] + 1) / 2 * w, y0 + (1 - ndc[1]) / 2 * hh


def test_gizmo_drag_is_one_undo_step(h):
    h.click("entity crate")
    crate = h.model.scene.entity("crate")
    before = h.model.scene.get(crate, Transform)
    steps = len(h.model.undo_stack)
    x0, y0 = _screen(h, before.position)
    x1, y1 = _screen(h, (before.position[0] + 1.0, *before.position[1:]))
    length = ((x1 - x0) ** 2 + (y1 - y0) ** 2) ** 0.5
    dx, dy = (x1 - x0) / length, (y1 - y0) / length
    start = (x0 + 20 * dx, y0 + 20 * dy)  # on the gizmo's x arrow
    h.gui.drag(start, (start[0] + 60 * dx, start[1] + 60 * dy), h.draw)
    h.frames(2)
    after = h.model.scene.get(crate, Transform)
    assert after.position[0] > before.position[0] + 0.1
    assert after.position[1:] == before.position[1:]  # only x moved: no float32 noise elsewhere
    assert after.rotation == before.rotation and after.scale == before.scale
    assert len(h.model.undo_stack) == steps + 1 and h.model.selected == crate
    h.key(imgui.Key.z, ctrl=True)
    assert h.model.scene.get(crate, Transform) == before


def test_click_in_the_viewport_selects(h):
    plinth = h.model.scene.get(h.model.scene.entity("plinth"), Transform).position
    h.gui.click_at(*_screen(h, plinth), h.draw)
    assert h.model.selected_name == "plinth"
    x0, y0, x1, y1 = ITEMS.rects["viewport"]
    h.gui.click_at(x0 + 0.15 * (x1 - x0), y0 + 0.95 * (y1 - y0), h.draw)  # the floor, bottom left
    assert h.model.selected_name == "floor"


def test_right_drag_looks_around_without_editing(h):
    yaw = h.ui.view.yaw
    x0, y0, x1, y1 = ITEMS.rects["viewport"]
    h.gui.drag(((x0 + x1) / 2, (y0 + y1) / 2), ((x0 + x1) / 2 + 100, (y0 + y1) / 2), h.draw, button=1)
    assert h.ui.view.yaw != yaw and not h.model.dirty


def test_an_error_in_a_panel_is_reported_not_fatal(h, monkeypatch, capsys):
    imgui.get_io().config_error_recovery_enable_assert = False

    def broken(model):
        imgui.begin("Inspector")
        raise RuntimeError("panel bug")

    monkeypatch.setattr(h.ui.inspector, "draw", broken)
    h.gui.frame(h.ui.safe_draw)
    assert "panel bug" in h.model.last_message.text and h.model.last_message.level == "error"
    monkeypatch.undo()
    h.gui.run(h.ui.safe_draw, 2)  # the next frames are whole again
    h.menu("Add", "Aberration")
    assert "aberration" in names(h.model)
    capsys.readouterr()


def test_f1_and_the_help_menu_show_the_key_table(h):
    from editor.keys import help_lines

    assert not h.ui.show_help
    h.key(imgui.Key.f1)
    assert h.ui.show_help
    h.frames(2)
    h.key(imgui.Key.f1)
    assert not h.ui.show_help
    h.menu("Help", "Keys")
    assert h.ui.show_help
    rows = dict(help_lines())
    assert rows["W"] and rows["Ctrl+Shift+Z / Ctrl+Y"] == "redo" and rows["F1"].startswith("show or hide")


def test_every_key_in_the_help_parses_and_the_handlers_act_on_them(h):
    from editor.keys import GIZMO, SECTIONS

    for bindings in SECTIONS.values():
        for binding in bindings.values():
            assert binding.mouse or binding.chords  # a keyboard label that names no imgui key fails here
    x, y = ITEMS.center("viewport")
    h.gui.move(x, y, h.draw)
    for operation, binding in reversed(GIZMO.items()):
        ((_, key),) = binding.chords
        h.key(key)
        assert h.ui.viewport.gizmo.operation == operation
    before = len(names(h.model))
    h.model.select(h.model.scene.entities()[0])
    h.key(imgui.Key.d, ctrl=True)
    assert len(names(h.model)) == before + 1
    h.key(imgui.Key.z, ctrl=True, shift=False)
    assert len(names(h.model)) == before
    h.key(imgui.Key.z, ctrl=True, shift=True)  # redo, not undo: modifiers match exactly
    assert len(names(h.model)) == before + 1


def test_the_readme_lists_every_key_binding():
    from editor.keys import SECTIONS

    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text(encoding="utf-8")
    section = readme[readme.index("## Editor") :]
    section = section[: section.index("\n## ", 1)]
    for bindings in SECTIONS.values():
        for binding in bindings.values():
            assert f"`{binding.label}` {binding.does}" in section
