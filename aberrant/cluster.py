"""Flythroughs on a Dask cluster: the path simulated here once, each frame rendered by a worker from its pose.

``aberrant render SCENE --path --workers N`` starts a :class:`distributed.LocalCluster` on this
machine (N worker processes of one thread each); ``--scheduler tcp://HOST:PORT`` uses a cluster
that is already running. The camera path is walked once by the real movement and teleport systems
(:func:`aberrant.flythrough.simulate_path`); every task then renders one frame from its recorded
pose with :class:`aberrant.flythrough.PoseRenderer`, so the frames are those of a single-process
run, byte for byte.

What travels: the scene as its scene-file JSON plus the bytes of the mesh and texture files it loads (a worker
on another machine has neither this file system nor our GPU state), the poses and the frame size,
broadcast to every worker once. A worker opens its backend once, in a worker plugin, and keeps it,
and the scene it last rendered, between tasks.

Frames arrive as PNGs in a work folder beside the output, ``.<out>.frames-<key>/`` (the key hashes
the scene, the poses, the size and the backend), so a run that is stopped and started again
renders only what is missing. The clip is written at the end through :class:`aberrant.sinks.Sink`
(a temporary, renamed into place), and the work folder is removed after that succeeded. Dask
re-runs the tasks of a worker that dies; each frame is kept once, by its index.
"""

from __future__ import annotations

import contextlib
import hashlib
import io
import logging
import os
import shutil
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

import numpy as np

from aberrant.cluster_worker import PLUGIN, FrameJob, backend_plugin, backend_status, frame_job, render_frame
from aberrant.flythrough import plan_frames, progress_bar, simulate_path
from aberrant.sinks import Sink, check_fps, check_gif_memory, check_output
from backends.samples import check_spp
from engine.atomic_files import write_atomically
from engine.errors import AberrantError, BackendUnavailable, shorten
from engine.scene import Scene
from systems.camera_path import CameraPath

if TYPE_CHECKING:
    from engine.records import Precision

__all__ = [
    "CONNECT_TIMEOUT_S",
    "connect",
    "local_cluster",
    "render_distributed",
    "work_folder",
]

#: How long to try reaching a ``--scheduler`` before giving up.
CONNECT_TIMEOUT_S = 10.0
MISSING = "--workers needs the cluster extra: pip install -e '.[cluster]'"


def _distributed() -> Any:
    try:
        import distributed
    except ImportError:
        raise AberrantError(MISSING) from None
    return distributed


def local_cluster(workers: int, **kwargs: Any) -> Any:
    """A LocalCluster on loopback: ``workers`` processes of one thread each, no dashboard, quiet logs.

    Dask's nannies set ``MALLOC_TRIM_THRESHOLD_`` in their workers, which turns off glibc's adaptive
    mmap threshold: every large NumPy temporary is then mapped and unmapped afresh, and the
    reference backend's frames took twice as long. Its workers go without it. They are not daemonic
    processes either, so that a task may start processes of its own (the bench's Embree pool does).
    """
    import dask

    distributed = _distributed()
    settings = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None, "distributed.worker.daemon": False}
    with dask.config.set(settings):
        return distributed.LocalCluster(
            n_workers=workers,
            threads_per_worker=1,
            processes=True,
            host="127.0.0.1",
            dashboard_address=None,
            silence_logs=logging.CRITICAL,
            **kwargs,
        )


@contextlib.contextmanager
def connect(workers: int | None, scheduler: str | None, timeout_s: float) -> Iterator[Any]:
    """A client of the cluster at ``scheduler``, or of a LocalCluster of ``workers`` processes started here."""
    distributed = _distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as e:
            raise AberrantError(f"--scheduler {shorten(scheduler)}: cannot reach the scheduler ({e})") from None
        try:
            yield client
        finally:
            client.close()
        return
    if workers is None or workers < 1:
        raise AberrantError(f"--workers must be at least 1, got {workers}")
    cluster = local_cluster(workers)
    try:
        client = distributed.Client(cluster, set_as_default=False)
        try:
            yield client
        finally:
            client.close()
    finally:
        cluster.close()


def _start_backends(client: Any, backend: str, precision: Precision | None) -> str:
    """Open the backend on every worker; the one name they all run, or one line saying what failed."""
    client.register_plugin(backend_plugin(backend, precision), name=PLUGIN)
    status = client.run(backend_status)
    if not status:
        raise AberrantError("the cluster has no workers")
    names = set()
    for worker, (name, error) in sorted(status.items()):
        if name is None:
            raise BackendUnavailable(f"worker {worker}: {' '.join(str(error).split())}")
        names.add(name)
    if len(names) > 1:
        raise BackendUnavailable(
            f"the workers run different backends ({', '.join(sorted(names))}); name one with --backend"
        )
    return names.pop()


def work_folder(out: Path, job: FrameJob, backend: str, precision: str | None) -> Path:
    """Where the frames of this flythrough wait for the clip: beside ``out``, named by what they depend on."""
    key = hashlib.sha256(f"{job.key}|{backend}|{precision or ''}".encode()).hexdigest()[:16]
    return out.parent / f".{out.name}.frames-{key}"


def _frame_file(folder: Path, index: int) -> Path:
    return folder / f"frame_{index:05d}.png"


def _read_frame(path: Path, size: tuple[int, int]) -> np.ndarray | None:
    """A kept frame, or ``None`` when it is missing or not a frame of this size."""
    from PIL import Image

    try:
        with Image.open(path) as image:
            rgb = np.asarray(image.convert("RGB"))
    except (OSError, ValueError):
        return None
    return rgb if rgb.shape == (size[1], size[0], 3) else None


def _keep_frame(path: Path, rgb: np.ndarray) -> None:
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(rgb).save(buffer, "PNG")
    write_atomically({path: buffer.getvalue()})


def render_distributed(
    scene: Scene,
    path: CameraPath,
    frames: int | None,
    size: Sequence[int],
    out: str | os.PathLike[str],
    *,
    backend: str = "auto",
    precision: Precision | None = None,
    workers: int | None = None,
    scheduler: str | None = None,
    fps: float | None = None,
    spp: int = 1,
    progress: TextIO | bool = True,
    connect_timeout_s: float | None = None,
) -> str:
    """:func:`aberrant.flythrough.render_flythrough`'s clip, its frames rendered on a Dask cluster.

    ``workers``: start a LocalCluster of that many processes here; ``scheduler``: the address of
    a running one. ``spp``: samples a pixel of every frame. Returns the name of the backend the workers ran.
    """
    spp = check_spp(spp)
    frames, fps = plan_frames(path, fps=fps, frames=frames)
    out_path = Path(out)
    kind = check_output(out_path)
    check_fps(fps)
    width, height = (int(c) for c in size)
    if kind == "gif":
        check_gif_memory(frames, (width, height))
    _distributed()  # a missing extra fails before the path is walked
    poses = simulate_path(scene, path, frames)
    job = frame_job(scene, poses, (width, height), spp)
    timeout_s = CONNECT_TIMEOUT_S if connect_timeout_s is None else connect_timeout_s
    with connect(workers, scheduler, timeout_s) as client:
        name = _start_backends(client, backend, precision)
        folder = work_folder(out_path, job, name, precision)
        _render_frames(client, job, name, folder, progress)
    _write_clip(out_path, kind, fps, folder, job)
    return name


def _render_frames(client: Any, job: FrameJob, backend: str, folder: Path, progress: TextIO | bool) -> None:
    """Every frame not yet in ``folder``, rendered on the cluster and kept there as it arrives."""
    from distributed import as_completed

    try:
        folder.mkdir(exist_ok=True)
    except OSError as e:
        raise OSError(e.errno, e.strerror, str(folder)) from None
    total = len(job.poses)
    missing = [i for i in range(total) if _read_frame(_frame_file(folder, i), job.size) is None]
    bar = progress_bar(progress, total)
    try:
        if bar is not None and total - len(missing):
            bar.step(count=total - len(missing))
        if not missing:
            return
        shared = client.scatter(job, broadcast=True, hash=False)
        futures = client.map(render_frame, missing, job=shared, key=[f"frame-{job.key}-{i}" for i in missing])
        index_of = {future.key: i for future, i in zip(futures, missing, strict=True)}
        try:
            for future in as_completed(futures, loop=client.loop):
                try:
                    ran, rgb = future.result()
                except AberrantError:
                    raise
                except Exception as e:
                    raise AberrantError(
                        f"frame {index_of[future.key]} failed on the cluster: {type(e).__name__}: {e}"
                    ) from None
                if ran != backend:
                    raise BackendUnavailable(f"a worker ran the {ran} backend, not {backend}; name one with --backend")
                _keep_frame(_frame_file(folder, index_of[future.key]), rgb)
                if bar is not None:
                    bar.step()
        finally:
            client.cancel(futures)
    except BaseException:
        if not any(folder.iterdir()):  # nothing to resume from: leave nothing behind
            shutil.rmtree(folder, ignore_errors=True)
        raise
    finally:
        if bar is not None:
            bar.finish()


def _write_clip(out: Path, kind: str, fps: float, folder: Path, job: FrameJob) -> None:
    """The kept frames, in order, through the flythrough's sink; the work folder goes once the clip is in place."""
    sink = Sink(out, kind, fps)
    try:
        for index in range(len(job.poses)):
            rgb = _read_frame(_frame_file(folder, index), job.size)
            if rgb is None:
                raise AberrantError(f"{shorten(folder)}: frame {index} went missing; run again to render it")
            sink.add(rgb)
        sink.commit()
    except BaseException:
        sink.discard()
        raise
    shutil.rmtree(folder, ignore_errors=True)
