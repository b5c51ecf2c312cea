"""`serenity reference` and `serenity compare` end to end (tiny sizes)."""

import numpy as np
import pytest

from serenity.cli import main
from serenity.io.exr import read_exr, write_exr
from serenity.io.png import read_png, write_png

pytest.importorskip("mitsuba")
pytest.importorskip("flip_evaluator")


@pytest.fixture(autouse=True)
def _cache(tmp_path, monkeypatch):
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))


def test_reference_then_compare(tmp_path, capsys):
    ref = str(tmp_path / "ref.exr")
    assert main(["reference", "plane", "--size", "32x18", "--spp", "4", "--component", "direct", "-q",
                 "-o", ref]) == 0
    out = capsys.readouterr().out
    assert "32x18, 4 spp, component direct" in out and "from the cache" not in out
    floor = out.split("noise floor (two halves of 2 spp): FLIP ")[1].split()
    assert 0 < float(floor[0].rstrip(",")) < 1 and floor[1] == "relMSE" and float(floor[2]) > 0
    img = read_exr(ref)["beauty"]
    assert img.shape == (18, 32, 3) and img.max() > 100
    assert main(["reference", "plane", "--size", "32x18", "--spp", "4", "--depth", "2", "-q", "-o", ref]) == 0
    assert "from the cache" in capsys.readouterr().out  # depth 2 is the direct component

    ours = str(tmp_path / "ours.exr")
    write_exr(ours, {"beauty": img * 1.1, "depth": np.ones((18, 32, 1), np.float32)})
    mask = np.zeros((18, 32, 3), np.uint8)
    mask[:, :16] = 255
    write_png(str(tmp_path / "mask.png"), mask)
    flip_png = str(tmp_path / "flip.png")
    assert main(["compare", ours, ref, "--mask", str(tmp_path / "mask.png"), "-o", flip_png]) == 0
    out = capsys.readouterr().out
    assert "relMSE" in out and "FLIP" in out and "over 288 masked pixels" in out
    rel = float(out.split("relMSE")[1].split()[0])
    covered = img[:, :16] > 0
    assert rel == pytest.approx(0.01 * covered.mean(), rel=0.05)
    assert read_png(flip_png).shape == (18, 32, 3)


def test_one_line_errors(tmp_path, capsys):
    assert main(["reference", "no-such-scene", "-o", str(tmp_path / "x.exr")]) == 2
    assert "serenity: error:" in capsys.readouterr().err
    a = str(tmp_path / "a.exr")
    b = str(tmp_path / "b.exr")
    write_exr(a, {"beauty": np.ones((4, 4, 3), np.float32)})
    write_exr(b, {"beauty": np.ones((5, 4, 3), np.float32)})
    assert main(["compare", a, b]) == 2
    assert "shape mismatch" in capsys.readouterr().err
    assert main(["compare", a, a, "--layer", "albedo"]) == 2
    assert "no layer 'albedo'" in capsys.readouterr().err
