"""bench sensing judges each sensing preset against the log in one line: within 0.75-1.25 x in every bin of 50
samples or more, or a MISMATCH with the ratios' range (a preset describing another sensor than the log's)."""

from __future__ import annotations

from typing import Any

from tissue_retract.cli.bench_sensing import _agreement_line, agreement


def _result(pairs: list[tuple[int, float, float]]) -> dict[str, Any]:
    rows = [{"samples": n, "thin": n < 50, "logged": real, "preset": model} for n, real, model in pairs]
    return {"columns": ["logged", "preset"], "by_depth": rows[:1], "by_speed": rows[1:]}


def test_a_preset_within_the_band_in_every_full_bin_agrees() -> None:
    result = _result([(400, 2.0, 2.2), (300, 1.0, 0.8), (3, 10.0, 1.0)])  # the thin bin's 0.1 x is not judged
    verdict = agreement(result, "preset")
    assert verdict == {"within": True, "ratio_min": 0.8, "ratio_max": 1.1, "bins_judged": 2}
    result["agreement"] = {"preset": verdict}
    assert _agreement_line(result, "preset").startswith("  preset: within 0.75-1.25 x in every bin of 50")


def test_a_preset_outside_the_band_in_one_full_bin_is_a_mismatch() -> None:
    result = _result([(400, 7.0, 1.4), (300, 1.0, 1.0)])
    verdict = agreement(result, "preset")
    assert verdict["within"] is False and round(verdict["ratio_min"], 6) == 0.2
    result["agreement"] = {"preset": verdict}
    line = _agreement_line(result, "preset")
    assert line.startswith("  MISMATCH: preset is 0.20-1.00 x the error of 'logged'") and "another sensor" in line


def test_no_full_bin_is_no_verdict() -> None:
    result = _result([(10, 1.0, 1.0)])
    verdict = agreement(result, "preset")
    assert verdict["within"] is False and verdict["bins_judged"] == 0
    result["agreement"] = {"preset": verdict}
    assert "no bin of 50 samples or more" in _agreement_line(result, "preset")
