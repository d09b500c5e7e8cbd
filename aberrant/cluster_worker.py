"""The worker's side of a flythrough on a Dask cluster: the job every worker is sent once, the backend each
worker opens once and keeps (a worker plugin), and the task that renders one frame of the job.

:mod:`aberrant.cluster` plans the job, starts or reaches the cluster and gathers the frames.
"""

from __future__ import annotations

import hashlib
import shutil
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from aberrant.flythrough import PoseRenderer
from components import Mesh, Transform
from engine.errors import AberrantError, BackendUnavailable, shorten
from engine.scene import Scene
from engine.scene_file import scene_from_text
from engine.scene_writer import dumps, scene_document

if TYPE_CHECKING:
    from backends.base import Backend
    from engine.records import Precision

#: The name the backend plugin is registered under on every worker.
PLUGIN = "aberrant-backend"


@dataclass(frozen=True)
class FrameJob:
    """Everything a worker needs to render any frame of one flythrough."""

    #: The scene file's JSON; asset paths are names in :attr:`files`.
    scene_text: str
    #: Mesh file name -> its bytes.
    files: dict[str, bytes]
    poses: tuple[Transform, ...]
    size: tuple[int, int]
    #: Samples a pixel of every frame.
    spp: int = 1
    key: str = field(default="", compare=False)


def frame_job(scene: Scene, poses: Sequence[Transform], size: Sequence[int], spp: int = 1) -> FrameJob:
    """``scene`` as a scene file plus its mesh and texture files, with the poses (and samples a pixel) to render it.

    Rotations are written as quaternions (not as the Euler angles a file may have given them
    as), so every value reaches the worker bit for bit.
    """
    saved_angles = scene.euler_deg
    try:
        scene.euler_deg = {}
        doc = scene_document(scene)
    finally:
        scene.euler_deg = saved_angles
    files: dict[str, bytes] = {}
    for index, (name, spec) in enumerate(sorted(scene.assets.items())):
        if spec.path is None:
            continue
        source = scene.asset_path(spec)
        local = f"{index:03d}-{source.name}"
        try:
            files[local] = source.read_bytes()
        except OSError as e:
            raise AberrantError(f"asset {name!r}: cannot read {shorten(source)} ({e.strerror or e})") from None
        doc["assets"][name] = {"path": local}
    textures: dict[Path, str] = {}
    for item in doc["entities"]:
        mesh = item.get("mesh")
        if mesh is None or "texture" not in mesh:
            continue
        source = scene.texture_path(scene.get(scene.entity(item["name"]), Mesh).texture)
        if source not in textures:
            try:
                data = source.read_bytes()
            except OSError:
                continue  # the worker warns of it as this process does, and draws the base colour
            textures[source] = f"texture{len(textures):03d}-{source.name}"
            files[textures[source]] = data
        mesh["texture"] = textures[source]
    text = dumps(doc)
    width, height = (int(c) for c in size)
    digest = hashlib.sha256(text.encode())
    for name in sorted(files):
        digest.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
    for pose in poses:
        digest.update(repr((pose.position, pose.rotation, pose.scale)).encode())
    digest.update(f"{width}x{height}x{spp}".encode())
    return FrameJob(text, files, tuple(poses), (width, height), spp, digest.hexdigest()[:16])


def open_job(job: FrameJob, folder: Path) -> Scene:
    """The job's scene, its mesh files written into ``folder`` first."""
    for name, data in job.files.items():
        (folder / name).write_bytes(data)
    return scene_from_text(job.scene_text, "(flythrough scene)", folder)


class BackendHolder:
    """A worker's backend, opened once when the worker starts, and the renderer of the job it last rendered.

    A backend that cannot start is remembered as its reason, not raised: the client asks every
    worker (:func:`backend_status`) and fails with that reason in one line.
    """

    name = PLUGIN

    def __init__(self, backend: str, precision: Precision | None) -> None:
        self.backend_name, self.precision = backend, precision
        self.backend: Backend | None = None
        self.error: str | None = None
        self._job: str | None = None
        self._renderer: PoseRenderer | None = None
        self._folder: Path | None = None

    def setup(self, worker: object = None) -> None:
        from backends.base import create_backend

        try:
            self.backend = create_backend(
                self.backend_name,
                precision=self.precision,
                fallback=self.backend_name == "auto",
                log=lambda message: None,
            )
        except AberrantError as e:
            self.error = str(e)
        except Exception as e:  # a driver that crashes while starting: reported, not a dead worker
            self.error = f"{self.backend_name} backend cannot start: {type(e).__name__}: {e}"

    def renderer(self, job: FrameJob) -> PoseRenderer:
        if self.backend is None:
            raise BackendUnavailable(self.error or "no backend")
        if self._job != job.key or self._renderer is None:
            self._drop()
            self._folder = Path(tempfile.mkdtemp(prefix="aberrant-job-"))
            scene = open_job(job, self._folder)
            self._renderer = PoseRenderer(scene, self.backend, job.poses, job.size, spp=job.spp)
            self._job = job.key
        return self._renderer

    def _drop(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer.scene.close()
            self._renderer = None
        if self._folder is not None:
            shutil.rmtree(self._folder, ignore_errors=True)
            self._folder = None
        self._job = None

    def teardown(self, worker: object = None) -> None:
        self._drop()
        if self.backend is not None:
            self.backend.release()
            self.backend = None


def backend_plugin(backend: str, precision: Precision | None) -> BackendHolder:
    """A :class:`BackendHolder` that Dask takes as a worker plugin (the subclass needs dask, imported here)."""
    from distributed.diagnostics.plugin import WorkerPlugin

    class BackendPlugin(BackendHolder, WorkerPlugin):
        pass

    return BackendPlugin(backend, precision)


def holder(worker: Any = None) -> BackendHolder:
    """This worker's (or ``worker``'s) backend plugin."""
    if worker is None:
        from distributed import get_worker

        worker = get_worker()
    plugin = worker.plugins[PLUGIN]
    assert isinstance(plugin, BackendHolder)
    return plugin


def backend_status(dask_worker: Any) -> tuple[str | None, str | None]:
    """(backend name, None) when this worker's backend started, else (None, why not); run by ``Client.run``."""
    plugin = holder(dask_worker)
    return (plugin.backend.name if plugin.backend is not None else None), plugin.error


def render_frame(index: int, job: FrameJob) -> tuple[str, np.ndarray]:
    """One frame on a worker: (the backend that rendered it, (H, W, 3) uint8 RGB)."""
    plugin = holder()
    renderer = plugin.renderer(job)
    assert plugin.backend is not None
    return plugin.backend.name, renderer.render(index)
