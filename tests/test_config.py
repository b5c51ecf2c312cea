"""RenderConfig rejects what it cannot render with a message naming the field."""

import pytest

from serenity.config import RenderConfig, SSAOConfig
from serenity.errors import SerenityError
from serenity.kernels.lpv import LPVConfig


@pytest.mark.parametrize("kw, field", [
    ({"ssao": False}, "ssao"),
    ({"shadow": "pcss"}, "shadow"),
    ({"lpv_settings": {"resolution": 16}}, "lpv_settings"),
    ({"sky_settings": 3}, "sky_settings"),
    ({"transmissions": -1}, "transmissions"),
    ({"transmissions": 2.5}, "transmissions"),
    ({"exposure": 0.0}, "exposure"),
])
def test_bad_fields_name_themselves(kw, field):
    with pytest.raises(SerenityError, match=field):
        RenderConfig(**kw)


def test_good_settings_pass():
    RenderConfig(ssao=SSAOConfig(enabled=False), lpv_settings=LPVConfig(resolution=8), transmissions=0)
