"""Shared fixtures: the compute ``device`` (cpu always, each CUDA device when present) and one
headless GL context per session.

``SERENITY_TEST_DEVICES=cpu`` (or ``cuda:0``, or ``cpu,cuda:0``) narrows the device list.
"""

from __future__ import annotations

import os

import pytest


def _test_devices() -> list[str]:
    from serenity.device import available_devices

    devs = available_devices()
    want = os.environ.get("SERENITY_TEST_DEVICES")
    if want:
        devs = [d for d in devs if d in {w.strip() for w in want.split(",")}]
    return devs


def pytest_generate_tests(metafunc):
    if "device" in metafunc.fixturenames:
        metafunc.parametrize("device", _test_devices())


@pytest.fixture(scope="session")
def cuda_devices() -> list[str]:
    return [d for d in _test_devices() if d.startswith("cuda")]


@pytest.fixture(scope="session")
def artifacts_dir():
    """Where failing tests write ours/ref/diff images (``tests/_artifacts/``)."""
    path = os.path.join(os.path.dirname(__file__), "_artifacts")
    os.makedirs(path, exist_ok=True)
    return path
