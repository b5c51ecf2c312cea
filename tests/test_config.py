"""RenderConfig and its sub-configs reject what they cannot render with a SerenityError naming the field;
importing the config module loads neither Warp nor moderngl."""

import subprocess
import sys

import pytest

from serenity.config import LPVConfig, RenderConfig, ShadowConfig, SkyConfig, SSAOConfig
from serenity.errors import SerenityError


@pytest.mark.parametrize("kind, kw, field", [
    (RenderConfig, {"ssao": False}, "RenderConfig.ssao"),
    (RenderConfig, {"shadow": "pcss"}, "RenderConfig.shadow"),
    (RenderConfig, {"lpv": False}, "RenderConfig.lpv"),
    (RenderConfig, {"lpv": {"resolution": 16}}, "RenderConfig.lpv"),
    (RenderConfig, {"sky": 3}, "RenderConfig.sky"),
    (RenderConfig, {"transmissions": -1}, "RenderConfig.transmissions"),
    (RenderConfig, {"transmissions": 2.5}, "RenderConfig.transmissions"),
    (RenderConfig, {"exposure": 0.0}, "RenderConfig.exposure"),
    (ShadowConfig, {"filter_samples": 0}, "ShadowConfig.filter_samples"),
    (SSAOConfig, {"steps": 0}, "SSAOConfig.steps"),
    (SkyConfig, {"window": "box"}, "SkyConfig.window"),
    (SkyConfig, {"rays_per_probe": 0}, "SkyConfig.rays_per_probe"),
    (LPVConfig, {"cascades": 4}, "LPVConfig.cascades"),
    (LPVConfig, {"resolution": (16, 16)}, "LPVConfig.resolution"),
    (LPVConfig, {"forward_shift": 0.5}, "LPVConfig.forward_shift"),
    (LPVConfig, {"glossy_step": 0.0}, "LPVConfig.glossy_step"),
])
def test_bad_fields_name_themselves(kind, kw, field):
    with pytest.raises(SerenityError, match=field.replace(".", r"\.")):
        kind(**kw)


def test_good_settings_pass():
    cfg = RenderConfig(ssao=SSAOConfig(enabled=False), lpv=LPVConfig(resolution=8), sky=SkyConfig(enabled=False),
                       transmissions=0)
    assert cfg.lpv.enabled and not cfg.sky.enabled
    assert RenderConfig().lpv == LPVConfig() and RenderConfig().sky == SkyConfig()


def test_config_imports_no_warp_or_gl():
    code = ("import sys, serenity.config; "
            "print(sorted(m for m in ('warp', 'moderngl') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True).stdout
    assert out.strip() == "[]"
