"""Flythrough outputs: frames in, one ``.mp4``, ``.gif`` or folder of PNGs out, whole or not at all.

``.mp4`` (H.264, yuv420p) streams each frame to an ffmpeg process (imageio-ffmpeg's binary) writing a
hidden temporary beside the target; a folder of PNGs writes each frame into a hidden temporary folder;
both are renamed into place at the end. A GIF needs every frame at once (Pillow writes them in one
go), so its frames are kept as palette images (one byte a pixel) and written through
:func:`engine.atomic_files.write_atomically`; its memory is checked against the budget up front.

Temporaries are named ``.NAME.PID-RANDOM.tmp[.ext]`` like every atomic write's, so a run killed
outright (SIGKILL) leaves one that the next run into the same place removes; SIGINT, SIGTERM and
SIGHUP remove it at once (:mod:`aberrant.signals`). ffmpeg's messages go to a log file, never the
terminal: a failure is one line naming the output and ffmpeg's first error.
"""

from __future__ import annotations

import contextlib
import errno
import io
import math
import os
import re
import shutil
import subprocess
import tempfile
from fractions import Fraction
from pathlib import Path
from typing import IO, TYPE_CHECKING, NoReturn

import numpy as np

from aberrant.memory import check_fits
from engine.atomic_files import (
    UnsafeTarget,
    check_target,
    check_writable,
    clean_stale_temps,
    temp_path,
    write_atomically,
)

if TYPE_CHECKING:
    from PIL import Image
from engine.errors import AberrantError, shorten

VIDEO_SUFFIXES = (".mp4", ".gif")
#: Frame rates a flythrough accepts: a GIF stores each frame's delay in 16 bits of 10 ms (at most 655 s),
#: and ffmpeg's H.264 writer wants a sane time base.
FPS_RANGE = (0.01, 1000.0)
#: Bytes a GIF frame holds until the file is written: our palette image and Pillow's copy of it.
GIF_BYTES_PER_PIXEL = 2
#: H.264 constant rate factor (0 best, 51 worst): imageio's ``quality=8``.
MP4_CRF = 10
_FFMPEG_PREFIX = re.compile(r"^\[[^\]]*\]\s*")


def output_kind(out: Path) -> str:
    """``"mp4"``, ``"gif"`` or ``"png"`` (a folder) from the output path."""
    suffix = out.suffix.lower()
    if suffix in VIDEO_SUFFIXES:
        return suffix[1:]
    if suffix in (".png", ".jpg", ".jpeg", ".webm", ".avi", ".mov", ".mkv"):
        raise AberrantError(
            f"--out {shorten(out)}: a flythrough is written as .mp4, .gif or a folder of PNGs (no suffix)"
        )
    return "png"


def check_output(out: Path) -> str:
    """Fail before rendering when ``out`` cannot be written; returns its kind."""
    kind = output_kind(out)
    name = shorten(out)
    try:
        check_writable(out, folder=kind == "png")
    except UnsafeTarget as e:
        raise AberrantError(f"--out {name}: {e.strerror}") from None
    if kind == "png" and (out.exists() or out.is_symlink()):
        if not out.is_dir():
            raise AberrantError(f"--out {name}: exists and is not a folder (PNG frames are written into a folder)")
        stray = [p.name for p in out.iterdir() if not (p.name.startswith("frame_") and p.suffix == ".png")]
        if stray:
            raise AberrantError(
                f"--out {name}: the folder holds other files ({shorten(stray[0])}...); choose an empty folder"
            )
    if kind == "mp4":
        reason = mp4_unavailable()
        if reason is not None:
            raise AberrantError(f"--out {name}: cannot write .mp4: {reason}; write a .gif or a folder instead")
    return kind


def check_fps(fps: float) -> float:
    """``fps`` when it lies in :data:`FPS_RANGE`, else an error saying the range."""
    low, high = FPS_RANGE
    if not (math.isfinite(fps) and low <= fps <= high):
        raise AberrantError(f"--fps must lie in [{low:g}, {high:g}] frames per second, got {fps:g}")
    return fps


def check_gif_memory(frames: int, size: tuple[int, int]) -> None:
    """Refuse up front a GIF whose frames would not fit in the memory budget (they are all held at once)."""
    width, height = size
    check_fits(
        frames * width * height * GIF_BYTES_PER_PIXEL,
        f"a {frames}-frame {width}x{height} GIF",
        "write .mp4 or a folder of PNGs instead (streamed: constant memory), or fewer frames or a smaller --size",
    )


def mp4_unavailable() -> str | None:
    """``None`` when .mp4 can be written here, else why not."""
    try:
        import imageio_ffmpeg
    except ImportError:
        return "imageio-ffmpeg is not installed (pip install imageio-ffmpeg)"
    try:
        imageio_ffmpeg.get_ffmpeg_exe()
    except RuntimeError as e:
        return f"imageio-ffmpeg finds no ffmpeg executable ({e})"
    return None


def _even(rgb: np.ndarray) -> np.ndarray:
    """Pad to even width and height by repeating the last row/column (yuv420p needs even sides)."""
    h, w = rgb.shape[:2]
    return np.pad(rgb, ((0, h % 2), (0, w % 2), (0, 0)), mode="edge") if h % 2 or w % 2 else rgb


def _named(error: OSError, out: Path) -> OSError:
    """``error`` about the user's output, not about the temporary it was writing."""
    return OSError(error.errno, error.strerror or str(error), str(out))


class Ffmpeg:
    """An ffmpeg process encoding raw RGB frames from its stdin to H.264 in ``path``; its log kept off the terminal."""

    def __init__(self, path: Path, out: Path, size: tuple[int, int], fps: float) -> None:
        import imageio_ffmpeg

        self.out = out
        self.log: IO[bytes] = tempfile.TemporaryFile()  # noqa: SIM115 - lives as long as the process; closed by close()/abort()
        command = [
            imageio_ffmpeg.get_ffmpeg_exe(), "-y", "-v", "error", "-f", "rawvideo", "-vcodec", "rawvideo",
            "-s", f"{size[0]}x{size[1]}", "-pix_fmt", "rgb24", "-r", str(Fraction(fps).limit_denominator()),
            "-i", "-", "-an", "-vcodec", "libx264", "-pix_fmt", "yuv420p", "-crf", str(MP4_CRF), str(path),
        ]  # fmt: skip
        # Its own session: a Ctrl-C in the terminal reaches us, and we stop ffmpeg after cleaning up.
        self.process = subprocess.Popen(
            command, stdin=subprocess.PIPE, stdout=subprocess.DEVNULL, stderr=self.log, start_new_session=True
        )

    def send(self, frame: np.ndarray) -> None:
        assert self.process.stdin is not None
        try:
            self.process.stdin.write(np.ascontiguousarray(frame).tobytes())
        except OSError:  # ffmpeg exited (a full disk, a bad option): its log says why
            self.fail()

    def close(self) -> None:
        """Finish the file; an ffmpeg failure is an :class:`AberrantError` naming the output."""
        assert self.process.stdin is not None
        try:
            self.process.stdin.close()
        except OSError:
            self.fail()
        if self.process.wait() != 0:
            self.fail()
        self.log.close()

    def fail(self) -> NoReturn:
        self.abort(close_log=False)
        self.log.seek(0)
        lines = [_FFMPEG_PREFIX.sub("", line).strip() for line in self.log.read().decode(errors="replace").splitlines()]
        self.log.close()
        lines = [line for line in lines if line]
        reason = next((line for line in lines if "No space" in line), None) or (lines[0] if lines else "")
        code = self.process.returncode
        detail = reason or f"exit status {code}"
        if "No space left" in detail:
            raise _named(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC)), self.out)
        raise AberrantError(f"{shorten(self.out)}: cannot write the video (ffmpeg: {shorten(detail, 300)})")

    def abort(self, close_log: bool = True) -> None:
        """Stop ffmpeg now (an interrupted or failed run)."""
        with contextlib.suppress(OSError):
            assert self.process.stdin is not None
            self.process.stdin.close()
        if self.process.poll() is None:
            self.process.kill()
        self.process.wait()
        if close_log:
            self.log.close()


class Sink:
    """Frames in, one output out: written to a temporary, put in place by :meth:`commit`."""

    def __init__(self, out: Path, kind: str, fps: float) -> None:
        self.kind, self.fps = kind, fps
        self.name = out  # what messages say: the user's path
        if kind == "png":
            self.out = Path(os.path.realpath(out)) if out.is_symlink() else out
        else:
            self.out = check_target(out)  # a symlink's file: the link stays
        clean_stale_temps(self.out)  # what a killed run left here
        self.tmp = temp_path(self.out, ".mp4" if kind == "mp4" else "")
        self.frames: list[Image.Image] = []
        self.count = 0
        self.writer: Ffmpeg | None = None
        if kind == "png":
            try:
                self.tmp.mkdir()
            except OSError as e:
                raise _named(e, self.name) from e

    def add(self, rgb: np.ndarray) -> None:
        from PIL import Image

        if self.kind == "png":
            try:
                Image.fromarray(rgb).save(self.tmp / f"frame_{self.count:04d}.png")
            except OSError as e:
                raise _named(e, self.name) from e
        elif self.kind == "gif":
            # What Pillow's GIF writer converts each RGB frame to, done now: a third of the memory.
            self.frames.append(Image.fromarray(rgb).convert("P", palette=Image.Palette.ADAPTIVE))
        else:
            frame = _even(rgb)
            if self.writer is None:
                self.writer = Ffmpeg(self.tmp, self.name, (frame.shape[1], frame.shape[0]), self.fps)
            self.writer.send(frame)
        self.count += 1

    def commit(self) -> None:
        if self.kind == "gif":
            buffer = io.BytesIO()
            first, *rest = self.frames
            first.save(buffer, "GIF", save_all=True, append_images=rest, loop=0, duration=round(1000.0 / self.fps))
            self.frames.clear()
            write_atomically({self.out: buffer.getvalue()})
            return
        if self.kind == "mp4":
            assert self.writer is not None
            self.writer.close()
            self.writer = None
            try:
                os.replace(self.tmp, self.out)
            except OSError as e:
                raise _named(e, self.name) from e
            return
        self._swap_folder()

    def _swap_folder(self) -> None:
        """Put the frames folder in place; an earlier run's (or a concurrent run's) folder is moved aside first."""
        for _ in range(100):
            aside = temp_path(self.out, ".old")
            old: Path | None = aside
            try:
                os.rename(self.out, aside)
            except FileNotFoundError:
                old = None
            try:
                os.rename(self.tmp, self.out)
            except OSError as e:
                if e.errno not in (errno.ENOTEMPTY, errno.EEXIST):
                    if old is not None:
                        with contextlib.suppress(OSError):
                            os.rename(old, self.out)
                    raise _named(e, self.name) from e
                continue  # another run put its folder there in between: move that aside too
            finally:
                if old is not None and old.exists():
                    shutil.rmtree(old, ignore_errors=True)
            return
        raise AberrantError(f"--out {shorten(self.name)}: other runs keep replacing the folder; try again")

    def discard(self) -> None:
        if self.writer is not None:
            self.writer.abort()
            self.writer = None
        self.frames.clear()
        if self.tmp.is_dir():
            shutil.rmtree(self.tmp, ignore_errors=True)
        else:
            with contextlib.suppress(OSError):
                os.unlink(self.tmp)
