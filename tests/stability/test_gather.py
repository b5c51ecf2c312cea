"""The gathered probes (SkyConfig.method = "gather") where trilinear probes fail: a wall thinner than
a cell, lit on one side, must not light its other side (exact: 0)."""

from serenity.eval import stability as S


def test_thin_wall_does_not_leak_with_probe_visibility(device):
    """Measured (``gather_thin_wall_case``, 5 cm wall, 1 m cells, five positions across a cell):
    plain trilinear lets the lit side's probes light the dark face with up to 2.9× the lit face's
    irradiance when the wall sits near a probe plane; weighed by the probes' depth moments the worst
    is 4e-5 of it (the default offset) — the exact answer is 0."""
    case = S.gather_thin_wall_case(fracs=(0.1, 0.5, 0.9), device=device)
    assert case.error_without > 0.5
    assert case.error_with <= 0.01
