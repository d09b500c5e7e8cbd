"""An entity's unique, human-readable name."""

from __future__ import annotations

from dataclasses import dataclass

from components.validation import ValidationError


@dataclass(frozen=True)
class Name:
    """Names are how scene files, portal targets and the editor refer to entities."""

    value: str

    def __post_init__(self) -> None:
        if not isinstance(self.value, str) or not self.value.strip():
            raise ValidationError("name", f"expected a non-empty string, got {self.value!r}")
