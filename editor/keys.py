"""The editor's key bindings, one table read by the handlers, the menus and the on-screen help alike.

A binding's label ("Ctrl+Shift+Z / Ctrl+Y") is what it matches: each chord
separated by " / " is modifiers and one key, so the help (F1) and the menus
show exactly the keys the code reacts to. Mouse bindings have no chord; they
are listed for the help only.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

from imgui_bundle import imgui

#: Key words in labels that are not the imgui key's own name (lowercased).
_KEY_NAMES = {"del": "delete", "esc": "escape", "ctrl": "mod_ctrl", "shift": "mod_shift"}
_KEY_NAMES.update({arrow: f"{arrow}_arrow" for arrow in ("up", "down", "left", "right")})
_MODIFIERS = ("ctrl", "shift")


@dataclass(frozen=True)
class Binding:
    """One action: the keys (or mouse gesture) that trigger it and what it does."""

    label: str
    does: str
    mouse: bool = False

    @cached_property
    def chords(self) -> tuple[tuple[frozenset[str], imgui.Key], ...]:
        """``(modifiers, key)`` per chord of the label; a single modifier ("Shift") is its key held."""
        if self.mouse:
            return ()
        chords = []
        for chord in self.label.split(" / "):
            words = [w.strip().lower() for w in chord.split("+")]
            *mods, key = words
            chords.append((frozenset(mods), getattr(imgui.Key, _KEY_NAMES.get(key, key.replace(" ", "_")))))
        return tuple(chords)

    def pressed(self) -> bool:
        """A chord went down this frame with exactly its modifiers held (no key repeat)."""
        io = imgui.get_io()
        held = {name for name, on in zip(_MODIFIERS, (io.key_ctrl, io.key_shift), strict=True) if on}
        return any(mods == held and imgui.is_key_pressed(key, False) for mods, key in self.chords)

    def down(self) -> bool:
        """A chord's key is held (modifiers ignored: movement keys combine with Shift)."""
        return any(imgui.is_key_down(key) for _, key in self.chords)


#: Moving the editor's view in the viewport.
NAVIGATION = {
    "look": Binding("Right mouse drag", "look around (hold it to fly with the keys below)", mouse=True),
    "forward": Binding("W", "fly forward"),
    "back": Binding("S", "fly back"),
    "left": Binding("A", "fly left"),
    "right": Binding("D", "fly right"),
    "up": Binding("E", "fly up"),
    "down": Binding("Q", "fly down"),
    "boost": Binding("Shift", "fly or wheel faster"),
    "wheel": Binding("Mouse wheel", "move forward and back", mouse=True),
    "pan": Binding("Middle mouse drag", "pan", mouse=True),
    "select": Binding("Left click", "select what is under the cursor", mouse=True),
    "focus": Binding("F", "frame the selection"),
}

#: The gizmo on the selection (keys act while the mouse is over the viewport and no button is held).
GIZMO = {
    "translate": Binding("W", "gizmo: move"),
    "rotate": Binding("E", "gizmo: rotate"),
    "scale": Binding("R", "gizmo: scale"),
}

#: Play mode (the played camera, driven by the real systems).
PLAY = {
    "forward": Binding("W", "walk forward"),
    "back": Binding("S", "walk back"),
    "left": Binding("A", "walk left"),
    "right": Binding("D", "walk right"),
    "up": Binding("Space / E", "up"),
    "down": Binding("Q / Left Ctrl", "down"),
    "look": Binding("Mouse", "look around", mouse=True),
    "sprint": Binding("Shift", "sprint"),
    "stop": Binding("Esc", "stop playing"),
}

#: Editor commands, wherever the keyboard focus is (except while typing or playing).
COMMANDS = {
    "undo": Binding("Ctrl+Z", "undo"),
    "redo": Binding("Ctrl+Shift+Z / Ctrl+Y", "redo"),
    "save": Binding("Ctrl+S", "save"),
    "save_as": Binding("Ctrl+Shift+S", "save as"),
    "open": Binding("Ctrl+O", "open a scene file"),
    "new": Binding("Ctrl+N", "new scene"),
    "quit": Binding("Ctrl+Q", "quit"),
    "duplicate": Binding("Ctrl+D", "duplicate the selection"),
    "delete": Binding("Del", "delete the selection"),
    "rename": Binding("F2", "rename the selection"),
    "play": Binding("F5", "play"),
    "help": Binding("F1", "show or hide this help"),
}

#: ``aberrant play``: the player window (keyboard alone is enough: the arrows turn).
PLAYER = {
    "forward": Binding("W / Up", "forward"),
    "back": Binding("S / Down", "back"),
    "left": Binding("A", "step left"),
    "right": Binding("D", "step right"),
    "turn_left": Binding("Left", "turn left"),
    "turn_right": Binding("Right", "turn right"),
    "look_up": Binding("Page Up", "look up"),
    "look_down": Binding("Page Down", "look down"),
    "look": Binding("Mouse", "look around", mouse=True),
    "up": Binding("Space / E", "fly up"),
    "down": Binding("Q / Left Ctrl", "fly down"),
    "sprint": Binding("Shift", "run"),
    "mode": Binding("Tab", "walk or fly"),
    "fullscreen": Binding("F11", "fullscreen or window"),
    "record": Binding("R", "record the camera path; again: stop and save it"),
    "quit": Binding("Esc", "quit"),
}

#: The help overlay's sections, in order.
SECTIONS = {"Navigation": NAVIGATION, "Gizmo": GIZMO, "Play mode": PLAY, "Commands": COMMANDS}


def help_lines() -> list[tuple[str, str]]:
    """``(keys, what they do)`` rows of every section, a section's title as a row with an empty second column."""
    rows: list[tuple[str, str]] = []
    for title, bindings in SECTIONS.items():
        rows.append((title, ""))
        rows.extend((b.label, b.does) for b in bindings.values())
    return rows
