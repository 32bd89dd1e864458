"""The live latency benchmark runs the process and reports consistent figures."""

import math

from tracking.live.bench import format_result, measure_latency


def test_measure_latency_reports_percentiles_and_pace():
    r = measure_latency(seconds=1.5, size=(320, 240), fps=15.0, motion="reference")
    assert r["samples"] >= 1 and r["errors"] == 0
    lat = r["latency_ms"]
    assert 0 <= lat["p50"] <= lat["p99"] <= lat["max"]
    # the parts add up: publishing in the tracker process plus the way to the reader
    assert math.isclose(r["publish_ms"]["p50"] + r["transport_ms"]["p50"], lat["p50"], rel_tol=0.5, abs_tol=2.0)
    assert 0 < r["fps_kept"] <= 16.0
    assert r["tracker_ms_mean"] > 0 and r["render_ms_mean"] > 0
    text = format_result(r)
    assert text.startswith("320x240: kept ") and "p99" in text
