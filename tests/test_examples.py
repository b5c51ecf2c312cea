"""The user-facing examples run: each on a tiny image of the plane scene, writing what it says."""

from __future__ import annotations

import importlib.util
import os

import numpy as np
import pytest

EXAMPLES = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), "examples")

pytestmark = pytest.mark.gl


def _example(name: str):
    spec = importlib.util.spec_from_file_location(name, os.path.join(EXAMPLES, f"{name}.py"))
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_render_your_model_writes_png_and_exr(tmp_path, capsys):
    from PIL import Image

    from serenity.io.exr import read_exr

    example = _example("render_your_model")
    assert os.path.exists(example.BREAKFAST_ROOM)  # the default model ships with the repository
    png = tmp_path / "out" / "plane.png"
    assert example.main(["plane", "--size", "24x16", "-o", str(png)]) == 0
    assert Image.open(png).size == (24, 16)
    layers = read_exr(str(png.with_suffix(".exr")))
    assert layers["beauty"].shape == (16, 24, 3) and np.all(np.isfinite(layers["beauty"]))
    assert "depth" in layers and "wrote" in capsys.readouterr().out
    assert example.main([str(tmp_path / "missing.obj")]) == 2
    assert "missing.obj" in capsys.readouterr().err


@pytest.mark.slow  # ~50 s: the reference's sky map and Mitsuba's start dominate even at 24x16
def test_compare_with_reference_prints_flip_and_relmse(tmp_path, capsys, monkeypatch):
    pytest.importorskip("mitsuba")
    pytest.importorskip("flip_evaluator")
    pytest.importorskip("matplotlib")
    from PIL import Image

    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    png = tmp_path / "cmp.png"
    code = _example("compare_with_reference").main(["plane", "--size", "24x16", "--spp", "4", "-o", str(png)])
    assert code == 0
    out = capsys.readouterr().out
    assert "FLIP" in out and "relMSE" in out
    assert Image.open(png).size == (3 * 24, 16)  # ours | reference | FLIP map
