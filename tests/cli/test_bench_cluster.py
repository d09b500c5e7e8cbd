"""``aberrant bench`` on a Dask cluster: the same cells as one process, each naming its machine; merged reports."""

from __future__ import annotations

import io
import itertools
import json

import pytest

pytest.importorskip("distributed")

import aberrant.cluster as cluster
from aberrant.bench.results import write_outputs
from aberrant.bench.runner import make_config, run_bench
from aberrant.bench.spread import run_bench_on_cluster
from aberrant.cli import main


def tiny(out):
    """The reference and one fast backend on one scene at a small size, no sweeps: a few seconds."""
    config = make_config(
        scenes=["ten-boxes"], backends=["reference", "glsl"], size=(32, 24), repeat=1, out=out, sweeps=["none"],
        overhead=False,
    )  # fmt: skip
    config.embree = False
    return config


def cells(results):
    return [(r["scene"], r["label"], r["status"], r.get("errors")) for r in results["rows"]]


@pytest.fixture
def two_workers():
    made = cluster.local_cluster(2)
    try:
        yield made
    finally:
        made.close()


def test_two_workers_measure_the_cells_of_one_process_and_name_the_machine(tmp_path, two_workers):
    config = tiny(tmp_path / "out")
    alone = run_bench(config, io.StringIO())
    spread = run_bench_on_cluster(config, scheduler=two_workers.scheduler_address, stream=io.StringIO())
    assert cells(spread) == cells(alone) and len(cells(alone)) >= 2
    assert {r["machine"] for r in spread["rows"]} == set(spread["machines"]) == {alone["machine"]["name"]}
    assert all(r["device"] not in ("", "?") for r in spread["rows"])
    write_outputs(spread, config.out)
    assert "### ten-boxes" in (config.out / "report.md").read_text()


def test_cells_on_one_machine_never_overlap(tmp_path, two_workers):
    """Two workers on one host: the tasks' measuring spans, recorded by the workers, are disjoint."""
    config = tiny(tmp_path / "out")
    spread = run_bench_on_cluster(config, scheduler=two_workers.scheduler_address, stream=io.StringIO())
    spans = sorted((m["start"], m["end"]) for m in spread["spans"])
    assert len(spans) == 2
    assert all(a_end <= b_start for (_, a_end), (b_start, _) in itertools.pairwise(spans))


def test_results_of_two_machines_merge_into_one_report(tmp_path, capsys):
    config = tiny(tmp_path / "a")
    results = run_bench(config, io.StringIO())
    write_outputs(results, tmp_path / "a")
    other = json.loads((tmp_path / "a" / "results.json").read_text())
    other["machine"]["name"] = "gpu-box"
    other["machines"] = {"gpu-box": other["machine"]}
    for row in other["rows"]:
        row["machine"] = "gpu-box"
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "results.json").write_text(json.dumps(other))
    argv = ["bench", "--from-results", str(tmp_path / "a" / "results.json"), str(tmp_path / "b" / "results.json")]
    assert main([*argv, "--out", str(tmp_path / "merged")]) == 0
    merged = json.loads((tmp_path / "merged" / "results.json").read_text())
    here = results["machine"]["name"]
    assert set(merged["machines"]) == {here, "gpu-box"}
    assert len(merged["rows"]) == 2 * len(results["rows"])
    report = (tmp_path / "merged" / "report.md").read_text()
    assert f"glsl f32 @ {here}" in report and "glsl f32 @ gpu-box" in report
    assert "| machine |" in report.replace("| setting | machine |", "| machine |")


def test_an_unreachable_scheduler_is_one_line_exit_2(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 1.0)
    out = tmp_path / "out"
    argv = ["bench", "--quick", "--scenes", "ten-boxes", "--scheduler", "tcp://127.0.0.1:9", "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "cannot reach the scheduler" in err
    assert not out.exists()
