"""Every demo runs 5 ticks headless and renders in every backend with parity to the reference.

The imported TelloEngine ``AberrationRoom`` renders in every backend too. Each
fast backend's frame is compared with the float64 reference on the same scene
and camera: instance-id mismatch <= 0.5 % of pixels, no NaN.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from aberrant.importers.tello import import_tello
from components import Transform
from demos import build_demo, demo_names
from engine.input import InputState, ScriptedInput
from engine.scene import Scene
from systems.app import App, render_once

SIZE = (64, 48)
FAST = [("glsl", "f32"), ("opencl", "f32"), ("opencl", "f64")]
TELLO = Path(__file__).resolve().parents[2] / "tests" / "data" / "tello"

_references: dict[str, np.ndarray] = {}


def _mismatch(frame_instance: np.ndarray, reference_instance: np.ndarray) -> float:
    return float(np.mean(frame_instance != reference_instance))


def _check_against_reference(scene: Scene, key: str, backend) -> None:
    if key not in _references:
        from backends.reference.backend import ReferenceBackend

        with ReferenceBackend() as reference:
            _references[key] = render_once(scene, reference, SIZE, ("instance",)).aov("instance")
    frame = render_once(scene, backend, SIZE, ("color", "depth", "perceived", "instance"))
    for name in ("depth", "perceived"):
        values = frame.aov(name)
        assert not np.isnan(values).any(), f"{key}: NaN in {name}"
    assert _mismatch(frame.aov("instance"), _references[key]) <= 0.005, key


@pytest.mark.parametrize("demo", demo_names())
def test_demo_runs_five_ticks_headless(demo: str) -> None:
    scene = build_demo(demo)
    try:
        walk = ScriptedInput([InputState(move=(0.0, 0.0, -1.0), look=(1.0, 0.0))] * 5)
        with App(scene, input_source=walk) as app:
            app.run(5, 1 / 30)
        assert np.all(np.isfinite(scene.get(scene.camera_entity, Transform).position))
    finally:
        scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), FAST, ids=[f"{b}-{p}" for b, p in FAST])
@pytest.mark.parametrize("demo", demo_names())
def test_demo_renders_with_parity(demo: str, backend_name: str, precision: str, backend_factory) -> None:
    backend = backend_factory(backend_name, precision)
    scene = build_demo(demo)
    try:
        _check_against_reference(scene, demo, backend)
    finally:
        scene.close()


@pytest.mark.parametrize(("backend_name", "precision"), FAST, ids=[f"{b}-{p}" for b, p in FAST])
def test_imported_aberration_room_renders_in_every_backend(
    backend_name: str, precision: str, backend_factory, tmp_path: Path
) -> None:
    backend = backend_factory(backend_name, precision)
    result = import_tello(TELLO / "Scenes" / "AberrationRoom", TELLO / "Mesh", tmp_path / "room.json")
    try:
        _check_against_reference(result.scene, "tello-AberrationRoom", backend)
    finally:
        result.scene.close()
