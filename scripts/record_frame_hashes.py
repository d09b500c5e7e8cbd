"""Re-record tests/data/frame_hashes.json after a deliberate change of pixels.

Run it only when a change is meant to alter what a demo looks like, and say why in the commit:
``python scripts/record_frame_hashes.py [DEMO ...]`` (all demos when none are named). Every
backend variant that can start on this machine is recorded; the devices are stored with them. A fast
backend's device other than the main record's goes under ``other_devices`` (``--main`` makes it the main
one), so each device keeps its own bits.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(ROOT), str(ROOT / "tests"), str(ROOT / "tests" / "demos")]

from test_frame_hashes import RECORD, SIZE, VARIANTS, device_of, frame_hash  # noqa: E402

from backends.base import backend_class  # noqa: E402
from demos import build_demo, demo_names  # noqa: E402
from systems.app import render_once  # noqa: E402


def main(argv: list[str]) -> int:
    main_device = "--main" in argv
    demos = [a for a in argv if a != "--main"] or demo_names()
    record = json.loads(RECORD.read_text())
    for backend_name, precision in VARIANTS:
        backend = backend_class(backend_name)(precision=None if backend_name == "reference" else precision)
        hashes = record["hashes"]
        if backend_name != "reference":
            device = device_of(backend)
            if main_device or record["devices"].get(backend_name) in (None, device):
                record["devices"][backend_name] = device
            else:
                hashes = record.setdefault("other_devices", {}).setdefault(backend_name, {}).setdefault(device, {})
        for demo in demos:
            scene = build_demo(demo)
            try:
                frame = render_once(scene, backend, size=SIZE)
            finally:
                scene.close()
            key = f"{demo}/{backend_name}-{precision}"
            new = frame_hash(frame)
            if hashes.get(key) != new:
                print(f"changed: {key}")
            hashes[key] = new
        backend.release()
    RECORD.write_text(json.dumps(record, indent=1, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
