"""The app: systems registered in named priority order, frames and upload stats exposed, clean close."""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import esper
import numpy as np
import pytest

from backends.base import AOVS, Backend, Frame, create_backend
from components import Transform
from engine.camera_view import CameraView
from engine.errors import AberrantError
from engine.input import InputSource, InputState, NoInput, ScriptedInput
from engine.packed import PackedScene, TableUpdate
from engine.scene import Scene
from systems.app import App, render_once
from systems.camera_movement import CameraMovementProcessor
from systems.gpu_upload import GpuUploadProcessor
from systems.portal_teleport import PortalTeleportProcessor
from systems.priorities import TICK_ORDER, Priority
from systems.render import RenderProcessor

FORWARD = InputState(move=(0.0, 0.0, -1.0))


class RecordingBackend(Backend):
    """A stand-in tracer that logs every call into a shared list."""

    name = "recording"

    def __init__(self, log: list[str] | None = None) -> None:
        super().__init__()
        self.log = [] if log is None else log
        self.sizes: list[tuple[int, int, tuple[str, ...]]] = []

    @classmethod
    def probe(cls) -> str | None:
        return None

    def upload(self, packed: PackedScene, updates: Sequence[TableUpdate]) -> int:
        self.log.append("upload")
        return packed.update_bytes(list(updates))

    def render(self, camera: CameraView, width: int, height: int, aovs: Sequence[str] = AOVS) -> Frame:
        self.log.append("render")
        self.sizes.append((width, height, tuple(aovs)))
        return Frame(width, height, instance=np.full((height, width), -1, np.int32))


class RecordingInput:
    """An input source that logs when it is polled."""

    def __init__(self, log: list[str]) -> None:
        self.log = log

    def poll(self, dt: float) -> InputState:
        self.log.append("poll")
        return FORWARD


def traced(processor: esper.Processor, log: list[str]):
    """``processor.process`` that first logs the processor's class name."""
    inner = processor.process
    name = type(processor).__name__

    def process(dt: float) -> None:
        log.append(name)
        inner(dt)

    return process


@pytest.fixture
def scene() -> Iterator[Scene]:
    s = Scene("app-test")
    s.set_camera((0.0, 0.0, 5.0), speed=3.0)
    s.add_mesh("box", "box")
    yield s
    s.close()


def test_priorities_are_named_and_ordered():
    assert TICK_ORDER == (Priority.CAMERA_MOVEMENT, Priority.PORTAL_TELEPORT, Priority.GPU_UPLOAD, Priority.RENDER)
    assert len(set(Priority)) == 4


def test_processors_run_in_the_named_order(scene):
    log: list[str] = []
    backend = RecordingBackend(log)
    with App(scene, backend, size=(4, 3), input_source=RecordingInput(log)) as app:
        kinds = [type(p) for p in app.processors]
        assert kinds == [CameraMovementProcessor, PortalTeleportProcessor, GpuUploadProcessor, RenderProcessor]
        assert [p.priority for p in app.processors] == list(TICK_ORDER)
        for processor in app.processors:  # wrap each so the shared log sees it run
            vars(processor)["process"] = traced(processor, log)  # an instance attribute shadows the method
        app.tick(0.1)
    assert log == [
        "CameraMovementProcessor", "poll",
        "PortalTeleportProcessor",
        "GpuUploadProcessor", "upload",
        "RenderProcessor", "render",
    ]  # fmt: skip


def test_headless_app_has_no_upload_or_render(scene):
    with App(scene, input_source=ScriptedInput([FORWARD])) as app:
        assert [type(p) for p in app.processors] == [CameraMovementProcessor, PortalTeleportProcessor]
        assert app.tick(0.1) is None
        assert app.frame is None and app.packed is None and app.size is None
        assert app.last_upload_bytes == 0 and app.last_updates == []
    assert np.allclose(scene.get(scene.camera_entity, Transform).position, (0.0, 0.0, 4.7), atol=1e-12)


def test_tick_returns_the_frame_and_resizes(scene):
    backend = RecordingBackend()
    with App(scene, backend, size=(4, 3), aovs=("depth", "instance")) as app:
        frame = app.tick(0.1)
        assert frame is app.frame and frame is not None
        assert (frame.width, frame.height) == (4, 3)
        app.size = (8, 6)
        assert app.run(2, 0.1) is app.frame
        assert app.frame_slot.frames == 3
    assert backend.sizes == [(4, 3, ("depth", "instance"))] + [(8, 6, ("depth", "instance"))] * 2


def test_close_removes_the_processors_and_a_second_app_is_refused_while_open(scene):
    app = App(scene, RecordingBackend())
    with pytest.raises(AberrantError, match="already runs"):
        App(scene)
    app.close()
    app.close()  # idempotent
    scene.activate()
    for kind in (CameraMovementProcessor, PortalTeleportProcessor, GpuUploadProcessor, RenderProcessor):
        assert esper.get_processor(kind) is None
    with pytest.raises(AberrantError, match="closed"):
        app.tick(0.1)
    with App(scene) as again:
        again.tick(0.1)


def test_apps_on_two_scenes_do_not_interfere(scene):
    other = Scene("other")
    other.set_camera((0.0, 0.0, 0.0))
    try:
        a = App(scene, input_source=ScriptedInput([FORWARD] * 2))
        b = App(other, input_source=ScriptedInput([InputState(move=(1.0, 0.0, 0.0))] * 2))
        for _ in range(2):
            a.tick(0.1)
            b.tick(0.1)
        a.close()
        b.close()
        assert np.allclose(scene.get(scene.camera_entity, Transform).position, (0.0, 0.0, 4.4), atol=1e-12)
        assert np.allclose(other.get(other.camera_entity, Transform).position, (0.6, 0.0, 0.0), atol=1e-12)
    finally:
        other.close()


def test_input_source_can_be_swapped_between_ticks(scene):
    with App(scene) as app:
        assert isinstance(app.input_source, NoInput)
        app.tick(0.1)
        source: InputSource = ScriptedInput([FORWARD])
        app.input_source = source
        app.tick(0.1)
    assert np.allclose(scene.get(scene.camera_entity, Transform).position, (0.0, 0.0, 4.7), atol=1e-12)


def test_negative_dt_and_bad_size_are_errors(scene):
    with pytest.raises(AberrantError, match="size"):
        App(scene, RecordingBackend(), size=(0, 10))
    with App(scene) as app, pytest.raises(AberrantError, match="dt"):
        app.tick(-0.1)


def test_render_once_renders_without_moving_and_cleans_up(scene):
    backend = RecordingBackend()
    frame = render_once(scene, backend, (6, 4), ("instance",))
    assert (frame.width, frame.height) == (6, 4)
    assert backend.log == ["upload", "render"]
    assert np.allclose(scene.get(scene.camera_entity, Transform).position, (0.0, 0.0, 5.0))
    scene.activate()
    assert esper.get_processor(RenderProcessor) is None


def test_with_the_reference_backend(scene):
    """End to end: the real reference tracer sees the box, and what the camera walked."""
    from conftest import require_backend

    require_backend("reference")
    backend = create_backend("reference", fallback=False)
    try:
        box = scene.entity("box")
        size, aovs = (33, 25), ("color", "depth", "instance")
        frame = render_once(scene, backend, size, aovs)
        centre = (size[1] // 2, size[0] // 2)  # odd sizes: the centre pixel's ray is the view axis
        assert frame.aov("instance")[centre] == box
        assert frame.aov("depth")[centre] == pytest.approx(4.5, abs=1e-4)  # camera z 5, box face z 0.5
        assert frame.aov("color").shape == (size[1], size[0], 4)

        with App(scene, backend, size=size, aovs=aovs, input_source=ScriptedInput([FORWARD] * 2)) as app:
            app.run(3, 0.1)  # walks 0.6 closer, then a static tick
            assert app.last_upload_bytes == 0
            assert app.frame is not None
            assert app.frame.aov("depth")[centre] == pytest.approx(3.9, abs=1e-4)
            assert app.frame.aov("instance")[centre] == box
    finally:
        backend.release()
