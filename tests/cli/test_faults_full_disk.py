"""A really full disk (a tiny tmpfs, filled) under every writer, and messages quoting huge names.

Each writer fails with one line naming the output (never ffmpeg's own log or
command line), exit 2, and leaves the folder as it was: no temporary, no
half-written file, no meshes folder of an import that did not finish. Mounting
needs root (or CAP_SYS_ADMIN); where it cannot be done the tmpfs tests skip
with the reason, and the full disk is simulated in tests/cli/test_faults.py.
"""

from __future__ import annotations

import errno
import os
import shutil
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from test_fuzz_scene_files import run_cli

from aberrant.sinks import mp4_unavailable
from demos import build_demo
from engine.scene_file import SceneFileError, save_scene

ROOT = Path(__file__).resolve().parents[2]
TELLO = ROOT / "tests" / "data" / "tello"
FREE = 12 * 1024  # bytes left free: a 16x12 PNG fits, a 64x48 flythrough and an import do not
FILLER = "filler"


@pytest.fixture
def full_disk(tmp_path: Path) -> Iterator[Path]:
    """A 1 MiB tmpfs with only ``FREE`` bytes left."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if shutil.which("mount") is None:
        pytest.skip("no mount(8) to make a small file system with")
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=1m", "tmpfs", str(disk)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {mounted.stderr.decode(errors='replace').strip()}")
    try:
        (disk / FILLER).touch()
        fill(disk, FREE)  # real blocks (fallocate), not a sparse file
        yield disk
    finally:
        subprocess.run(["umount", str(disk)], check=True)


def fill(disk: Path, free: int) -> None:
    """Grow the filler until only ``free`` bytes are left."""
    st = os.statvfs(disk)
    fd = os.open(disk / FILLER, os.O_WRONLY)
    try:
        os.posix_fallocate(fd, 0, os.fstat(fd).st_size + st.f_bavail * st.f_frsize - free)
    finally:
        os.close(fd)


def assert_one_line_about(code: int, stderr: str, target: Path) -> None:
    assert code == 2, stderr
    lines = [line for line in stderr.splitlines() if not line.startswith("flythrough [")]  # the progress bar
    assert len(lines) == 1 and lines[0].startswith("aberrant: error: "), stderr
    assert str(target) in lines[0] and "No space left on device" in lines[0], lines[0]
    assert "ffmpeg" not in lines[0].lower() or "No space" in lines[0]
    assert ".tmp" not in lines[0], lines[0]


def assert_only_the_filler(disk: Path) -> None:
    assert sorted(p.name for p in disk.iterdir()) == [FILLER]


def test_render_onto_a_full_disk(full_disk):
    out = full_disk / "frame.png"
    code, _, stderr = run_cli(["render", "starter", "--backend", "reference", "--size", "320x240", "--out", str(out)])
    assert_one_line_about(code, stderr, out)
    assert_only_the_filler(full_disk)


@pytest.mark.parametrize("name", ["walk.gif", "frames", "walk.mp4"])
def test_a_flythrough_onto_a_full_disk(full_disk, name):
    if name.endswith(".mp4") and mp4_unavailable() is not None:
        pytest.skip(f"cannot write .mp4 here: {mp4_unavailable()}")
    out = full_disk / name
    argv = ["render", "starter", "--path", "--frames", "12", "--size", "96x72", "--backend", "reference"]
    code, _, stderr = run_cli([*argv, "--out", str(out)])
    assert_one_line_about(code, stderr, out)
    assert_only_the_filler(full_disk)


def test_save_scene_onto_a_full_disk(full_disk):
    scene = build_demo("starter")
    try:
        with pytest.raises(SceneFileError) as failure:
            for i in range(50):  # ~5 KB each: the disk fills within a few
                save_scene(scene, full_disk / f"scene{i}.json")
    finally:
        scene.close()
    assert "No space left on device" in str(failure.value) and ".tmp" not in str(failure.value)
    assert not [p for p in full_disk.iterdir() if ".tmp" in p.name]


def test_import_tello_onto_a_full_disk_leaves_no_meshes_folder(full_disk):
    scene_file = TELLO / "Scenes" / "AberrationRoom"  # five small meshes and the scene: more than one page
    fill(full_disk, 4096)
    out = full_disk / "imported.json"
    code, _, stderr = run_cli(["import-tello", str(scene_file), "--mesh-dir", str(TELLO / "Mesh"), "--out", str(out)])
    assert code == 2, stderr
    [line] = stderr.splitlines()
    assert "No space left on device" in line and ".tmp" not in line, line
    assert_only_the_filler(full_disk)


def test_enospc_from_any_writer_names_the_file_in_one_line(tmp_path, monkeypatch):
    """Without a tmpfs: the PNG writer of a frames folder fails as a full disk does."""
    from PIL import Image

    def full(self: Image.Image, fp: object, *args: object, **kwargs: object) -> None:
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(Image.Image, "save", full)
    out = tmp_path / "frames"
    code, _, stderr = run_cli(["render", "starter", "--path", "--frames", "2", "--size", "16x12",
                               "--backend", "reference", "--out", str(out)])  # fmt: skip
    monkeypatch.undo()
    assert_one_line_about(code, stderr, out)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("length", [10_000, 10_000_000])
def test_an_error_quoting_a_huge_name_is_one_short_line(tmp_path, length):
    name = "x" * length
    code, _, stderr = run_cli(["render", name, "--backend", "reference", "--size", "8x6", "--out", str(tmp_path / "o")])
    assert code == 2
    [line] = stderr.splitlines()
    assert len(line) < 1200 and f"({length:,} characters)" in line and "is neither a scene file" in line


def test_ffmpeg_says_nothing_on_the_terminal_when_the_disk_fills(full_disk):
    """In a child process, so ffmpeg's own stderr (a file descriptor it inherits) would be seen too."""
    if mp4_unavailable() is not None:
        pytest.skip(f"cannot write .mp4 here: {mp4_unavailable()}")
    out = full_disk / "walk.mp4"
    argv = ["render", "starter", "--path", "--frames", "12", "--size", "96x72", "--backend", "reference"]
    result = subprocess.run(
        [sys.executable, "-m", "aberrant.cli", *argv, "--out", str(out)], cwd=ROOT, capture_output=True, text=True
    )
    assert_one_line_about(result.returncode, result.stderr, out)
    assert_only_the_filler(full_disk)
