"""`layerpilot bench scale` on the smallest survey it takes: every cost measured, the table, the JSON line last."""

from __future__ import annotations

import json

from layerpilot.cli import main


def test_bench_scale_measures_every_cost_and_prints_json_last(capsys) -> None:
    assert main(["bench", "scale", "--sides", "60", "--repeat", "1"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    result = json.loads(lines[-1])
    row = result["sides_m"]["60"]
    assert row["frames"] == 1 and row["window_cells"] == 100 and row["leaves"] > 1000
    assert 0 < row["observed_fraction"] < 1 and row["same_decision"]
    for key in ("insert_ms_per_frame", "columns_ms", "encode_ms", "decode_ms", "total_ms", "static_total_ms",
                "reference_distance_transform_ms"):
        assert row[key] > 0, key
    assert "60 m" in lines[2]
    assert main(["bench", "scale", "--sides", "10"]) == 2
    assert "each side must be within [50, 2000] m, got 10" in capsys.readouterr().err
