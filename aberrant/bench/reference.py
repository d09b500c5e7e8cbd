"""The float64 reference frames errors are measured against, rendered once and cached on disk.

A reference frame of an 800x800 view of a 200,000-triangle mesh takes the
NumPy tracer about ten seconds, so it is rendered once per scene, camera,
size and ``max_events`` and kept under ``$ABERRANT_CACHE_DIR/reference/``
(else ``~/.cache/aberrant/reference/``). The key hashes the scene's JSON
(:func:`engine.scene_file.scene_document`, with each mesh file replaced by
its content hash so moving a file does not matter but editing it does), the
camera, the size and the reference tracer's own source, so an edit to the
reference invalidates every cached frame. :func:`render_ahead` fills the
cache in several processes before a run measures anything.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, replace
from importlib import resources
from pathlib import Path

import numpy as np

from backends.base import AOVS
from backends.samples import render_samples
from backends.upload import SceneUploader
from engine.camera_view import CameraView, scene_camera
from engine.scene import Scene
from engine.scene_file import dumps, scene_document

#: Bump when the cached file's layout changes.
CACHE_FORMAT = 1
#: Sources whose edits change what the reference renders.
_SOURCES: tuple[tuple[str, str], ...] = (
    ("backends.reference", "*.py"),
    ("backends", "upload.py"),
    ("engine", "packing.py"),
    ("engine", "layout.py"),
)


def cache_dir() -> Path:
    """``$ABERRANT_CACHE_DIR/reference`` or ``~/.cache/aberrant/reference``."""
    env = os.environ.get("ABERRANT_CACHE_DIR")
    return (Path(env) if env else Path.home() / ".cache" / "aberrant") / "reference"


def _source_hash() -> str:
    h = hashlib.sha256()
    for package, pattern in _SOURCES:
        root = resources.files(package)
        names = sorted(p.name for p in root.iterdir() if Path(p.name).match(pattern))
        for name in names:
            h.update(name.encode())
            h.update(root.joinpath(name).read_bytes())
    return h.hexdigest()


def scene_key(scene: Scene, camera: CameraView, size: tuple[int, int], spp: int = 1) -> str:
    """The cache key of one reference frame of ``spp`` samples a pixel (hex SHA-256)."""
    doc = scene_document(scene, Path("/"))
    for name, spec in doc["assets"].items():
        if "path" in spec:
            doc["assets"][name] = {"content": scene.asset(name).content_hash}
    h = hashlib.sha256()
    h.update(f"aberrant-reference-v{CACHE_FORMAT};".encode())
    h.update(dumps(doc).encode())
    h.update(np.asarray(camera.position, np.float64).tobytes())
    h.update(np.asarray(camera.rotation, np.float64).tobytes())
    h.update(f";fov={camera.fov_deg!r};size={size[0]}x{size[1]};".encode())
    if spp != 1:  # one sample a pixel keeps the key it always had
        h.update(f"spp={spp};".encode())
    h.update(_source_hash().encode())
    return h.hexdigest()


@dataclass
class ReferenceFrame:
    """Every AOV of the reference's frame and how it was obtained."""

    aovs: dict[str, np.ndarray]
    render_ms: float  # what rendering it took (when it was rendered, maybe in an earlier run)
    cached: bool  # read from the disk cache in this run
    key: str


def render_reference(
    scene: Scene, camera: CameraView, size: tuple[int, int], spp: int = 1
) -> tuple[dict[str, np.ndarray], float]:
    """Render every AOV with the float64 reference tracer (the colour of ``spp`` samples a pixel); returns
    them and the milliseconds taken."""
    from backends.reference.backend import ReferenceBackend

    start = time.perf_counter()
    with ReferenceBackend() as backend:
        SceneUploader(backend).sync(scene, camera.position)
        frame = render_samples(backend, camera, size[0], size[1], AOVS, spp)
    return {name: frame.aov(name) for name in AOVS}, (time.perf_counter() - start) * 1e3


def _load(path: Path, key: str) -> ReferenceFrame | None:
    """A cached frame, or ``None`` when missing or unreadable (a broken file is re-rendered, not trusted)."""
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["meta"]))
            if meta.get("key") != key or meta.get("format") != CACHE_FORMAT:
                return None
            aovs = {name: np.array(data[name]) for name in AOVS}
    except (OSError, KeyError, ValueError):
        return None
    return ReferenceFrame(aovs, float(meta.get("render_ms", 0.0)), True, key)


def _save(path: Path, frame: ReferenceFrame) -> None:
    """Write atomically (temporary file, then rename): an interrupted run never leaves a torn cache file."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.stem, suffix=".tmp")
    try:
        with os.fdopen(fd, "wb") as fh:
            meta = json.dumps({"format": CACHE_FORMAT, "key": frame.key, "render_ms": frame.render_ms})
            # mypy cannot tell that the unpacked AOV names never include savez's allow_pickle keyword.
            np.savez_compressed(fh, meta=np.array(meta), **frame.aovs)  # type: ignore[arg-type]
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


class ReferenceCache:
    """Reference frames by key: in memory for this run, on disk across runs."""

    def __init__(self, folder: Path | None = None) -> None:
        self.folder = folder or cache_dir()
        self._memory: dict[str, ReferenceFrame] = {}
        self.hits = 0
        self.misses = 0

    def get(self, scene: Scene, camera: CameraView, size: tuple[int, int], spp: int = 1) -> ReferenceFrame:
        """The reference frame of ``scene`` from ``camera`` at ``size`` and ``spp``, rendered only when not
        cached."""
        key = scene_key(scene, camera, size, spp)
        if key in self._memory:
            return self._memory[key]
        path = self.folder / f"{key}.npz"
        frame = _load(path, key)
        if frame is not None:
            self.hits += 1
        else:
            self.misses += 1
            aovs, ms = render_reference(scene, camera, size, spp)
            frame = ReferenceFrame(aovs, ms, False, key)
            _save(path, frame)
        self._memory[key] = frame
        return frame


#: One scene's share of :func:`render_ahead`: its bench name and the (max_events or ``None`` for its own, size)
#: of each frame.
Task = tuple[str, list[tuple[int | None, tuple[int, int]]]]


def _render_task(task: tuple[Task, Path]) -> str:
    """A worker's share: one bench scene's missing frames into the disk cache (a scene that does not build is
    skipped: the measuring run records why)."""
    from aberrant.bench.scenes import bench_scenes

    (name, keys), folder = task
    try:
        scene = bench_scenes()[name].build(folder)
    except Exception:  # reported by the run that measures it
        return name
    try:
        camera, cache, own = scene_camera(scene), ReferenceCache(), scene.settings
        for max_events, size in keys:
            scene.settings = own if max_events is None else replace(own, max_events=max_events)
            cache.get(scene, camera, size)
    finally:
        scene.close()
    return name


def render_ahead(tasks: list[Task], folder: Path, jobs: int, done: Callable[[str], object]) -> None:
    """Render the bench scenes' missing frames in ``jobs`` spawned processes (``folder``: their mesh files);
    ``done`` hears each scene's name as it finishes, in order."""
    context = multiprocessing.get_context("spawn")  # the GL and OpenCL runtimes do not survive a fork
    with ProcessPoolExecutor(jobs, mp_context=context) as pool:
        for name in pool.map(_render_task, [(task, folder) for task in tasks]):
            done(name)
