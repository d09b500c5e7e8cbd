"""The float64 reference frames errors are measured against, rendered once and cached on disk.

A reference frame of an 800x800 view of a 200,000-triangle mesh takes the
NumPy tracer about ten seconds, so it is rendered once per scene, camera,
size and ``max_events`` and kept under ``$ABERRANT_CACHE_DIR/reference/``
(else ``~/.cache/aberrant/reference/``). The key hashes the scene's JSON
(:func:`engine.scene_file.scene_document`, with each mesh file replaced by
its content hash so moving a file does not matter but editing it does), the
camera, the size and the reference tracer's own source, so an edit to the
reference invalidates every cached frame.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import numpy as np

from backends.base import AOVS
from backends.upload import SceneUploader
from engine.camera_view import CameraView
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


def scene_key(scene: Scene, camera: CameraView, size: tuple[int, int]) -> str:
    """The cache key of one reference frame (hex SHA-256)."""
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
    h.update(_source_hash().encode())
    return h.hexdigest()


@dataclass
class ReferenceFrame:
    """Every AOV of the reference's frame and how it was obtained."""

    aovs: dict[str, np.ndarray]
    render_ms: float  # what rendering it took (when it was rendered, maybe in an earlier run)
    cached: bool  # read from the disk cache in this run
    key: str


def render_reference(scene: Scene, camera: CameraView, size: tuple[int, int]) -> tuple[dict[str, np.ndarray], float]:
    """Render every AOV with the float64 reference tracer; returns them and the milliseconds taken."""
    from backends.reference.backend import ReferenceBackend

    start = time.perf_counter()
    with ReferenceBackend() as backend:
        SceneUploader(backend).sync(scene, camera.position)
        frame = backend.render(camera, size[0], size[1], AOVS)
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

    def get(self, scene: Scene, camera: CameraView, size: tuple[int, int]) -> ReferenceFrame:
        """The reference frame of ``scene`` from ``camera`` at ``size``, rendered only when not cached."""
        key = scene_key(scene, camera, size)
        if key in self._memory:
            return self._memory[key]
        path = self.folder / f"{key}.npz"
        frame = _load(path, key)
        if frame is not None:
            self.hits += 1
        else:
            self.misses += 1
            aovs, ms = render_reference(scene, camera, size)
            frame = ReferenceFrame(aovs, ms, False, key)
            _save(path, frame)
        self._memory[key] = frame
        return frame
