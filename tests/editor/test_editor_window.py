"""The editor in a real window (under Xvfb when there is no display): it opens a demo, renders, screenshots.

Each run is a subprocess, so glfw and the GL context start and end cleanly.
Screenshots are kept in ``out/test-artifacts/`` for a person to look at.
"""

from __future__ import annotations

import contextlib
import json
import os
import select
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("imgui_bundle", reason="the editor extra is not installed: pip install 'aberrant[editor]'")
pytest.importorskip("glfw", reason="the editor extra is not installed: pip install 'aberrant[editor]'")

from PIL import Image

from editor.backend_host import STILL_SPP

ROOT = Path(__file__).resolve().parents[2]
ARTIFACTS = ROOT / "out" / "test-artifacts"
SIZE = (1280, 800)

#: Runs in the subprocess: open the editor on a scene, draw frames, screenshot, report as JSON.
SCRIPT = r"""
import json, sys, time
from editor.window import EditorWindow, load_target
args = json.loads(sys.argv[1])
model = load_target("starter")
if args["overlays"]:
    model.add_aberration((-1.6, 1.4, -0.6))
    model.add_portal_pair((1.4, 1.3, 0.8))
    model.select(None)
window = EditorWindow(model, size=tuple(args["size"]), backend=args["backend"])
window.host.scale = args["scale"]
window.run(frames=args["frames"], screenshot=args["shot"])
ui, host = window.ui, window.host
report = {
    "backend": host.name, "error": host.error, "traced": host.frames,
    "origin": list(ui.viewport.origin), "size": list(ui.viewport.size),
    "traced_size": [host.last_frame.width, host.last_frame.height] if host.last_frame else None,
    "samples": host.samples,
}
if args["idle"]:
    from editor.backend_host import STILL_SPP
    window.idle_wait_s = 0.2
    window.run(frames=STILL_SPP)  # a still view first refines its image, one sample a pixel more a frame
    report["refined"] = host.samples
    still = (host.frames, window.preview.renders)
    cpu = time.process_time()
    window.run(frames=args["idle"])
    report["idle_cpu_s"] = time.process_time() - cpu
    report["idle"] = [host.frames - still[0], window.preview.renders - still[1], window.still_frames]
    ui.view.position[0] += 0.25
    window.run(frames=1)
    report["moved"] = [host.frames - still[0], window.preview.renders - still[1]]
if args["play"]:
    from imgui_bundle import imgui
    from engine.scene_file import scene_to_json
    before = scene_to_json(model.scene)
    start = list(model.scene.get(model.scene.camera_entity, __import__("components").Transform).position)
    ui.start_play()
    imgui.get_io().add_key_event(imgui.Key.w, True)
    for _ in range(8):
        window.frame()
    imgui.get_io().add_key_event(imgui.Key.w, False)
    window.frame(args["play"])
    report["played"] = [float(c) for c in ui.play.camera_view.position]
    report["play_frames"] = host.frames
    report["play_error"] = ui.play.error
    imgui.get_io().add_key_event(imgui.Key.escape, True)
    window.frame()
    imgui.get_io().add_key_event(imgui.Key.escape, False)
    window.frame()
    report["stopped"] = not ui.playing
    report["unchanged"] = scene_to_json(model.scene) == before
    report["start"] = start
if args["bench"]:
    editor_ms = []
    for _ in range(args["bench"]):
        host.invalidate()  # force a fresh trace every frame, as when the view moves
        start = time.perf_counter(); window.frame(); editor_ms.append((time.perf_counter() - start) * 1e3)
    view = ui.view.camera()
    w, h = report["traced_size"]
    bare_ms = []
    for _ in range(args["bench"]):
        start = time.perf_counter(); host.backend.render(view, w, h, ()); window.ctx.finish()
        bare_ms.append((time.perf_counter() - start) * 1e3)
    report["editor_ms"], report["bare_ms"] = editor_ms, bare_ms
window.close()
print("REPORT " + json.dumps(report))
"""


@pytest.fixture(scope="module")
def display():
    """$DISPLAY, or a private Xvfb server started for these tests (skipped when neither exists)."""
    if os.environ.get("DISPLAY"):
        yield os.environ["DISPLAY"]
        return
    xvfb = shutil.which("Xvfb")
    if xvfb is None:
        pytest.skip("no display and no Xvfb (apt-get install xvfb) for the editor window tests")
    read_end, write_end = os.pipe()  # -displayfd: Xvfb picks a free display and writes its number here
    proc = subprocess.Popen(
        [xvfb, "-displayfd", str(write_end), "-screen", "0", f"{SIZE[0]}x{SIZE[1]}x24", "-nolisten", "tcp"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        pass_fds=(write_end,),
    )
    os.close(write_end)
    try:
        ready, _, _ = select.select([read_end], [], [], 15.0)
        number = os.read(read_end, 64).decode().strip() if ready else ""
        if not number:
            pytest.skip("Xvfb did not start")
        yield f":{number}"
    finally:
        os.close(read_end)
        proc.terminate()
        with contextlib.suppress(subprocess.TimeoutExpired):
            proc.wait(5)


def run_editor(
    display: str,
    shot: Path,
    *,
    overlays: bool,
    backend: str | None = "glsl",
    frames=4,
    bench=0,
    play=None,
    idle=0,
    scale=1.0,
) -> dict:
    """``scale``: the tracer's resolution over the viewport's (the editor's own setting)."""
    env = {**os.environ, "DISPLAY": display}
    args = {"size": SIZE, "frames": frames, "shot": str(shot), "overlays": overlays, "backend": backend}
    args.update(bench=bench, play=None if play is None else str(play), idle=idle, scale=scale)
    result = subprocess.run(
        [sys.executable, "-c", SCRIPT, json.dumps(args)], cwd=ROOT, env=env, capture_output=True, text=True, timeout=240
    )
    lines = [line for line in result.stdout.splitlines() if line.startswith("REPORT ")]
    if result.returncode != 0 or not lines:
        if "needs a display" in result.stderr or "GLX" in result.stderr:
            pytest.skip(f"the editor window cannot open here: {result.stderr.strip().splitlines()[-1]}")
        raise AssertionError(f"editor run failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return json.loads(lines[-1][len("REPORT ") :])


def _require_glsl() -> None:
    from backends.base import probe

    reason = probe("glsl")
    if reason is not None:
        pytest.skip(f"glsl backend cannot run here: {reason}")


def _crop(shot: Path, report: dict) -> np.ndarray:
    image = np.asarray(Image.open(shot).convert("RGB")).astype(int)
    x, y = (round(c) for c in report["origin"])
    w, h = report["size"]
    return image[y : y + h, x : x + w]


def test_editor_window_shows_the_glsl_texture(display):
    _require_glsl()
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "editor_starter.png"
    report = run_editor(display, shot, overlays=False)
    assert report["backend"] == "glsl" and report["error"] is None and report["traced"] >= 1
    assert report["traced_size"] == report["size"]  # resolution scale 1: one texel per viewport pixel
    viewport = _crop(shot, report)

    from backends.glsl.backend import GlslBackend
    from demos import build_demo
    from systems.app import render_once

    scene = build_demo("starter")
    backend = GlslBackend()
    try:
        # The still view has refined its image with more samples a pixel: the same count, rendered at once.
        spp = report["samples"]
        bare = render_once(scene, backend, tuple(report["size"]), ("color",), spp=spp).color[..., :3].astype(int)
    finally:
        backend.release()
        scene.close()
    diff = np.abs(viewport - bare)
    assert np.mean(diff) < 2.0 and np.mean(np.max(diff, axis=-1) <= 3) > 0.98


def test_editor_window_draws_preview_lines_in_their_colours(display):
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    shot = ARTIFACTS / "editor_overlays.png"
    report = run_editor(display, shot, overlays=True, backend=None)
    viewport = _crop(shot, report)
    orange = np.all(np.abs(viewport - (255, 140, 25)) <= 3, axis=-1)  # the aberration's colour (1, 0.55, 0.1)
    blue = np.all(np.abs(viewport - (51, 153, 255)) <= 3, axis=-1)  # the portals' colour (0.2, 0.6, 1.0)
    assert orange.sum() > 200 and blue.sum() > 200
    half = viewport.shape[1] // 2
    assert orange[:, :half].sum() > orange[:, half:].sum()  # the box stands left, the portals right
    assert blue[:, half:].sum() > 0


def test_editor_window_play_then_stop(display):
    _require_glsl()
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    report = run_editor(
        display, ARTIFACTS / "editor_before_play.png", overlays=False, play=ARTIFACTS / "editor_play.png"
    )
    assert report["play_error"] is None and report["play_frames"] > report["traced"]  # the tracer ran in play
    assert report["played"][2] < report["start"][2] - 0.1  # W walked the camera forward (towards -z)
    assert report["stopped"] and report["unchanged"]


def test_a_still_editor_traces_once_and_sleeps(display):
    """No input: once the still view has its samples, the loop sleeps on the event queue and neither the
    tracer nor the preview draws again; moving the camera traces once more."""
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    # The reference refines 16 samples a pixel: at a quarter of the viewport's resolution (100 s at the whole).
    shot = ARTIFACTS / "editor_idle.png"
    report = run_editor(display, shot, overlays=True, backend="reference", frames=6, idle=10, scale=0.25)
    assert report["traced"] >= 1 and report["error"] is None
    assert report["refined"] == STILL_SPP
    traced, previewed, still = report["idle"]
    assert traced == 0 and previewed == 0 and still >= 10
    assert report["moved"] == [1, 1]
    print(f"10 idle iterations (0.2 s waits): {report['idle_cpu_s'] * 1e3:.0f} ms of CPU")


@pytest.mark.benchmark(group="editor")
def test_editor_frame_time_against_a_bare_render(display, benchmark):
    """Editor frame (UI + preview + trace) over a bare trace of the same scene and size."""
    _require_glsl()
    shot = ARTIFACTS / "editor_bench.png"
    ARTIFACTS.mkdir(parents=True, exist_ok=True)
    report = benchmark.pedantic(
        lambda: run_editor(display, shot, overlays=False, frames=3, bench=5), rounds=1, iterations=1
    )
    editor_ms = float(np.median(report["editor_ms"]))
    bare_ms = float(np.median(report["bare_ms"]))
    benchmark.extra_info.update(
        editor_ms=editor_ms, bare_ms=bare_ms, ratio=editor_ms / bare_ms, size="x".join(map(str, report["size"]))
    )
    print(f"editor frame {editor_ms:.1f} ms, bare render {bare_ms:.1f} ms, ratio {editor_ms / bare_ms:.2f}")
