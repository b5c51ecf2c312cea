"""Per-region error report (``serenity.eval.regions``) and ``serenity compare --regions``."""

import json

import numpy as np
import pytest

from serenity.cli import main
from serenity.errors import SerenityError
from serenity.eval.metrics import flip, rel_mse
from serenity.eval.regions import format_region_report, region_masks, region_report
from serenity.io.exr import write_exr

pytest.importorskip("flip_evaluator")

H, W = 24, 40


def _aovs():
    """Top 6 rows sky, then an up-facing band, a vertical band, a down-facing band; material = band."""
    normal = np.zeros((H, W, 3), np.float32)
    depth = np.full((H, W, 1), 5.0, np.float32)
    material = np.full((H, W, 1), -1.0, np.float32)
    depth[:6] = np.inf
    normal[6:12] = (0, 1, 0)
    normal[12:18] = (0.8, 0.1, 0.59)
    normal[18:] = (0, -1, 0)
    material[6:12], material[12:18], material[18:] = 0, 1, 2
    depth[12:18] = 3.0  # a depth step at rows 11/12 and 17/18
    return normal, depth, material


def _ref():
    rng = np.random.default_rng(3)
    return (20.0 + 10.0 * rng.random((H, W, 3))).astype(np.float32)


def test_masks_partition_the_image():
    normal, depth, material = _aovs()
    regions, materials = region_masks(normal, depth, material, ["ground", "wall"])
    four = [regions[k] for k in ("sky", "up-facing", "down-facing", "vertical")]
    assert np.array_equal(sum(m.astype(int) for m in four), np.ones((H, W), int))
    assert regions["sky"][:6].all() and regions["up-facing"][6:12].all()
    assert regions["vertical"][12:18].all() and regions["down-facing"][18:].all()
    # edges: sky/ground boundary and both sides of the two depth steps
    assert regions["edges"][[5, 6, 11, 12, 17, 18]].all() and not regions["edges"][[0, 8, 14, 21]].any()
    assert list(materials) == ["ground", "wall", "material 2"]  # unnamed index falls back to its number
    assert np.array_equal(materials["wall"], regions["vertical"])


def test_region_figures_match_masked_metrics_and_luminance_ratio():
    normal, depth, material = _aovs()
    ref = _ref()
    ours = ref.copy()
    ours[18:] *= 0.5  # the down-facing band at half the reference's brightness, the rest exact
    rep = region_report(ours, ref, normal, depth, material)
    down = rep["regions"]["down-facing"]
    assert down["luminance_ratio"] == pytest.approx(0.5, rel=1e-6)
    assert rep["regions"]["up-facing"]["luminance_ratio"] == pytest.approx(1.0)
    mask = np.zeros((H, W), bool)
    mask[18:] = True
    assert down["rel_mse"] == pytest.approx(rel_mse(ours, ref, mask), rel=1e-6)
    assert down["flip"] == pytest.approx(flip(ours, ref, mask), rel=1e-5)
    assert rep["all"]["rel_mse"] == pytest.approx(rel_mse(ours, ref), rel=1e-6)
    # all of the relMSE sits in the band (FLIP leaks a little across its boundary: its filters are wide)
    assert down["rel_mse_share"] == pytest.approx(1.0)
    assert rep["regions"]["sky"]["rel_mse_share"] == 0.0
    shares = sum(rep["regions"][k]["flip_share"] for k in ("sky", "up-facing", "down-facing", "vertical"))
    assert shares == pytest.approx(1.0)
    assert rep["materials"]["material 2"]["rel_mse"] == pytest.approx(down["rel_mse"])
    text = format_region_report(rep)
    assert "down-facing" in text and "0.500" in text and "by material:" in text


def test_bad_aovs_are_one_line_errors():
    normal, depth, _ = _aovs()
    ref = _ref()
    with pytest.raises(SerenityError, match="normal layer"):
        region_report(ref, ref, normal[..., :2], depth)
    with pytest.raises(SerenityError, match="shape mismatch"):
        region_report(ref[:, :20], ref[:, :20], normal, depth)


def test_compare_regions_cli(tmp_path, capsys):
    normal, depth, material = _aovs()
    ref = _ref()
    ours = ref * np.float32(1.2)
    a, b, j = str(tmp_path / "ours.exr"), str(tmp_path / "ref.exr"), str(tmp_path / "regions.json")
    write_exr(a, {"beauty": ours, "normal": normal, "depth": depth, "material": material})
    write_exr(b, {"beauty": ref})
    assert main(["compare", a, b, "--regions", "--json", j]) == 0
    out = capsys.readouterr().out
    assert "up-facing" in out and "material 1" in out
    rep = json.load(open(j))
    assert rep["regions"]["vertical"]["luminance_ratio"] == pytest.approx(1.2, rel=1e-5)
    # the reference has no AOVs; asking for regions from it is a one-line error
    assert main(["compare", b, a, "--regions"]) == 2
    assert "needs the layer(s) normal, depth" in capsys.readouterr().err
    assert main(["compare", a, b, "--json", j]) == 2
    assert "go with --regions" in capsys.readouterr().err


def test_leak_ratio_finds_light_in_a_dark_region_not_in_noise():
    """A reference with a dark quarter (1 % of the rest's light): ours with the same image has ratio
    ~1 there; ours with a 6 × 6 patch at 10× the reference's light inside the dark quarter reads
    max ratio ~10 and some boxes over 4; one lone bright pixel (a firefly, 5 × 5 boxes) stays under 4."""
    from serenity.eval.regions import leak_ratio

    ref = np.full((60, 80, 3), 10.0)
    ref[30:, 40:] = 0.1
    same = leak_ratio(ref, ref)
    assert same["max_ratio"] == pytest.approx(1.0) and same["over_4"] == 0.0
    assert same["dark_fraction"] == pytest.approx(0.25, abs=0.03)
    leak = ref.copy()
    leak[40:46, 55:61] = 1.0
    r = leak_ratio(leak, ref)
    assert 9.0 <= r["max_ratio"] <= 10.5 and r["over_4"] > 0.0
    firefly = ref.copy()
    firefly[45, 60] = 0.1 * 3.0 * 25 / 2  # a box mean of 2.5x the dark level at most
    assert leak_ratio(firefly, ref)["max_ratio"] < 4.0
    assert leak_ratio(np.full((8, 8, 3), 1.0), np.full((8, 8, 3), 1.0))["max_ratio"] is None  # nothing dark
    with pytest.raises(SerenityError, match="shape mismatch"):
        leak_ratio(ref[:10], ref)
