"""Interrupted saves: a process killed mid-save leaves the complete old file or the complete new one.

``save_scene`` writes ``.NAME.PID-RANDOM.tmp`` beside the target, fsyncs it and
renames it over the target. These tests SIGKILL real processes at varied
moments of that (20 kills at seeded random delays, plus one stopped exactly
mid-write) and check, after every kill, that the target parses and equals
one of the two versions being saved, byte for byte. A killed save can leave
its temporary behind; the next save of the same file removes every
temporary whose process is gone (or that is older than an hour), and never
one a live process is still writing.
"""

from __future__ import annotations

import os
import random
import re
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest

from engine.atomic_files import STALE_TEMP_SECONDS, clean_stale_temps
from engine.scene import Scene
from engine.scene_file import load_scene, save_scene, scene_to_json

ROOT = Path(__file__).resolve().parents[2]
KILLS = 20

pytestmark = pytest.mark.skipif(os.name != "posix", reason="SIGKILL and fork semantics are POSIX")

#: The child: loads the big scene, slows its writes down (so kills land mid-write often), says "ready",
#: then saves forever, alternating the scene's name between "A" and "B". With "stop-mid-write" it writes
#: half of the first save, says "writing" and sleeps, so the parent can kill it exactly there.
CHILD = textwrap.dedent(
    """
    import os, sys, time
    from engine.scene_file import load_scene, save_scene

    source, target, mode = sys.argv[1], sys.argv[2], sys.argv[3]
    scene = load_scene(source)
    real_fdopen = os.fdopen

    class SlowFile:
        def __init__(self, f):
            self.f = f

        def write(self, data):
            for i in range(0, len(data), 4096):
                if mode == "stop-mid-write" and i >= len(data) // 2:
                    self.f.flush()
                    print("writing", flush=True)
                    time.sleep(60)
                self.f.write(data[i : i + 4096])
                self.f.flush()
                time.sleep(0.0005)
            return len(data)

        def __getattr__(self, name):
            return getattr(self.f, name)

        def __enter__(self):
            return self

        def __exit__(self, *exc):
            self.f.close()

    os.fdopen = lambda fd, *args, **kwargs: SlowFile(real_fdopen(fd, *args, **kwargs))
    print("ready", flush=True)
    i = 0
    while True:
        scene.name = "A" if i % 2 == 0 else "B"
        save_scene(scene, target)
        i += 1
    """
)


def big_scene() -> Scene:
    """About 230 KB of JSON: 600 boxes."""
    scene = Scene("A")
    for i in range(600):
        scene.add_mesh(
            f"box_{i:04d}", "box", position=(i * 0.5, 0.25 * (i % 7), -1.0 * (i % 13)),
            euler_deg=(i % 90, 3 * i % 360, 0), scale=(1 + i % 3, 1, 0.5), color=(0.5, (i % 10) / 10, 0.2),
        )  # fmt: skip
    scene.set_camera((0.0, 1.0, 5.0), look_at=(0.0, 0.0, 0.0))
    return scene


def temps(target: Path) -> list[Path]:
    return sorted(target.parent.glob(f".{target.name}.*.tmp"))


def versions(source: Path, target: Path) -> dict[bytes, str]:
    """The exact bytes a save of the scene named "A" and "B" writes to ``target``."""
    scene = load_scene(source)
    try:
        out = {}
        for name in ("A", "B"):
            scene.name = name
            out[scene_to_json(scene, target.parent).encode()] = name
        return out
    finally:
        scene.close()


def start_child(source: Path, target: Path, mode: str) -> subprocess.Popen[str]:
    child = subprocess.Popen(
        [sys.executable, "-c", CHILD, str(source), str(target), mode],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    assert child.stdout is not None
    line = child.stdout.readline()
    if line.strip() != "ready":
        child.kill()
        pytest.fail(f"the saving child did not start: {line!r} {child.communicate()[1]}")
    return child


def kill(child: subprocess.Popen[str]) -> None:
    child.kill()  # SIGKILL: no cleanup handler of any kind runs
    child.wait(timeout=30)  # reaped: its PID no longer exists, so its temporary counts as stale
    assert child.returncode == -9


@pytest.fixture
def big_files(tmp_path: Path) -> tuple[Path, Path, dict[bytes, str]]:
    source = tmp_path / "source.json"
    scene = big_scene()
    try:
        save_scene(scene, source)
    finally:
        scene.close()
    target = tmp_path / "saves" / "big.json"
    target.parent.mkdir()
    expected = versions(source, target)
    target.write_bytes(next(data for data, name in expected.items() if name == "A"))
    return source, target, expected


def test_killed_saves_leave_the_old_or_the_new_file_never_a_mix(big_files):
    source, target, expected = big_files
    rng = random.Random(20240611)
    seen: dict[str, int] = {"A": 0, "B": 0}
    left_behind = 0
    killed: set[int] = set()
    for _ in range(KILLS):
        child = start_child(source, target, "loop")
        time.sleep(rng.uniform(0.0, 0.15))
        kill(child)
        killed.add(child.pid)
        data = target.read_bytes()
        assert data in expected, f"partial or mixed file after a kill: {len(data)} bytes"
        seen[expected[data]] += 1
        stray = temps(target)
        # Each save first removes the temporaries of dead processes, so at most one is ever left: this
        # child's, or the previous one's when this child died before its first save got that far.
        assert len(stray) <= 1, stray
        for tmp in stray:
            match = re.fullmatch(r"\.big\.json\.(\d+)-[0-9a-f]{8}\.tmp", tmp.name)
            assert match is not None and int(match.group(1)) in killed, tmp.name
        left_behind += len(stray)
    assert load_scene(target).name in ("A", "B")
    scene = load_scene(source)
    try:
        save_scene(scene, target)  # the next save cleans up what the last kill left
    finally:
        scene.close()
    assert temps(target) == []
    assert sorted(p.name for p in target.parent.iterdir()) == ["big.json"]
    print(f"{KILLS} kills: old/new file A {seen['A']}x, B {seen['B']}x; {left_behind} kills left a temporary")


def test_a_save_killed_mid_write_leaves_the_old_file_and_a_temp_the_next_save_removes(big_files):
    source, target, expected = big_files
    before = target.read_bytes()
    child = start_child(source, target, "stop-mid-write")
    assert child.stdout is not None
    assert child.stdout.readline().strip() == "writing"
    kill(child)
    assert target.read_bytes() == before
    [tmp] = temps(target)
    assert tmp.name.startswith(f".big.json.{child.pid}-")
    assert 0 < tmp.stat().st_size < len(before)  # the half-written new version, never the target itself
    scene = load_scene(source)
    try:
        scene.name = "B"
        save_scene(scene, target)
    finally:
        scene.close()
    assert expected[target.read_bytes()] == "B"
    assert temps(target) == []


# --- which temporaries the next save removes --------------------------------------------------------


def dead_pid() -> int:
    """A PID that existed a moment ago and has been reaped."""
    process = subprocess.Popen([sys.executable, "-c", "pass"])
    process.wait()
    return process.pid


def test_only_temporaries_of_dead_processes_or_old_ones_are_removed(tmp_path):
    target = tmp_path / "scene.json"
    target.write_text("{}")
    sleeper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"])
    try:
        dead = tmp_path / f".scene.json.{dead_pid()}-0123abcd.tmp"
        live = tmp_path / f".scene.json.{sleeper.pid}-0123abcd.tmp"
        old_live = tmp_path / f".scene.json.{sleeper.pid}-deadbeef.tmp"
        mine = tmp_path / f".scene.json.{os.getpid()}-00000000.tmp"
        keep = [
            live,
            mine,
            tmp_path / f".other.json.{dead_pid()}-0123abcd.tmp",  # another file's temporary
            tmp_path / ".scene.json.bak",
            tmp_path / "scene.json.tmp",
            tmp_path / ".scene.json.notapid-0123abcd.tmp",
        ]
        for path in [dead, old_live, *keep]:
            path.write_text("partial")
        hour_ago = time.time() - STALE_TEMP_SECONDS - 60
        os.utime(old_live, (hour_ago, hour_ago))
        assert sorted(clean_stale_temps(target)) == sorted([dead, old_live])
        assert all(path.exists() for path in keep)
        assert not dead.exists() and not old_live.exists()
    finally:
        sleeper.kill()
        sleeper.wait()


def test_save_scene_cleans_stale_temporaries_of_its_target(tmp_path):
    target = tmp_path / "scene.json"
    stale = tmp_path / f".scene.json.{dead_pid()}-0123abcd.tmp"
    stale.write_text('{"half": ')
    scene = Scene("x")
    try:
        save_scene(scene, target)
    finally:
        scene.close()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.json"]
