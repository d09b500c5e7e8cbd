"""Several samples a pixel: the centre first, colour averaged, the same on every backend."""

from __future__ import annotations

import numpy as np
import pytest

from aberrant.cli import main
from backends.samples import MAX_SPP, check_spp, subpixel_offsets
from demos import starter
from engine.errors import AberrantError
from systems.app import render_once

SIZE = (48, 36)


def frame_of(backend, spp: int):
    """The starter demo at SIZE and ``spp`` samples a pixel."""
    scene = starter.build()
    try:
        return render_once(scene, backend, SIZE, spp=spp)
    finally:
        scene.close()


def test_offsets_start_at_the_centre_and_spread_over_the_pixel():
    points = subpixel_offsets(16)
    assert tuple(points[0]) == (0.5, 0.5)
    assert np.all((points >= 0.0) & (points < 1.0))
    assert len({tuple(p) for p in points}) == 16
    for quarter in ((0, 0), (0, 1), (1, 0), (1, 1)):  # every quarter of the pixel holds a point of the first 8
        assert np.any(np.all((points[:8] >= 0.5 * np.array(quarter)) & (points[:8] < 0.5 * np.array(quarter) + 0.5), 1))


@pytest.mark.parametrize("bad", [0, MAX_SPP + 1, -3, 2.5, True, "4"])
def test_a_bad_count_is_refused(bad):
    with pytest.raises(AberrantError, match="spp"):
        check_spp(bad)


def test_one_sample_is_the_plain_frame(backend_factory):
    backend = backend_factory("reference")
    scene = starter.build()
    try:
        plain = render_once(scene, backend, SIZE)
        one = render_once(scene, backend, SIZE, spp=1)
    finally:
        scene.close()
    for name in plain.present():
        assert np.array_equal(plain.aov(name), one.aov(name)), name


def test_four_samples_blend_an_edge_and_keep_the_centre_aovs(backend_factory):
    backend = backend_factory("reference")
    one, four = frame_of(backend, 1), frame_of(backend, 4)
    for name in ("depth", "instance", "perceived", "events"):
        assert np.array_equal(one.aov(name), four.aov(name)), name
    centre = one.instance[1:-1, 1:-1]
    inside = (centre == one.instance[1:-1, 2:]) & (centre == one.instance[1:-1, :-2])
    edge = centre != one.instance[1:-1, 2:]
    assert edge.sum() > 10
    c1, c4 = one.color[..., :3].astype(int), four.color[..., :3].astype(int)
    # Every sample lies in its pixel, so an edge pixel's mean lies between the colours either side of it
    # (all but a few, where a checker's line crosses the pixel away from its neighbours' centres).
    stack = np.stack([c1[y : y + c1.shape[0] - 2, x : x + c1.shape[1] - 2] for y in range(3) for x in range(3)])
    lo, hi = stack.min(axis=0), stack.max(axis=0)
    mid = c4[1:-1, 1:-1]
    between = np.all((mid[edge] >= lo[edge] - 2) & (mid[edge] <= hi[edge] + 2), axis=1)
    assert between.mean() > 0.9, f"{between.mean():.1%}"
    assert np.mean(np.any(mid[edge] != c1[1:-1, 1:-1][edge], axis=1)) > 0.5  # most edge pixels are blended
    assert np.median(np.abs(mid[inside] - c1[1:-1, 1:-1][inside])) <= 1  # most of a surface stays as it was


def test_samples_are_deterministic(backend_factory):
    backend = backend_factory("reference")
    assert np.array_equal(frame_of(backend, 4).color, frame_of(backend, 4).color)


@pytest.mark.parametrize("precision", ["f32", "f64"])
@pytest.mark.parametrize("name", ["glsl", "opencl"])
def test_four_samples_agree_with_the_reference(backend_factory, name, precision):
    ref, fast = frame_of(backend_factory("reference"), 4), frame_of(backend_factory(name, precision), 4)
    same = fast.instance == ref.instance
    assert same.mean() > 0.99
    off = np.abs(fast.color.astype(int) - ref.color.astype(int)).max(axis=2) > 2
    assert off.mean() <= 0.01, f"{off.mean():.3%} of pixels off by more than 2 levels"


@pytest.mark.parametrize("value", ["0", "257"])
def test_the_command_line_refuses_a_bad_count(tmp_path, capsys, value):
    out = tmp_path / "frame.png"
    assert main(["render", "starter", "--backend", "reference", "--spp", value, "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--spp" in err[0] and not out.exists()


def test_the_command_line_renders_samples(tmp_path, capsys):
    out = tmp_path / "frame.png"
    args = ["render", "starter", "--backend", "reference", "--size", "16x12", "--spp", "2", "--out", str(out)]
    assert main(args) == 0
    assert out.exists() and "2 samples a pixel" in capsys.readouterr().out
