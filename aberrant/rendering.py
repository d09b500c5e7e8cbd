"""One call from a scene to a frame: :func:`render` picks a backend when asked to, renders, and tidies up.

The frame is rendered by :func:`systems.app.render_once`, so a script sees
exactly what the command line's ``aberrant render`` and the editor see: the
same packing, upload and tick.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Sequence
from typing import SupportsIndex, cast

from backends.base import AOVS, Backend, Frame, create_backend
from backends.samples import check_spp
from engine.errors import AberrantError
from engine.records import Precision
from engine.scene import Scene
from systems.app import DEFAULT_SIZE, render_once


def _frame_size(size: object) -> tuple[int, int]:
    """``size`` as ``(width, height)``: two whole numbers of pixels, both positive, or one AberrantError."""
    try:
        first, second = cast("Sequence[object]", size)
        if isinstance(first, bool) or isinstance(second, bool):
            raise TypeError("a bool is not a pixel count")
        width, height = operator.index(cast("SupportsIndex", first)), operator.index(cast("SupportsIndex", second))
    except (TypeError, ValueError):
        raise AberrantError(f"size must be (width, height) in whole pixels, e.g. (640, 480); got {size!r}") from None
    if width <= 0 or height <= 0:
        raise AberrantError(f"size must be positive, got {width}x{height}")
    return width, height


def render(
    scene: Scene,
    backend: Backend | str | None = None,
    size: Sequence[int] = DEFAULT_SIZE,
    aovs: Sequence[str] | str = AOVS,
    *,
    precision: Precision | None = None,
    spp: int = 1,
    log: Callable[[str], object] | None = None,
) -> Frame:
    """Render one frame of ``scene`` from its camera; the frame's AOVs are numpy arrays.

    ``backend`` is a :class:`backends.base.Backend` you opened (used, and left
    open for the next frame), or a name (``reference``, ``glsl``, ``opencl``,
    ``auto``), or ``None`` for ``$ABERRANT_BACKEND`` or ``auto``. As on the
    command line, a backend named here that cannot start raises
    :class:`engine.errors.BackendUnavailable` with the reason (an explicit
    choice is never swapped for another), while ``auto`` says which one it
    chose (to stderr, or to ``log``). A backend opened here is released before
    this returns.
    ``aovs`` names the outputs to trace (one name or several; see ``AOVS``).
    ``spp`` samples a pixel (1 to 256) anti-alias the colour; the other AOVs come from the pixel centre.

    >>> import aberrant
    >>> scene = aberrant.build_demo("starter")
    >>> frame = aberrant.render(scene, "reference", size=(32, 24), aovs=("color", "depth"))
    >>> frame.color.shape, frame.depth.dtype.name
    ((24, 32, 4), 'float32')
    >>> scene.close()
    """
    width, height = _frame_size(size)  # before a backend is opened, so a bad size costs nothing
    spp = check_spp(spp)
    names = (aovs,) if isinstance(aovs, str) else tuple(aovs)
    if isinstance(backend, Backend):
        if precision is not None and precision != backend.precision:
            raise AberrantError(
                f"precision {precision!r} is for a backend render() opens; the {backend.name} backend given "
                f"traces at {backend.precision}"
            )
        return render_once(scene, backend, (width, height), names, spp=spp)
    opened = create_backend(backend, precision=precision, fallback=False, log=log)
    try:
        return render_once(scene, opened, (width, height), names, spp=spp)
    finally:
        opened.release()
