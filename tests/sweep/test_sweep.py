"""``serenity sweep`` on a real Dask ``LocalCluster`` of 2 worker processes, at tiny sizes.

One cluster serves the module. The first sweep (built-in ``plane`` at 32×18, two times of day, our
frame + a 4-spp reference + the comparison, and a broken scene file) is shared by the tests that
check its files, its manifest and that a second run does nothing; the killed-worker test (slow) runs
its own. The cluster's start and the workers' first tasks (imports, Warp and Mitsuba start-up) are
most of the module's time.
"""

from __future__ import annotations

import csv
import json
import os
import signal
import threading
import time

import numpy as np
import pytest

pytest.importorskip("distributed")
pytest.importorskip("mitsuba")

from serenity.io.exr import read_exr  # noqa: E402
from serenity.sweep import ReferenceJob, load_spec, read_manifest, render_references, run_sweep  # noqa: E402

pytestmark = pytest.mark.gl

SPEC = """
[sweep]
name = "tiny"
scenes = ["plane", "broken.toml"]
sizes = ["32x18"]
produce = ["compare"]
quality = ["baseline"]   # no sky volume or LPV to set up: the sweep is under test here, not the GI
[time]
start = "2024-06-21 09:00 +01:00"
end = "2024-06-21 15:00 +01:00"
step_minutes = 360
[render]
frames = 1
[reference]
spp = 4
"""


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    import logging

    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, dashboard_address=":0",
                           silence_logs=logging.CRITICAL, env={"SERENITY_THREADS": "1"})
    c = Client(cluster)
    yield c
    c.close()
    cluster.close()


@pytest.fixture(scope="module")
def sweep(client, tmp_path_factory):
    d = tmp_path_factory.mktemp("sweep")
    (d / "broken.toml").write_text("this is not [a scene\n")
    (d / "tiny.toml").write_text(SPEC)
    spec = load_spec(str(d / "tiny.toml"))
    out, cache = str(d / "out"), str(d / "cache")
    result = run_sweep(spec, out, client=client, cache=cache, progress=False)
    return spec, out, cache, result


def test_small_sweep_completes_with_the_expected_files(sweep):
    spec, out, cache, result = sweep
    m = read_manifest(out)
    assert m["spec_hash"] == spec.hash
    plane = {k: r for k, r in m["tasks"].items() if r["inputs"]["scene"] == "plane"}
    assert sorted(r["kind"] for r in plane.values()) == ["compare"] * 2 + ["frame"] * 2 + ["reference"] * 2
    assert all(r["status"] == "done" for r in plane.values()), [r["error"] for r in plane.values()]
    for key, r in plane.items():
        assert key in result.ran
        for rel in r["outputs"].values():
            assert os.path.getsize(os.path.join(out, rel)) > 0
        assert r["worker"] and r["pid"] != os.getpid()  # ran on a worker process, not here
        assert r["worker_deaths"] == 0
    frames = [r for r in plane.values() if r["kind"] == "frame"]
    assert {r["inputs"]["time"] for r in frames} == {"2024-06-21 09:00 +01:00", "2024-06-21 15:00 +01:00"}
    assert frames[0]["sun_elevation_deg"] != frames[1]["sun_elevation_deg"]
    assert all(r["timings"]["frame_wall_ms"] > 0 and "g-buffer" in r["timings"]["stages_ms"] for r in frames)
    for r in frames:  # the EXR holds our linear HDR frame, lit
        hdr = read_exr(os.path.join(out, r["outputs"]["exr"]))["beauty"]
        assert hdr.shape == (18, 32, 3) and np.isfinite(hdr).all() and hdr.mean() > 1.0
    for r in plane.values():
        if r["kind"] == "compare":
            assert 0.0 < r["metrics"]["flip"] < 1.0 and r["metrics"]["rel_mse"] > 0.0
    # the reference cache the workers share got both references
    assert len([f for f in os.listdir(cache) if f.endswith(".npy")]) == 2

    with open(os.path.join(out, "metrics.csv")) as f:
        rows = list(csv.DictReader(f))
    assert [(r["scene"], r["status"]) for r in rows] == [("plane", "done")] * 2 + [("broken", "error")] * 2
    for r in rows[:2]:
        assert float(r["flip"]) > 0 and float(r["frame_wall_ms"]) > 0 and r["reference_spp"] == "4"
    points = json.load(open(os.path.join(out, "metrics.json")))["points"]
    assert [p["flip"] for p in points[:2]] == [pytest.approx(float(r["flip"])) for r in rows[:2]]

    from PIL import Image

    with Image.open(os.path.join(out, "contact_sheet.png")) as im:
        assert im.width > 2 * 200 and im.height > 4 * 18
    with Image.open(os.path.join(out, "time_of_day_plane_32x18_baseline.gif")) as gif:
        assert gif.n_frames == 2


def test_bad_scene_is_reported_in_the_manifest_while_the_rest_completes(sweep):
    spec, out, _, result = sweep
    m = read_manifest(out)
    broken = [r for r in m["tasks"].values() if r["inputs"]["scene"].endswith("broken.toml")]
    assert len(broken) == 6 and all(r["status"] == "error" for r in broken)
    for r in broken:
        assert "\n" not in r["error"]
        if r["kind"] != "compare":
            assert r["error"].startswith(os.path.join(os.path.dirname(spec.source), "broken.toml") + ": not valid TOML")
        else:
            assert r["error"].startswith("no frame to compare: ")
    assert sorted(result.failed) == sorted(k for k, r in m["tasks"].items() if r["status"] == "error")


def test_second_run_does_nothing(sweep, client):
    spec, out, cache, first = sweep
    before = {}
    for root, _, files in os.walk(out):
        for f in files:
            p = os.path.join(root, f)
            before[p] = os.stat(p).st_mtime_ns
    again = run_sweep(spec, out, client=client, cache=cache, progress=False)
    assert again.ran == [] and again.outputs == []
    assert sorted(again.skipped) == sorted(first.ran)
    after = {os.path.join(root, f): os.stat(os.path.join(root, f)).st_mtime_ns
             for root, _, files in os.walk(out) for f in files}
    assert after == before  # not a file written


def test_render_references_api_shares_the_cache_with_the_sweep(sweep, client, monkeypatch):
    spec, out, cache, _ = sweep
    m = read_manifest(out)
    refs = [r for r in m["tasks"].values() if r["kind"] == "reference" and r["status"] == "done"]
    jobs = [ReferenceJob(scene="plane", width=32, height=18, spp=4, time=r["inputs"]["time"]) for r in refs]
    # a Scene object travels to the worker too (and is the same scene, so the same cache entry)
    from serenity.scene import load

    as_object = ReferenceJob(scene=load("plane"), width=32, height=18, spp=4, time=jobs[0].time)
    images = render_references(jobs + jobs[:1] + [as_object], client=client, cache=cache, progress=False)
    assert len(images) == 4
    np.testing.assert_array_equal(images[2], images[0])
    np.testing.assert_array_equal(images[3], images[0])
    for r, img in zip(refs, images, strict=False):
        np.testing.assert_array_equal(img, read_exr(os.path.join(out, r["outputs"]["exr"]))["beauty"])
    assert len([f for f in os.listdir(cache) if f.endswith(".npy")]) == 2  # nothing new was rendered
    # a benchmark's own render_reference(...) with the same arguments now reads the cache
    from serenity.eval.reference import render_reference
    from serenity.sweep.tasks import load_scene_at

    monkeypatch.setenv("SERENITY_CACHE", cache)
    info: dict = {}
    scene = load_scene_at({"scene": "plane", "time": jobs[0].time})
    img = render_reference(scene, 32, 18, spp=4, progress=False, info=info)
    assert info["cached"] is True
    np.testing.assert_array_equal(img, images[0])


def _executing(dask_worker):
    return [str(ts.key) for ts in dask_worker.state.executing]


@pytest.mark.slow  # a 1024-spp reference to be sure to kill it mid-task, rendered twice, and a worker restart
def test_a_worker_killed_mid_task_has_its_task_retried_elsewhere(client, tmp_path):
    # one point; its reference (1024 spp: seconds, even on a warm worker) is the task to kill
    spec_text = (SPEC.replace('"plane", "broken.toml"', '"plane"').replace("spp = 4", "spp = 1024")
                 .replace('end = "2024-06-21 15:00 +01:00"', 'end = "2024-06-21 09:00 +01:00"'))
    (tmp_path / "kill.toml").write_text(spec_text)
    spec = load_spec(str(tmp_path / "kill.toml"))
    out = str(tmp_path / "out")
    pids = client.run(os.getpid)
    box = {}
    runner = threading.Thread(target=lambda: box.update(result=run_sweep(spec, out, client=client,
                                                                          cache=str(tmp_path / "cache"),
                                                                          progress=False)))
    runner.start()
    victim = None
    deadline = time.monotonic() + 120
    while victim is None and time.monotonic() < deadline and runner.is_alive():
        for addr, keys in client.run(_executing).items():
            mine = [k for k in keys if k.startswith("reference-plane")]
            if mine and addr in pids:
                victim = (addr, pids[addr], mine[0])
                os.kill(pids[addr], signal.SIGKILL)  # the worker process this test's cluster started
                break
        time.sleep(0.02)
    runner.join(timeout=300)
    assert victim is not None, "no reference task was seen executing"
    assert not runner.is_alive()
    result = box["result"]
    m = read_manifest(out)
    assert len(m["tasks"]) == 3 and all(r["status"] == "done" for r in m["tasks"].values()), \
        [r["error"] for r in m["tasks"].values()]
    assert result.failed == []
    rec = m["tasks"][victim[2]]
    assert rec["pid"] != victim[1]  # finished by another (or the restarted) worker process
    assert rec["worker_deaths"] == 1
    assert all(r["worker_deaths"] == 0 for k, r in m["tasks"].items() if k != victim[2])
    for r in m["tasks"].values():
        for rel in r["outputs"].values():
            assert os.path.exists(os.path.join(out, rel))


def test_cli_on_a_running_scheduler(client, tmp_path, capsys):
    from serenity.cli import main

    (tmp_path / "one.toml").write_text('[sweep]\nscenes = ["plane"]\nsizes = ["16x9"]\nquality = ["baseline"]\n'
                                       '[render]\nframes = 1\n')
    out = tmp_path / "out"
    address = client.scheduler.address
    assert main(["sweep", str(tmp_path / "one.toml"), "--scheduler", address, "--out", str(out), "-q"]) == 0
    (rec,) = read_manifest(str(out))["tasks"].values()
    assert rec["status"] == "done" and rec["worker"] in client.scheduler_info()["workers"]
    assert os.path.exists(out / rec["outputs"]["png"]) and os.path.exists(out / "contact_sheet.png")
    capsys.readouterr()
    # --workers sizes only the embedded cluster: one line, exit status 2
    assert main(["sweep", str(tmp_path / "one.toml"), "--scheduler", address, "--workers", "2",
                 "--out", str(tmp_path / "other")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("serenity: error: --workers sizes the embedded cluster") and err.count("\n") == 1
