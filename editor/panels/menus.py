"""The main menu bar: File (the scene manager), Edit, Add, View and Play."""

from __future__ import annotations

from imgui_bundle import imgui

from demos import demo_names, describe
from editor.keys import COMMANDS, NAVIGATION, PLAY
from editor.panels import widgets as ui
from editor.panels.shell import EditorShell
from editor.panels.viewport import ViewportPanel
from engine.assets import PRIMITIVES


def draw_main_menu(shell: EditorShell, viewport: ViewportPanel) -> None:
    """The menu bar; View switches ``viewport`` between the traced frame and the raster preview."""
    if not imgui.begin_main_menu_bar():
        return
    _file_menu(shell)
    _edit_menu(shell)
    _add_menu(shell)
    _view_menu(shell, viewport)
    if ui.begin_menu("Help"):
        if ui.menu_item("Keys", COMMANDS["help"].label, True, shell.show_help):
            shell.toggle_help()
        imgui.end_menu()
    if shell.playing:
        if ui.menu_item("Stop", PLAY["stop"].label):
            shell.stop_play()
    elif ui.menu_item("Play", COMMANDS["play"].label):
        shell.start_play()
    imgui.end_main_menu_bar()


def _file_menu(shell: EditorShell) -> None:
    if not ui.begin_menu("File"):
        return
    model = shell.model
    editing = not shell.playing
    if ui.menu_item("New", COMMANDS["new"].label, editing):
        model.request("new")
    if ui.menu_item("Open...", COMMANDS["open"].label, editing):
        shell.show_open_dialog()
    if ui.begin_menu("Open demo", editing):
        for name in demo_names():
            if ui.menu_item(f"demo {name}"):
                model.request("demo", name)
            ui.tooltip(describe(name))
        imgui.end_menu()
    imgui.separator()
    if ui.menu_item("Save", COMMANDS["save"].label, editing):
        model.save()
    if ui.menu_item("Save as...", COMMANDS["save_as"].label, editing):
        shell.show_save_dialog()
    imgui.separator()
    if ui.menu_item("Quit", COMMANDS["quit"].label):
        shell.request_quit()
    imgui.end_menu()


def _edit_menu(shell: EditorShell) -> None:
    if not ui.begin_menu("Edit"):
        return
    model = shell.model
    editing = not shell.playing
    top = model.undo_stack[-1].label if model.undo_stack else ""
    after = model.redo_stack[-1].label if model.redo_stack else ""
    if ui.menu_item(f"Undo {top}###Undo", COMMANDS["undo"].label, editing and model.can_undo):
        model.undo()
    if ui.menu_item(f"Redo {after}###Redo", COMMANDS["redo"].label, editing and model.can_redo):
        model.redo()
    imgui.separator()
    entity = model.selected
    has = editing and entity is not None
    if ui.menu_item("Rename##edit", COMMANDS["rename"].label, has):
        shell.rename_selection()
    if ui.menu_item("Duplicate##edit", COMMANDS["duplicate"].label, has) and entity is not None:
        model.duplicate(entity)
    if ui.menu_item("Delete##edit", COMMANDS["delete"].label, has) and entity is not None:
        model.delete(entity)
    imgui.end_menu()


def _add_menu(shell: EditorShell) -> None:
    if not ui.begin_menu("Add", not shell.playing):
        return
    model = shell.model
    spot = shell.spawn_point()
    if ui.begin_menu("Mesh primitive"):
        for primitive in PRIMITIVES:
            if ui.menu_item(primitive):
                model.add_primitive(primitive, spot)
        imgui.end_menu()
    if ui.menu_item("Mesh from file..."):
        shell.show_import_dialog()
    imgui.separator()
    if ui.menu_item("Aberration"):
        model.add_aberration(spot)
    ui.tooltip("a box of compressed or stretched space")
    if ui.menu_item("Portal pair"):
        model.add_portal_pair(spot)
    ui.tooltip("two linked portals")
    if ui.menu_item("Sun"):
        model.add_light("sun", spot)
    ui.tooltip("a light shining along its -Z from the sky, casting shadows through deformed space")
    if ui.menu_item("Point light"):
        model.add_light("point", spot)
    ui.tooltip("a light at a point, fading with the square of the distance")
    imgui.separator()
    label = "Camera to view" if model.scene.camera_entity is not None else "Camera at view"
    if ui.menu_item(label):
        model.add_camera(shell.view.transform())
    ui.tooltip("the scene's camera takes the viewport's position and direction")
    imgui.end_menu()


def _view_menu(shell: EditorShell, viewport: ViewportPanel) -> None:
    if not ui.begin_menu("View"):
        return
    if ui.menu_item("Frame selection", NAVIGATION["focus"].label, shell.model.selected is not None):
        shell.focus_selection()
    if ui.menu_item("View from scene camera", "", shell.model.scene.camera_entity is not None):
        shell.view_from_camera()
    imgui.separator()
    if ui.menu_item("Traced frame", "", True, viewport.mode == "traced"):
        viewport.mode = "traced"
    if ui.menu_item("Raster preview", "", True, viewport.mode == "raster"):
        viewport.mode = "raster"
    if ui.menu_item("Raster while dragging", "", True, viewport.fast_while_moving):
        viewport.fast_while_moving = not viewport.fast_while_moving
    imgui.end_menu()
