"""Where the camera's movement intent comes from: a keyboard and mouse, a script, or nothing.

The camera movement system only sees :class:`InputState` values, polled once
per tick from an :class:`InputSource`; headless runs and tests use
:class:`ScriptedInput`, the editor's play mode its own keyboard/mouse source.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Protocol, runtime_checkable

Vec3 = tuple[float, float, float]


def _finite_tuple(value: Sequence[float], n: int, field: str) -> tuple[float, ...]:
    items = tuple(float(c) for c in value)
    if len(items) != n:
        raise ValueError(f"InputState.{field}: expected {n} numbers, got {len(items)}")
    if not all(math.isfinite(c) for c in items):
        raise ValueError(f"InputState.{field}: must be finite, got {items}")
    return items


@dataclass(frozen=True)
class InputState:
    """One tick of input.

    ``move`` is a direction in the camera's local frame (+x right, +y up,
    -z forward); the movement system normalises it, so only its direction
    counts. ``look`` is ``(yaw_deg, pitch_deg)`` turned this tick: positive
    yaw turns left (about world +Y), positive pitch looks up (about the
    camera's local +X). ``sprint`` multiplies the speed. ``speed``, when
    given, replaces the camera's perceived speed for this tick: scripted
    drivers (camera paths) set the exact step they want without editing the
    Camera component.
    """

    move: Vec3 = (0.0, 0.0, 0.0)
    look: tuple[float, float] = (0.0, 0.0)
    sprint: bool = False
    speed: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "move", _finite_tuple(self.move, 3, "move"))
        object.__setattr__(self, "look", _finite_tuple(self.look, 2, "look"))
        object.__setattr__(self, "sprint", bool(self.sprint))
        if self.speed is not None:
            speed = float(self.speed)
            if not (math.isfinite(speed) and speed >= 0.0):
                raise ValueError(f"InputState.speed: must be a finite number >= 0, got {self.speed!r}")
            object.__setattr__(self, "speed", speed)

    @property
    def idle(self) -> bool:
        """No movement and no look this tick."""
        return not any(self.move) and not any(self.look)


#: The state of a tick without input.
NO_INPUT = InputState()


@runtime_checkable
class InputSource(Protocol):
    """Anything that yields one :class:`InputState` per tick."""

    def poll(self, dt: float) -> InputState:
        """The input for the tick about to run (``dt`` seconds long)."""
        ...


class NoInput:
    """The source of a camera nobody steers (renders, the CLI)."""

    def poll(self, dt: float) -> InputState:
        return NO_INPUT


class ScriptedInput:
    """Input for headless runs: a list with one state per tick, or ``tick_index -> state``.

    After a list ends, or for a ``None`` entry or callable result, there is
    no input, so a script can describe only the ticks that do something.
    """

    def __init__(self, script: Sequence[InputState | None] | Callable[[int], InputState | None]) -> None:
        self._script = script
        self.tick = 0

    def poll(self, dt: float) -> InputState:
        index = self.tick
        self.tick += 1
        if callable(self._script):
            state = self._script(index)
        else:
            state = self._script[index] if index < len(self._script) else None
        return NO_INPUT if state is None else state

    @classmethod
    def repeat(cls, state: InputState, ticks: int) -> ScriptedInput:
        """The same state for ``ticks`` ticks, then nothing."""
        return cls([state] * ticks)
