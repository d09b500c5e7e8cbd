"""The hierarchy: every entity in creation order, to select, rename (double-click or F2), duplicate and delete."""

from __future__ import annotations

from imgui_bundle import imgui

from components import Aberration, Camera, Mesh, Portal
from editor.model import EditorModel
from editor.panels import widgets as ui

#: Swatch colours for entities without a colour of their own.
CAMERA_SWATCH = (0.85, 0.85, 0.85)


def swatch(model: EditorModel, entity: int) -> tuple[tuple[float, float, float], str]:
    """The colour and kind shown in front of an entity's name."""
    scene = model.scene
    kinds: tuple[tuple[type[Aberration | Portal | Mesh], str], ...] = (
        (Aberration, "aberration"),
        (Portal, "portal"),
        (Mesh, "mesh"),
    )
    for kind, label in kinds:
        component = scene.try_get(entity, kind)
        if component is not None:
            return component.color, label
    if scene.has(entity, Camera):
        return CAMERA_SWATCH, "camera"
    return (0.5, 0.5, 0.5), "empty"


class HierarchyPanel:
    """Window "Hierarchy"; keeps the inline-rename state between frames."""

    def __init__(self) -> None:
        self.renaming: str | None = None
        self.buffer = ""
        self.filter = ""
        self._focus_rename = False

    def start_rename(self, model: EditorModel) -> None:
        if model.selected_name is not None:
            self.renaming = model.selected_name
            self.buffer = model.selected_name
            self._focus_rename = True

    def draw(self, model: EditorModel) -> None:
        if imgui.begin("Hierarchy"):
            self._toolbar(model)
            _, self.filter = imgui.input_text_with_hint("##filter", "filter by name", self.filter)
            ui.ITEMS.note("hierarchy filter")
            imgui.separator()
            if imgui.begin_child("##entities"):
                for entity in model.scene.entities():
                    self._row(model, entity)
            imgui.end_child()
        imgui.end()

    def _toolbar(self, model: EditorModel) -> None:
        entity = model.selected
        has = entity is not None
        if ui.button("Rename", has):
            self.start_rename(model)
        imgui.same_line()
        if ui.button("Duplicate", has) and entity is not None:
            model.duplicate(entity)
        imgui.same_line()
        if ui.button("Delete", has) and entity is not None:
            model.delete(entity)

    def _row(self, model: EditorModel, entity: int) -> None:
        name = model.scene.name_of(entity)
        if self.filter and self.filter.lower() not in name.lower():
            return
        color, kind = swatch(model, entity)
        flags = imgui.ColorEditFlags_.no_tooltip.value | imgui.ColorEditFlags_.no_picker.value
        imgui.color_button(f"##swatch{entity}", (*color, 1.0), flags, (12, 12))
        imgui.same_line()
        if self.renaming == name:
            self._rename_field(model, entity, name)
            return
        is_camera = entity == model.scene.camera_entity
        label = f"{name}{'  (camera)' if is_camera else ''}##entity{entity}"
        if ui.selectable(label, entity == model.selected, imgui.SelectableFlags_.allow_double_click.value):
            model.select(entity)
            if imgui.is_mouse_double_clicked(0):
                self.start_rename(model)
        ui.ITEMS.note(f"entity {name}")
        if imgui.is_item_hovered():
            imgui.set_tooltip(kind)
        if imgui.begin_popup_context_item(f"##context{entity}"):
            model.select(entity)
            if ui.menu_item("Rename", "F2"):
                self.start_rename(model)
            if ui.menu_item("Duplicate", "Ctrl+D"):
                model.duplicate(entity)
            if ui.menu_item("Delete", "Del"):
                model.delete(entity)
            imgui.end_popup()

    def _rename_field(self, model: EditorModel, entity: int, name: str) -> None:
        if self._focus_rename:
            imgui.set_keyboard_focus_here()
            self._focus_rename = False
        flags = imgui.InputTextFlags_.enter_returns_true.value | imgui.InputTextFlags_.auto_select_all.value
        imgui.set_next_item_width(-1)
        entered, self.buffer = imgui.input_text(f"##rename{entity}", self.buffer, flags)
        ui.ITEMS.note("rename field")
        if entered:
            if model.rename(entity, self.buffer) is None:
                self.renaming = None
        elif imgui.is_key_pressed(imgui.Key.escape) or (imgui.is_item_deactivated() and not entered):
            self.renaming = None
