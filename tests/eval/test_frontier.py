"""The equal-error speed-up: log-log interpolation on a peer curve, the three outcomes, and the chart."""

import math

import pytest

from serenity.errors import SerenityError
from serenity.eval.frontier import combine, describe, equal_error_speedup, goal_met, strongest, time_to_reach

# a power-law curve: error ∝ spp^-1/2 and time ∝ spp, so log-log interpolation is exact on it
SPP = (1, 2, 4, 8, 16)
CURVE = [(100.0 * n, 0.4 / math.sqrt(n)) for n in SPP]


def test_interpolation_is_exact_on_a_power_law():
    for n in (1.5, 3.0, 5.5, 11.0):
        r = time_to_reach(CURVE, 0.4 / math.sqrt(n))
        assert r["status"] == "reached"
        assert r["ms"] == pytest.approx(100.0 * n, rel=1e-12)


def test_points_themselves_and_the_first_crossing():
    assert time_to_reach(CURVE, CURVE[2][1])["ms"] == pytest.approx(CURVE[2][0])
    # a curve that dips below the target, comes back up and dips again: the first crossing counts
    wavy = [(100.0, 0.5), (200.0, 0.2), (400.0, 0.3), (800.0, 0.1)]
    r = time_to_reach(wavy, 0.25)
    assert r["status"] == "reached" and 100.0 < r["ms"] < 200.0
    # halfway in log error between 0.5 and 0.2 is halfway in log time
    r = time_to_reach(wavy, math.sqrt(0.5 * 0.2))
    assert r["ms"] == pytest.approx(math.sqrt(100.0 * 200.0))


def test_dominated_and_not_reached():
    r = equal_error_speedup(CURVE, our_ms=50.0, our_error=0.45)  # 1 spp (0.4) already better
    assert r["status"] == "dominated" and r["speedup"] is None
    assert r["bound"] == pytest.approx(100.0 / 50.0) and r["peer_ms"] == 100.0
    r = equal_error_speedup(CURVE, our_ms=50.0, our_error=0.01)  # 16 spp (0.1) still worse
    assert r["status"] == "not_reached" and r["peer_ms"] is None
    assert r["bound"] == pytest.approx(1600.0 / 50.0)
    assert goal_met(r) and describe(r) == "> 32× (not reached)"
    r = equal_error_speedup(CURVE, our_ms=32.0, our_error=0.2)  # reached at 4 spp, 400 ms
    assert r["status"] == "reached" and r["speedup"] == pytest.approx(12.5)
    assert goal_met(r) and not goal_met(r, goal=13.0)
    assert describe(r) == "12×" and describe({**r, "speedup": 2.345}) == "2.3×"
    assert "dominated" in describe(equal_error_speedup(CURVE, 50.0, 0.45))


def test_combine_takes_the_peer_s_fastest_way():
    slow = [(t * 3, e) for t, e in CURVE]
    fast = CURVE
    r = combine({"slow": equal_error_speedup(slow, 40.0, 0.2), "fast": equal_error_speedup(fast, 40.0, 0.2)})
    assert r["status"] == "reached" and r["curve"] == "fast" and r["speedup"] == pytest.approx(10.0)
    # one curve dominated at 300 ms, another reaches the error at 141 ms: dominated, bound from the faster
    r = combine({"slow": equal_error_speedup(slow, 50.0, 0.45),
                 "fast": equal_error_speedup([(50.0, 0.5)] + fast, 50.0, 0.45)})
    assert r["status"] == "dominated" and r["curve"] == "fast"
    assert 1.0 < r["bound"] < 2.0 and r["speedup"] is None
    r = combine({"slow": equal_error_speedup(slow, 50.0, 0.01), "fast": equal_error_speedup(fast, 50.0, 0.01)})
    assert r["status"] == "not_reached" and r["curve"] == "fast" and r["bound"] == pytest.approx(32.0)


def test_strongest_of_our_configs():
    results = {"low": equal_error_speedup(CURVE, 20.0, 0.45),  # dominated, bound 5
               "medium": equal_error_speedup(CURVE, 100.0, 0.2),  # reached: 4×
               "high": equal_error_speedup(CURVE, 500.0, 0.01)}  # not reached: > 3.2×
    assert strongest(results)[0] == "medium"
    del results["medium"]
    assert strongest(results)[0] == "high"  # a dominated config never leads while another is not
    assert strongest({"low": results["low"]})[0] == "low"
    with pytest.raises(SerenityError, match="at least one"):
        strongest({})


def test_bad_curves():
    with pytest.raises(SerenityError, match="at least one"):
        time_to_reach([], 0.1)
    with pytest.raises(SerenityError, match="finite and > 0"):
        time_to_reach([(100.0, 0.0)], 0.1)
    with pytest.raises(SerenityError, match="target error"):
        time_to_reach(CURVE, 0.0)
    with pytest.raises(SerenityError, match="frame time"):
        equal_error_speedup(CURVE, 0.0, 0.1)


def test_chart_png_is_written(tmp_path):
    pytest.importorskip("matplotlib")
    from serenity.eval.frontier import save_frontier_chart

    peer = {"raw": [{"spp": n, "ms": t, "flip": e, "rel_mse": 4 * e} for n, (t, e) in zip(SPP, CURVE, strict=True)],
            "high": [{"spp": n, "ms": t + 80, "flip": e / 2, "rel_mse": e} for n, (t, e) in
                     zip(SPP, CURVE, strict=True)]}
    ours = [{"name": "default", "ms": 60.0, "flip": 0.15, "rel_mse": 0.3}]
    sp = {m: combine({"high": equal_error_speedup([(p["ms"], p[m]) for p in peer["high"]], 60.0, ours[0][m])})
          for m in ("flip", "rel_mse")}
    out = save_frontier_chart([{"title": "test 32×18", "peer": peer, "ours": ours, "headline": "default",
                                "speedup": sp}], str(tmp_path / "f.png"))
    with open(out, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"
    with pytest.raises(SerenityError, match="at least one panel"):
        save_frontier_chart([], str(tmp_path / "g.png"))


def test_progressive_peer_accumulates_chunks(tmp_path, monkeypatch):
    pytest.importorskip("mitsuba")
    import numpy as np

    from serenity.eval.frontier import PEER_SEED_BASE, PathTracerPeer
    from serenity.scene.model import Sky
    from tests.raster.scenes import plane_scene

    s = plane_scene(with_box=True)
    s.sky = Sky(radiance=(20.0, 25.0, 30.0), model="constant")
    peer = PathTracerPeer(s, 24, 14, warmup=False)
    got = list(peer.progressive([1, 2, 4], repeat_below_s=0.0))
    assert [n for n, _, _ in got] == [1, 2, 4]
    assert got[0][2] < got[1][2] < got[2][2]  # time accumulates
    # 4 spp = (1 spp + 1 more + 2 more) / 4, each chunk with its own seed
    chunks = [peer.render(c, seed=PEER_SEED_BASE + n)[0] for c, n in ((1, 1), (1, 2), (2, 4))]
    np.testing.assert_allclose(got[2][1], (chunks[0] + chunks[1] + 2 * chunks[2]) / 4, rtol=1e-5, atol=1e-4)
    np.testing.assert_allclose(got[0][1], chunks[0])
    with pytest.raises(SerenityError, match="must rise"):
        list(peer.progressive([2, 2]))
