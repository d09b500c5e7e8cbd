"""Errors a user can act on. The CLI prints them as one line and exits with status 2."""

from __future__ import annotations

#: The most characters of one user-given value (a name, a path) that a message quotes.
QUOTE_LIMIT = 160


def shorten(value: object, limit: int = QUOTE_LIMIT) -> str:
    """``str(value)``, or its first ``limit`` characters and its length: a message quoting a 200 MB name
    stays one readable line."""
    text = str(value)
    if len(text) <= limit:
        return text
    return f"{text[:limit]}... ({len(text):,} characters)"


class AberrantError(Exception):
    """Base of every error caused by input (files, parameters, arguments), not by a bug."""


class SceneError(AberrantError, ValueError):
    """A scene is inconsistent or one of its values is invalid; names the entity and field."""

    def __init__(self, message: str, *, entity: str | None = None, field: str | None = None) -> None:
        where = ""
        if entity is not None:
            where += f"entity {entity!r}"
        if field is not None:
            where += f"{', ' if where else ''}field {field!r}"
        super().__init__(f"{where}: {message}" if where else message)
        self.entity = entity
        self.field = field
        self.detail = message


class BackendUnavailable(AberrantError, RuntimeError):
    """A tracer backend cannot run here; the message says why and what to install."""


class SceneFileError(AberrantError, ValueError):
    """A scene file cannot be read or saved; the one-line message names file, entity and field."""

    def __init__(
        self,
        file: str,
        message: str,
        *,
        entity: str | None = None,
        field: str | None = None,
        kind: str | None = "entity",
    ) -> None:
        parts = [file]
        if entity is not None:
            parts.append(f"{kind} {entity!r}" if kind else entity)
        if field is not None:
            parts.append(f"field {field!r}")
        super().__init__(": ".join([*parts, message]))
        self.file = file
        self.entity = entity
        self.field = field
        self.kind = kind
        self.detail = message
