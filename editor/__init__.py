"""aberrant: editor."""
