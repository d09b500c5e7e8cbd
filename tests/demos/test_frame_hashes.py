"""Every demo's frame on every backend variant hashes as recorded: moving code must not change a pixel.

The hashes were recorded at 48x36 over all five AOVs. The reference (float64 NumPy) is compared
everywhere; a fast backend's bits depend on its driver, so it is compared only on the devices the
hashes were recorded on (the main record's, and those under ``other_devices``) and skipped, with the device
named, elsewhere. A PoCL CPU device counts by the code PoCL generates for it (its LLVM target and PoCL's
version), not by the processor's brand in its name.
"""

from __future__ import annotations

import hashlib
import json
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import require_backend

from backends.base import AOVS, Backend, Frame
from demos import build_demo, demo_names
from systems.app import render_once

RECORD = Path(__file__).resolve().parents[1] / "data" / "frame_hashes.json"
SIZE = (48, 36)
VARIANTS = (("reference", "f64"), ("glsl", "f32"), ("opencl", "f32"), ("opencl", "f64"))


def frame_hash(frame: Frame) -> str:
    digest = hashlib.sha256()
    for aov in AOVS:
        digest.update(aov.encode())
        digest.update(np.ascontiguousarray(frame.aov(aov)).tobytes())
    return digest.hexdigest()


#: A PoCL CPU device's name: ``pthread-<LLVM target>-<processor brand>``; the target is lower case, the brand not.
_POCL_CPU_NAME = re.compile(r"^(?P<target>(?:pthread|basic|cpu)-[a-z0-9_.-]+?)-(?=[A-Z])")


def device_of(backend: Backend) -> str:
    info = dict(backend.info())
    if "pocl" in info and (match := _POCL_CPU_NAME.match(info.get("device", ""))):
        info["device"] = match["target"]
    return " / ".join(info[key] for key in ("renderer", "version", "device", "pocl") if key in info)


@pytest.mark.parametrize(("backend_name", "precision"), VARIANTS, ids=[f"{b}-{p}" for b, p in VARIANTS])
@pytest.mark.parametrize("demo", demo_names())
def test_demo_frame_is_bit_identical_to_the_record(
    demo: str, backend_name: str, precision: str, backend_factory
) -> None:
    record = json.loads(RECORD.read_text())
    require_backend(backend_name)
    backend = backend_factory(backend_name, precision if backend_name != "reference" else None)
    key = f"{demo}/{backend_name}-{precision}"
    hashes = record["hashes"]
    if backend_name != "reference" and (device := device_of(backend)) != record["devices"][backend_name]:
        others = record.get("other_devices", {}).get(backend_name, {})
        if device not in others:
            recorded = [record["devices"][backend_name], *others]
            pytest.skip(f"recorded on {', '.join(map(repr, recorded))}, this is {device!r}")
        hashes = others[device]
    scene = build_demo(demo)
    try:
        frame = render_once(scene, backend, size=SIZE)
    finally:
        scene.close()
    assert frame_hash(frame) == hashes[key]
