"""Results from several machines as one document: the report then compares backends across machines.

A merged row keeps its measurements and gains its machine's name in its label, family and backend
(``glsl f32 @ gpu-box``), so the headline, the plot and the tables hold one column or series per
backend per machine. Rows from one machine alone are left as they are.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from engine.errors import AberrantError, shorten

FORMAT = "aberrant-bench"


def read_results(path: Path) -> dict[str, Any]:
    """One results.json, checked to be a bench's; a bad one is one line naming the file."""
    try:
        results = json.loads(Path(path).read_text())
    except (OSError, ValueError) as e:
        raise AberrantError(f"--from-results {shorten(path)}: cannot read it ({e})") from None
    if not isinstance(results, dict) or results.get("format") != FORMAT or not isinstance(results.get("rows"), list):
        raise AberrantError(f"--from-results {shorten(path)}: not an aberrant bench results.json")
    results.pop("plot_note", None)
    return results


def machines_of(results: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """Name -> facts of every machine a document's rows ran on (older documents name one, unnamed)."""
    if isinstance(results.get("machines"), dict) and results["machines"]:
        return results["machines"]
    machine = results["machine"]
    return {machine.get("name", "?"): machine}


def _on(value: str, machine: str) -> str:
    return f"{value} @ {machine}"


def merge_results(documents: list[tuple[Path, dict[str, Any]]]) -> dict[str, Any]:
    """One document of every row of ``documents``; with more than one machine each row says which."""
    if len(documents) == 1:
        return documents[0][1]
    machines: dict[str, dict[str, Any]] = {}
    for _, results in documents:
        for name, info in machines_of(results).items():
            machines.setdefault(name, info)
    several = len(machines) > 1
    rows: list[dict[str, Any]] = []
    overhead: list[dict[str, Any]] = []
    settings: dict[str, dict[str, Any]] = {}
    scenes: dict[str, Any] = {}
    anchors: dict[str, Any] = {}
    for _, results in documents:
        default = next(iter(machines_of(results)))
        for row in results["rows"]:
            row = {**row, "machine": row.get("machine", default)}
            if several:
                machine = row["machine"]
                row.update(
                    label=_on(row["label"], machine),
                    family=_on(row["family"], machine),
                    backend=_on(row["backend"], machine),
                )
                setting = next((s for s in results["settings"] if s["label"] == row["label"].rsplit(" @ ", 1)[0]), None)
                if setting is not None:
                    settings.setdefault(row["label"], {**setting, "label": row["label"], "backend": row["backend"]})
            rows.append(row)
        for entry in results.get("overhead", []):
            machine = entry.get("machine", default)
            overhead.append({**entry, "backend": _on(entry["backend"], machine)} if several else entry)
        if not several:
            for setting in results["settings"]:
                settings.setdefault(setting["label"], setting)
        for name, info in results["scenes"].items():
            scenes.setdefault(name, info)
        for name, anchor in results.get("embree", {}).items():
            if name not in anchors or anchors[name].get("status") != "ok":
                anchors[name] = anchor
    first = documents[0][1]
    return {
        **first,
        "config": {**first["config"], "command": " + ".join(r["config"].get("command") or "?" for _, r in documents)},
        "duration_s": sum(r.get("duration_s", 0.0) for _, r in documents),
        "machine": next(iter(machines.values())),
        "machines": machines,
        "merged_from": [str(path) for path, _ in documents],
        "settings": list(settings.values()),
        "scenes": scenes,
        "embree": anchors,
        "rows": rows,
        "overhead": overhead,
    }
