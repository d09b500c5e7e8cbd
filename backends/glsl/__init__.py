"""aberrant: backends/glsl."""
