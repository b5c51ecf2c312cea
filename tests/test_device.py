"""Device choice: CUDA where there is a GPU, else the CPU, SERENITY_DEVICE over both, and a missing device
is a SerenityError."""

import pytest

from serenity import device as D
from serenity.errors import SerenityError


def test_default_is_cuda_where_there_is_a_gpu_else_the_cpu(monkeypatch):
    monkeypatch.delenv("SERENITY_DEVICE", raising=False)
    monkeypatch.setattr(D, "available_devices", lambda: ["cpu"])
    assert D.resolve_device(None) == "cpu"
    monkeypatch.setattr(D, "available_devices", lambda: ["cpu", "cuda:0"])
    assert D.resolve_device(None) == "cuda:0"
    monkeypatch.setenv("SERENITY_DEVICE", "cpu")
    assert D.resolve_device(None) == "cpu"


def test_missing_device_is_a_serenity_error():
    with pytest.raises(SerenityError, match="cuda:7"):
        D.resolve_device("cuda:7")
    with pytest.raises(SerenityError, match="tpu"):
        D.resolve_device("tpu")


def test_cuda_aliases(capsys):
    if "cuda:0" not in D.available_devices():
        pytest.skip("no CUDA device")
    assert D.resolve_device("cuda") == "cuda:0"
    assert D.resolve_device("cuda:0") == "cuda:0"
    assert capsys.readouterr().err == ""
