"""Speed-vs-accuracy chart: the Pareto front and a PNG that gets written."""

import pytest

from serenity.errors import SerenityError

pytest.importorskip("matplotlib")

from serenity.eval.charts import pareto_front, save_speed_accuracy_chart  # noqa: E402

POINTS = [
    {"technique": "LPV", "label": "16³", "ms": 4.0, "error": 0.30},
    {"technique": "LPV", "label": "32³", "ms": 9.0, "error": 0.20, "paper": True},
    {"technique": "LPV", "label": "64³", "ms": 40.0, "error": 0.21},  # dominated by 32³
    {"technique": "ambient", "label": "constant", "ms": 0.5, "error": 0.45},
    {"technique": "sky volume", "label": "8 layers", "ms": 6.0, "error": 0.35},  # dominated by 16³
    {"technique": "sky volume", "label": "32 layers", "ms": 20.0, "error": 0.12},
]


def test_pareto_front():
    assert pareto_front(POINTS) == [3, 0, 1, 5]
    # ties in time: the lower error wins, the other is dominated
    assert pareto_front([{"ms": 1, "error": 2}, {"ms": 1, "error": 1}]) == [1]


def test_chart_png_is_written(tmp_path):
    out = save_speed_accuracy_chart(POINTS, str(tmp_path / "sub" / "chart.png"), error_name="relMSE",
                                    title="test")
    with open(out, "rb") as f:
        assert f.read(8) == b"\x89PNG\r\n\x1a\n"


def test_bad_points():
    with pytest.raises(SerenityError, match="at least one"):
        save_speed_accuracy_chart([], "x.png")
    with pytest.raises(SerenityError, match="ms must be"):
        save_speed_accuracy_chart([{"technique": "a", "ms": 0.0, "error": 1.0}], "x.png")
    with pytest.raises(SerenityError, match="needs technique"):
        save_speed_accuracy_chart([{"technique": "a", "error": 1.0}], "x.png")
