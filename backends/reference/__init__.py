"""aberrant: backends/reference."""
