"""The backend panel: pick the tracer, its precision and resolution scale; frame time and Mrays/s over time."""

from __future__ import annotations

import numpy as np
from imgui_bundle import imgui, implot

from backends.base import BACKENDS
from editor.backend_host import BackendHost
from editor.panels import widgets as ui

ERROR_COLOR = (1.0, 0.45, 0.4, 1.0)


def draw_backend_panel(host: BackendHost, *, playing: bool) -> None:
    """Window "Backend". Switching is disabled during play (the played scene holds the backend)."""
    if imgui.begin("Backend"):
        _chooser(host, playing)
        _stats(host)
    imgui.end()


def _chooser(host: BackendHost, playing: bool) -> None:
    reasons = host.reasons()
    if playing:
        imgui.begin_disabled()
    preview = host.name or "(none)"
    opened = imgui.begin_combo("backend", preview)
    ui.ITEMS.note("backend")
    if opened:
        for name in BACKENDS:
            reason = reasons.get(name)
            label = name if reason is None else f"{name} (unavailable)"
            if ui.selectable(f"{label}##backend", name == host.name) and name != host.name:
                host.select(name)  # an unavailable one fails with its reason, shown below
            if reason is not None:
                ui.tooltip(reason)
        imgui.end_combo()
    if host.name is not None:
        precisions = list(host.precisions(host.name))
        changed, precision = ui.combo("precision", host.precision or precisions[0], precisions)
        if changed:
            host.select(host.name, precision)
    changed, scale = imgui.slider_float("resolution", host.scale, 0.1, 1.0, "%.2f")
    ui.ITEMS.note("resolution")
    if changed:
        host.scale = float(scale)
    if imgui.button("Probe again"):
        host.reasons(refresh=True)
    ui.tooltip("check again which backends can run here")
    if playing:
        imgui.end_disabled()
    if host.error:
        imgui.push_text_wrap_pos(0.0)
        imgui.text_colored(ERROR_COLOR, host.error)
        imgui.pop_text_wrap_pos()


def _stats(host: BackendHost) -> None:
    if not host.frame_ms:
        imgui.text_disabled("no frames traced yet")
        return
    ms = np.asarray(host.frame_ms, dtype=np.float64)
    mrays = np.asarray(host.mrays, dtype=np.float64)
    frame = host.last_frame
    size = f"{frame.width}x{frame.height}" if frame is not None else "?"
    imgui.text(f"{size}: {ms[-1]:.1f} ms (mean {ms.mean():.1f}), {mrays[-1]:.2f} Mrays/s")
    height = max(80.0, min(160.0, imgui.get_content_region_avail().y))
    if implot.begin_plot("##frame time", (-1, height), implot.Flags_.no_legend.value | implot.Flags_.no_menus.value):
        flags = implot.AxisFlags_.auto_fit.value
        implot.setup_axes("frame", "ms", flags, flags)
        implot.setup_axis(implot.ImAxis_.y2.value, "Mrays/s", flags | implot.AxisFlags_.opposite.value)
        implot.plot_line("frame ms", ms)
        implot.set_axes(implot.ImAxis_.x1.value, implot.ImAxis_.y2.value)
        implot.plot_line("Mrays/s", mrays)
        implot.end_plot()
