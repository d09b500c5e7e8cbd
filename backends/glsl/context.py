"""The GLSL backend's OpenGL context: a headless EGL one made with moderngl (Mesa's llvmpipe here, a GPU's
driver elsewhere), whether one can be made at all (the backend's probe), and whether its renderer is a CPU
rasteriser, which the backend lays its tables out for."""

from __future__ import annotations

from typing import TYPE_CHECKING

if TYPE_CHECKING:  # moderngl is imported lazily: importing this module must not need it
    import moderngl

#: What to install when no OpenGL 4.3 context can be made (Debian names).
INSTALL_HINT = (
    "install Mesa's EGL and OpenGL drivers (apt-get install libegl1 libegl-mesa0 libgl1 libgl1-mesa-dri) "
    "and moderngl (pip install 'aberrant[glsl]')"
)

#: CPU renderers: storage-buffer loads slow enough to keep the tables in images instead.
SOFTWARE_RENDERERS = ("llvmpipe", "softpipe")


def create_context() -> moderngl.Context:
    """A headless OpenGL 4.3 context through EGL."""
    import moderngl

    # moderngl's stub types each of **settings as a dict; they are plain values (backend="egl").
    return moderngl.create_standalone_context(backend="egl", require=430)  # type: ignore[arg-type]


def probe_context() -> str | None:
    """``None`` when a headless OpenGL 4.3 context with compute shaders can be made, else why not."""
    try:
        import moderngl  # noqa: F401
    except ImportError as e:
        return f"moderngl is not installed ({e}); pip install 'aberrant[glsl]'"
    try:
        ctx = create_context()
    except Exception as e:  # glcontext raises plain Exceptions naming the failed EGL call
        return f"no headless OpenGL 4.3 context through EGL ({type(e).__name__}: {e}); {INSTALL_HINT}"
    try:
        if ctx.version_code < 430:
            return f"OpenGL {ctx.version_code / 100:.1f} is too old (compute shaders need 4.3); {INSTALL_HINT}"
    finally:
        ctx.release()
    return None


def is_software(renderer: str) -> bool:
    """Whether ``renderer`` (``GL_RENDERER``) is a CPU rasteriser: storage-buffer loads go one SIMD lane at a
    time there, and the compiler flattens small branches, so rare-case code costs every lane."""
    return any(name in renderer.lower() for name in SOFTWARE_RENDERERS)
