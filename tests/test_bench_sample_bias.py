"""benchmarks/bench_sample_bias.py: its table of the sampled level's figures over the full level's."""

from __future__ import annotations

import importlib.util
from pathlib import Path

BENCH = Path(__file__).resolve().parent.parent / "benchmarks" / "bench_sample_bias.py"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_sample_bias", BENCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_table_has_a_row_of_ratios_per_scheme(tmp_path):
    bench = _bench()
    out = tmp_path / "bias.md"
    assert bench.main(["--scene", "default", "--size", "48", "--schemes", "zbuffer,linked-list",
                       "--gpu-set", "sample.min_tiles=1", "--report", str(out)]) == 0
    lines = out.read_text().splitlines()
    head = [c.strip() for c in lines[2].strip("|").split("|")]
    assert head[:4] == ["scheme", "cycles", "cycles, operations' bytes", "coalescer requests"]
    assert head[-1] == "speed-up"
    rows = {cells[0]: cells for cells in ([c.strip() for c in line.strip("|").split("|")]
                                          for line in lines[4:] if line.startswith("| "))}
    assert sorted(rows) == ["linked-list", "zbuffer"]
    for cells in rows.values():
        assert len(cells) == len(head)
        assert 0.5 < float(cells[1]) < 2.0           # the sampled cycles over the full level's
        assert 0.5 < float(cells[2]) < 2.0           # the sample without the run's coalesced traffic
        assert all(0 < int(sms) < 30 for sms in cells[-2].split("/"))   # a share of gtx280's 30 SMs
    assert rows["zbuffer"][head.index("L2 misses")] == "-"      # gtx280 has no L2


def test_a_ratio_without_a_full_figure_is_a_dash():
    bench = _bench()
    assert bench.ratio(3, 2) == "1.500"
    assert bench.ratio(None, 2) == bench.ratio(3, None) == bench.ratio(3, 0) == "-"


def test_the_runs_coalesced_traffic_gives_the_sample_the_runs_dram_busy_time():
    from gpusim.hw import load_gpu
    from gpusim.replay import run_functional
    from gpusim.scene import load_scene, trace_scene
    bench = _bench()
    trace = trace_scene(*load_scene("default", ["screen.width=64", "screen.height=64"]), progress=False)
    gpu = load_gpu("gtx280", ["runner.workers=1", "sample.min_tiles=1"])
    result, _, reference = run_functional(trace, "tfss", {})
    records = bench.compare(result, trace, gpu, reference)
    busy = {level: float(rec["units"]["dram"]["busy_cycles"]) for level, rec in records.items()}
    # scaled by its operations' bytes, the sample's DRAM is 11% busier than the run's: its warps coalesce worse;
    # set from the run's coalesced bytes, as busy as the run's
    assert abs(busy["ops"] - busy["full"]) > 0.05 * busy["full"]
    assert abs(busy["sampled"] - busy["full"]) < 0.02 * busy["full"]
