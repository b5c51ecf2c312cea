"""Device choice: the CPU unless CUDA is asked for, a CUDA choice says once that it is unverified, and a
missing device is a SerenityError."""

import pytest

from serenity import device as D
from serenity.errors import SerenityError


def test_default_is_the_cpu(monkeypatch):
    monkeypatch.delenv("SERENITY_DEVICE", raising=False)
    assert D.resolve_device(None) == "cpu"
    monkeypatch.setenv("SERENITY_DEVICE", "cpu")
    assert D.resolve_device(None) == "cpu"


def test_missing_device_is_a_serenity_error():
    with pytest.raises(SerenityError, match="cuda:7"):
        D.resolve_device("cuda:7")
    with pytest.raises(SerenityError, match="tpu"):
        D.resolve_device("tpu")


def test_cuda_says_once_that_it_is_unverified(monkeypatch, capsys):
    if "cuda:0" not in D.available_devices():
        pytest.skip("no CUDA device")
    monkeypatch.setattr(D, "_cuda_noted", False)
    assert D.resolve_device("cuda") == "cuda:0"
    assert D.resolve_device("cuda:0") == "cuda:0"
    err = capsys.readouterr().err
    assert err.count("unverified") == 1 and len(err.strip().splitlines()) == 1
