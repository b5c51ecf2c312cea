"""The tracer process's hand-over of the scene: a file in memory (``SCENE_DIR``) the child reads and
deletes, the temporary folder where that one is full, and no file left behind."""

import errno
import os
import pickle

import numpy as np
import pytest

from serenity.kernels import tracer_process as tp
from serenity.scene import load


def test_scene_file_falls_back_to_the_temporary_folder_when_memory_is_full(tmp_path, monkeypatch):
    full = tmp_path / "shm"
    full.mkdir()
    monkeypatch.setattr(tp, "SCENE_DIR", str(full))
    monkeypatch.setattr(tp.tempfile, "tempdir", str(tmp_path))
    real = pickle.dump

    def dump(obj, f, protocol=None):
        if os.path.dirname(os.readlink(f"/proc/self/fd/{f.fileno()}")) == str(full):
            raise OSError(errno.ENOSPC, "No space left on device")
        real(obj, f, protocol=protocol)

    monkeypatch.setattr(tp.pickle, "dump", dump)
    scene = load("glass")
    path = tp._dump_scene(scene)
    try:
        assert os.path.dirname(path) == str(tmp_path) and not list(full.iterdir())  # the full one cleaned up
        back = tp._load_scene(path)
        assert not os.path.exists(path)  # the reader deletes it
        assert all(np.array_equal(a, b) for a, b in zip(back.merged(), scene.merged(), strict=True))
    finally:
        if os.path.exists(path):
            os.unlink(path)


@pytest.mark.skipif(not os.path.isdir("/proc/self/fd"), reason="Linux /proc")
def test_scene_file_gone_once_the_tracer_is_ready(tmp_path, monkeypatch):
    monkeypatch.setattr(tp, "SCENE_DIR", str(tmp_path))
    monkeypatch.setenv("SERENITY_CACHE", str(tmp_path / "cache"))
    proc = tp.TracerProcess(load("glass"))
    try:
        assert len(list(tmp_path.glob("serenity-scene-*.pickle"))) <= 1
        results, t0, t1 = proc.result(proc.submit([None]))
        assert results == [None] and proc.build_seconds > 0 and t1 >= t0
        assert not list(tmp_path.glob("serenity-scene-*.pickle"))
    finally:
        proc.close()
