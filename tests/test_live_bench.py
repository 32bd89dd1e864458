"""The live latency benchmark runs the process and reports consistent figures."""

from tracking.live.latency_bench import format_result, measure_latency


def test_measure_latency_reports_percentiles_and_pace():
    r = measure_latency(seconds=1.5, size=(320, 240), fps=15.0, motion="reference")
    assert r["samples"] >= 1 and r["errors"] == 0
    lat = r["latency_ms"]
    assert 0 <= lat["p50"] <= lat["p99"] <= lat["max"]
    # each sample's latency is its publishing in the tracker process plus its way to the reader:
    # bounded by the parts (medians of the parts need not add up to the median of the sums when
    # the load makes one part of a few samples long)
    pub, way = r["publish_ms"], r["transport_ms"]
    assert max(pub["p50"], way["p50"]) - 1e-6 <= lat["max"]
    assert lat["p50"] <= pub["max"] + way["max"] + 1e-6
    assert 0 < r["fps_kept"] <= 16.0
    assert r["tracker_ms_mean"] > 0 and r["render_ms_mean"] > 0
    text = format_result(r)
    assert text.startswith("320x240: kept ") and "p99" in text
