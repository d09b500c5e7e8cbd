"""The inspector: widgets generated from the selected entity's component dataclass fields.

Each field's annotation picks its widget (``Vec3`` a 3-float drag, ``Color``
a colour picker, ``Quat`` Euler angles in degrees, ``bool`` a checkbox,
``int``/``float`` drags, strings with a fixed set of values a combo);
:data:`FIELD_HINTS` adds speeds, ranges and choices. Every change goes
through the model, so it can be undone; a drag is one undo step. A value
the component refuses (a zero scale, ``D <= -1`` in metric mode) is not
applied, and the inspector says why.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any

import numpy as np
from imgui_bundle import imgui

from components import (
    ABERRATION_EXITS,
    ABERRATION_MODES,
    LIGHT_KINDS,
    Aberration,
    Camera,
    Light,
    Mesh,
    Portal,
    Transform,
)
from editor.model import EditorModel
from editor.panels import widgets as ui
from engine.assets import PRIMITIVES
from engine.maths import quat_from_euler_deg, quat_to_euler_deg

#: Components in the order the inspector shows them.
SECTIONS: tuple[type, ...] = (Transform, Camera, Mesh, Aberration, Portal, Light)
#: The label shown for the inert choice of a portal's target.
NO_TARGET = "(none: inert)"


@dataclass(frozen=True)
class Hint:
    """How to draw one field: drag speed, limits, fixed choices, a friendlier label."""

    speed: float = 0.01
    lo: float = 0.0
    hi: float = 0.0
    choices: tuple[str, ...] = ()
    label: str | None = None
    help: str = ""


FIELD_HINTS: dict[tuple[str, str], Hint] = {
    ("Transform", "position"): Hint(0.05),
    ("Transform", "rotation"): Hint(0.5, label="rotation (deg)", help="Euler X, Y, Z: rotate about X, then Y, then Z"),
    ("Transform", "scale"): Hint(0.02, help="an aberration's size; a portal's half-width and half-height"),
    ("Camera", "fov_deg"): Hint(0.2, 1.0, 179.0, label="fov (deg)"),
    ("Camera", "speed"): Hint(0.05, 0.01, 1000.0, help="perceived walking speed, units per second"),
    ("Mesh", "checker"): Hint(0.005, 0.0, 100.0, help="checker cell size (0: plain colour)"),
    ("Mesh", "texture"): Hint(help="an image file sampled at the mesh's UVs (empty: the asset's own); Enter applies"),
    ("Mesh", "smooth"): Hint(help="shade with vertex normals (the file's, else averaged within the crease angle)"),
    ("Mesh", "crease_deg"): Hint(0.5, 0.0, 180.0, label="crease (deg)", help="edges sharper than this stay hard"),
    ("Aberration", "deformation"): Hint(0.01, help="D per axis; metric: space scale 1 + D (> 0)"),
    ("Aberration", "mode"): Hint(choices=ABERRATION_MODES),
    ("Aberration", "exit"): Hint(choices=ABERRATION_EXITS, help="radial and additive only"),
    ("Aberration", "priority"): Hint(0.05, help="the highest priority wins where boxes overlap"),
    ("Light", "kind"): Hint(choices=LIGHT_KINDS, help="a sun shines along its -Z; a point light from its position"),
    ("Light", "intensity"): Hint(0.05, 0.0, 1e6, help="a point light's falls off as 1/d^2: 9 is a unit sun at 3"),
    ("Light", "range"): Hint(0.05, 0.0, 1e6, help="a point light fades to nothing here (0: no range)"),
    ("Settings", "light_dir"): Hint(0.01, label="light direction", help="the implicit sun's, without Light entities"),
    ("Settings", "ambient"): Hint(0.005, 0.0, 1.0),
    ("Settings", "max_events"): Hint(0.1, 1, 1024, label="max events"),
}


class InspectorPanel:
    """Window "Inspector": the selection's components, or the scene settings when nothing is selected."""

    def __init__(self) -> None:
        #: entity name -> (quaternion, Euler degrees shown): keeps typed angles stable across frames.
        self._euler: dict[str, tuple[tuple[float, ...], list[float]]] = {}
        self.error: str | None = None
        self._name_buffer: tuple[int, str] | None = None

    def draw(self, model: EditorModel) -> None:
        if imgui.begin("Inspector"):
            imgui.push_item_width(-imgui.get_font_size() * 7.5)  # leave room for the labels
            entity = model.selected
            if entity is None:
                self._scene_section(model)
            else:
                self._entity(model, entity)
            if self.error:
                imgui.push_text_wrap_pos(0.0)
                imgui.text_colored((1.0, 0.45, 0.4, 1.0), self.error)
                imgui.pop_text_wrap_pos()
            imgui.pop_item_width()
        imgui.end()

    # --- sections --------------------------------------------------------------------------

    def _entity(self, model: EditorModel, entity: int) -> None:
        name = model.scene.name_of(entity)
        if self._name_buffer is None or self._name_buffer[0] != entity:
            self._name_buffer = (entity, name)
        flags = imgui.InputTextFlags_.enter_returns_true.value
        entered, text = imgui.input_text("name", self._name_buffer[1], flags)
        ui.ITEMS.note("inspector name")
        self._name_buffer = (entity, text)
        if entered:
            self.error = model.rename(entity, text)
            self._name_buffer = (model.selected or entity, model.selected_name or text)
        elif not imgui.is_item_active() and text != name:
            self._name_buffer = (entity, name)
        for kind in SECTIONS:
            component = model.scene.try_get(entity, kind)
            if component is None:
                continue
            flags = imgui.TreeNodeFlags_.default_open.value
            if imgui.collapsing_header(kind.__name__, flags):
                imgui.push_id(kind.__name__)
                for field in dataclasses.fields(component):
                    self._field(model, entity, component, field)
                imgui.pop_id()

    def _scene_section(self, model: EditorModel) -> None:
        imgui.text_disabled("Nothing selected: scene settings")
        entered, text = imgui.input_text("scene name", model.scene.name, imgui.InputTextFlags_.enter_returns_true.value)
        if entered:
            model.set_scene_name(text)
        settings = model.scene.settings
        for field in dataclasses.fields(settings):
            value = getattr(settings, field.name)
            changed, new = self._widget("Settings", field.name, str(field.type), value, [])
            if changed:
                self.error = model.set_settings(merge_key=("settings", field.name), **{field.name: new})

    # --- one field -----------------------------------------------------------------------------

    def _field(self, model: EditorModel, entity: int, component: Any, field: dataclasses.Field) -> None:
        kind = type(component)
        value = getattr(component, field.name)
        name = model.scene.name_of(entity)
        key = (name, kind.__name__, field.name)
        if kind is Transform and field.name == "rotation":
            self._rotation(model, entity, name, value)
            return
        if kind is Portal and field.name == "target":
            options: list[Any] = [None, *model.portal_targets(entity)]
            labels = [NO_TARGET, *options[1:]]
            changed, picked = ui.combo("target", value, options, labels)
            if changed:
                self.error = model.set_portal_target(entity, picked)
            return
        if kind is Light and field.name == "range":
            self._light_range(model, entity, component, key)
            return
        choices: list[str] = []
        if kind is Mesh and field.name == "asset":
            choices = sorted(set(model.scene.assets)) + [p for p in PRIMITIVES if p not in model.scene.assets]
        disabled = kind is Aberration and field.name == "exit" and component.mode == "metric"
        if disabled:
            imgui.begin_disabled()
        changed, new = self._widget(kind.__name__, field.name, str(field.type), value, choices)
        if disabled:
            imgui.end_disabled()
        if changed:
            self.error = model.edit(entity, kind, merge_key=key, **{field.name: new})

    def _light_range(self, model: EditorModel, entity: int, light: Light, key: tuple[str, str, str]) -> None:
        """A point light's range as a number, 0 for none; a sun has none."""
        if light.kind != "point":
            imgui.begin_disabled()
        changed, new = self._widget("Light", "range", "float", light.range or 0.0, [])
        if light.kind != "point":
            imgui.end_disabled()
        if changed:
            self.error = model.edit(entity, Light, merge_key=key, range=float(new) if new > 0.0 else None)

    def _rotation(self, model: EditorModel, entity: int, name: str, rotation: tuple[float, ...]) -> None:
        cached = self._euler.get(name)
        if cached is not None and np.allclose(cached[0], rotation, atol=1e-9):
            euler = cached[1]
        else:
            euler = [round(float(a), 9) + 0.0 for a in quat_to_euler_deg(rotation)]  # no "-0.00"
            self._euler[name] = (tuple(rotation), euler)
        hint = FIELD_HINTS[("Transform", "rotation")]
        changed, new = imgui.drag_float3(hint.label or "rotation", euler, hint.speed, 0.0, 0.0, "%.2f")
        ui.ITEMS.note("Transform.rotation")
        _help(hint)
        if changed:
            q = tuple(float(c) for c in quat_from_euler_deg(new))
            self.error = model.edit(entity, Transform, merge_key=(name, "Transform", "rotation"), rotation=q)
            if self.error is None:
                self._euler[name] = (q, list(new))

    def _widget(self, kind: str, field: str, annotation: str, value: Any, choices: list[str]) -> tuple[bool, Any]:
        """Draw the widget an annotation calls for; returns (changed, new value)."""
        hint = FIELD_HINTS.get((kind, field), Hint())
        label = hint.label or field.replace("_", " ")
        key = f"{kind}.{field}"
        changed, new = False, value
        if hint.choices or choices:
            options = list(hint.choices or choices)
            changed, new = ui.combo(label, value, options)
        elif annotation == "Color":
            changed, rgb = imgui.color_edit3(label, list(value), imgui.ColorEditFlags_.float.value)
            new = tuple(min(1.0, max(0.0, float(c))) for c in rgb)
        elif annotation == "Vec3":
            changed, xyz = imgui.drag_float3(label, list(value), hint.speed, hint.lo, hint.hi, "%.3f")
            new = tuple(float(c) for c in xyz)
        elif annotation == "bool":
            changed, new = ui.checkbox(label, bool(value))
        elif annotation == "int":
            changed, new = imgui.drag_int(label, int(value), hint.speed, int(hint.lo), int(hint.hi))
        elif annotation == "float":
            flags = imgui.SliderFlags_.always_clamp.value if hint.hi > hint.lo else 0
            changed, new = imgui.drag_float(label, float(value), hint.speed, hint.lo, hint.hi, "%.3f", flags)
        else:
            changed, new = imgui.input_text(label, str(value), imgui.InputTextFlags_.enter_returns_true.value)
        ui.ITEMS.note(key)
        _help(hint)
        return changed, new


def _help(hint: Hint) -> None:
    if hint.help:
        ui.tooltip(hint.help)
