"""Checks shared by the component dataclasses.

Every failure raises :class:`ValidationError` carrying the dotted field path,
so scene files, the builder API and the editor can all say *which* field of
*which* entity is wrong.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence, Sized

Vec3 = tuple[float, float, float]
Quat = tuple[float, float, float, float]
Color = tuple[float, float, float]


class ValidationError(ValueError):
    """A component field holds a value the engine cannot use."""

    def __init__(self, field: str, message: str) -> None:
        super().__init__(f"{field}: {message}")
        self.field = field
        self.message = message

    def within(self, prefix: str) -> ValidationError:
        """The same error with its field path nested under ``prefix``."""
        return ValidationError(f"{prefix}.{self.field}" if prefix else self.field, self.message)


def real(value: object, field: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ValidationError(field, f"expected a number, got {type(value).__name__} {value!r}")
    try:
        result = float(value)
    except OverflowError:  # an integer beyond the float range, e.g. 10**400 in a scene file
        raise ValidationError(field, "must be finite, got an integer too large for a float") from None
    if not math.isfinite(result):
        raise ValidationError(field, f"must be finite, got {result}")
    return result


#: The largest scale component, camera speed and world-space size of a mesh the tracers take: sizes and
#: distances then stay inside float32's range (3.4e38; depths are float32, and so are the fast backends'
#: tables) with a margin, and their squares inside float64's. Measured: meshes and aberration boxes
#: scaled 1e36 render alike in every backend; at 1e38 OpenCL misses 55 % of pixels, past 3.4e38 every
#: fast backend does and the reference's depths are infinite; at 1e50 a box's float32 inverse scale is 0.
MAX_MAGNITUDE = 1e36


def at_most(value: float, field: str, what: str) -> float:
    """``value`` when ``|value| <= MAX_MAGNITUDE``, else a :class:`ValidationError` saying why there is a limit."""
    if abs(value) > MAX_MAGNITUDE:
        raise ValidationError(
            field, f"{what} beyond {MAX_MAGNITUDE:g} overflows the tracers' float32 ranges, got {value:g}"
        )
    return value


def vector(value: object, n: int, field: str) -> tuple[float, ...]:
    # Any sized iterable: lists and tuples from scene files and callers, NumPy arrays from the maths.
    if isinstance(value, str | bytes) or not (isinstance(value, Iterable) and isinstance(value, Sized)):
        raise ValidationError(field, f"expected {n} numbers, got {type(value).__name__} {value!r}")
    items = list(value)
    if len(items) != n:
        raise ValidationError(field, f"expected {n} numbers, got {len(items)}")
    return tuple(real(x, f"{field}[{i}]") for i, x in enumerate(items))


def vec3(value: object, field: str) -> Vec3:
    x, y, z = vector(value, 3, field)
    return (x, y, z)


def color(value: object, field: str) -> Color:
    rgb = vec3(value, field)
    for i, c in enumerate(rgb):
        if not 0.0 <= c <= 1.0:
            raise ValidationError(f"{field}[{i}]", f"colour components lie in [0, 1], got {c}")
    return rgb


def unit_quaternion(value: object, field: str, tolerance: float = 1e-4) -> Quat:
    q = vector(value, 4, field)
    norm = math.sqrt(sum(c * c for c in q))
    if abs(norm - 1.0) > tolerance:
        raise ValidationError(
            field, f"quaternion (x, y, z, w) must have unit length, got length {norm:.6g}; normalise it"
        )
    x, y, z, w = q
    return (x, y, z, w)


def choice(value: object, options: Sequence[str], field: str) -> str:
    if not isinstance(value, str) or value not in options:
        raise ValidationError(field, f"must be one of {', '.join(map(repr, options))}, got {value!r}")
    return value


def boolean(value: object, field: str) -> bool:
    if not isinstance(value, bool):
        raise ValidationError(field, f"expected true or false, got {value!r}")
    return value


#: Integers are packed for the tracers as int32.
INT32_RANGE = (-(2**31), 2**31 - 1)


def integer(value: object, field: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise ValidationError(field, f"expected an integer, got {value!r}")
    low, high = INT32_RANGE
    if not low <= value <= high:  # the tracers pack integers as int32
        raise ValidationError(field, f"must lie in [{low}, {high}], got {value}")
    return value
