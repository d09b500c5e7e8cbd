"""Thin wrappers over the imgui widgets the panels use, noting where each labelled item was drawn.

The item log lets a headless test (or a script) find a widget by its label
and click it with simulated mouse input, the way the Dear ImGui test engine
does, without needing a window. Recording costs one dict store per widget
and is off unless :data:`ITEMS` is enabled.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from imgui_bundle import imgui


@dataclass
class ItemLog:
    """Label -> screen rectangle ``(x0, y0, x1, y1)`` of the widgets drawn in the last frames."""

    enabled: bool = False
    rects: dict[str, tuple[float, float, float, float]] = field(default_factory=dict)

    def note(self, label: str) -> None:
        """Remember the last item's rectangle under ``label`` (when enabled; ``"shown###id"`` is noted as ``id``)."""
        if self.enabled:
            label = label.split("###")[-1]
            lo, hi = imgui.get_item_rect_min(), imgui.get_item_rect_max()
            self.rects[label] = (lo.x, lo.y, hi.x, hi.y)

    def center(self, label: str) -> tuple[float, float]:
        x0, y0, x1, y1 = self.rects[label]
        return (x0 + x1) / 2.0, (y0 + y1) / 2.0


#: The process-wide item log (tests enable it).
ITEMS = ItemLog()


def button(label: str, enabled: bool = True) -> bool:
    if not enabled:
        imgui.begin_disabled()
    clicked = imgui.button(label)
    if not enabled:
        imgui.end_disabled()
    ITEMS.note(label)
    return clicked and enabled


def menu_item(label: str, shortcut: str = "", enabled: bool = True, selected: bool = False) -> bool:
    clicked = imgui.menu_item(label, shortcut, selected, enabled)[0]
    ITEMS.note(label)
    return clicked


def begin_menu(label: str, enabled: bool = True) -> bool:
    opened = imgui.begin_menu(label, enabled)
    ITEMS.note(label)
    return opened


def selectable(label: str, selected: bool, flags: int = 0) -> bool:
    clicked = imgui.selectable(label, selected, flags)[0]
    ITEMS.note(label)
    return clicked


def checkbox(label: str, value: bool) -> tuple[bool, bool]:
    changed, value = imgui.checkbox(label, value)
    ITEMS.note(label)
    return changed, value


def radio(label: str, active: bool) -> bool:
    clicked = imgui.radio_button(label, active)
    ITEMS.note(label)
    return clicked


def combo(label: str, current: Any, options: list[Any], labels: list[str] | None = None) -> tuple[bool, Any]:
    """A combo box over ``options`` (shown as ``labels``); returns (picked this frame, the option)."""
    shown = labels or [str(o) for o in options]
    preview = shown[options.index(current)] if current in options else str(current)
    changed, picked = False, current
    opened = imgui.begin_combo(label, preview)
    ITEMS.note(label)
    if opened:
        for option, text in zip(options, shown, strict=True):
            if selectable(f"{text}##{label}", option == current) and option != current:
                changed, picked = True, option
        imgui.end_combo()
    return changed, picked


def tooltip(text: str) -> None:
    """A tooltip on the last item, shown even when the item is disabled."""
    if imgui.is_item_hovered(imgui.HoveredFlags_.allow_when_disabled.value):
        imgui.set_tooltip(text)
