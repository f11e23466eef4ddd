"""The Python client against a real coordinator and worker on loopback (conftest.py)."""

import os
import signal
import threading
import time

import numpy as np
import pytest

import rayfarm
import rayfarm.client
from conftest import BINARY, CORNELL, run

SMALL = dict(spp=8, passes=4, resolution=(24, 24))


def local_render(tmp, frame, aovs="", **settings):
    """The CLI's local render of the Cornell box with the same settings: what the farm's image
    must equal exactly (the farm promise)."""
    out = os.path.join(tmp, f"local-{frame}.exr")
    w, h = settings["resolution"]
    args = ["render", CORNELL, "--spp", str(settings["spp"]), "--passes", str(settings["passes"]),
            "--res", f"{w}x{h}", "--frame", str(frame), "-q", "-o", out]
    if aovs:
        args += ["--aov", aovs]
    r = run(*args)
    assert r.returncode == 0, r.stderr
    return rayfarm.read_exr(out)


def test_submit_watch_fetch_a_frame_range(farm, tmp_out):
    client = farm.client()
    job = client.submit(CORNELL, frames=range(1, 3), name="py-range", **SMALL)
    assert job.id
    events = list(job.watch())
    assert events, "watch yields the status at every merge"
    assert events[-1].state == "completed" and events[-1].ended
    progress = [e.progress for e in events]
    assert progress == sorted(progress) and progress[-1] == 1.0
    status = job.status()
    assert [f.frame for f in status.frames] == [1, 2]
    assert all(f.done and f.passes_merged == 4 and f.rel_mse is not None for f in status.frames)
    assert status.settings == {"spp": 8, "passes": 4, "width": 24, "height": 24}
    assert status.tenant == "a" and status.name == "py-range" and status.ended_unix

    frames = job.fetch(os.path.join(tmp_out, "shot.####.exr"), arrays=True)
    assert [f.frame for f in frames] == [1, 2]
    assert frames[0].exr == os.path.join(tmp_out, "shot.0001.exr")
    assert os.path.exists(frames[0].exr) and os.path.exists(frames[0].png)
    image = frames[0].image
    assert image.rgb.shape == (24, 24, 3) and image.rgb.dtype == np.float32
    assert image.attributes["rayfarm:frame"] in (1, "1")
    # The farm's frame is the local render's, pixel for pixel.
    for f in frames:
        local = local_render(tmp_out, f.frame, **SMALL)
        np.testing.assert_array_equal(f.image.rgb, local.rgb)

    # The same files as the CLI's fetch: one writer.
    cli_dir = os.path.join(tmp_out, "cli")
    r = run("fetch", job.id, "-o", cli_dir, "--coordinator", farm.address,
            env={**os.environ, "RAYFARM_TOKEN": farm.tokens["a"]})
    assert r.returncode == 0, r.stderr
    cli = rayfarm.read_exr(os.path.join(cli_dir, f"{job.id}.0001.exr"))
    np.testing.assert_array_equal(cli.pixels, frames[0].image.pixels)
    assert cli.channels == frames[0].image.channels

    # Only the frames asked for, without PNG, half float.
    only = job.fetch(os.path.join(tmp_out, "half"), frames=2, png=False, half=True)
    assert [f.frame for f in only] == [2] and only[0].png is None
    assert not os.path.exists(only[0].exr.replace(".exr", ".png"))


def test_a_resubmission_uploads_nothing_twice(farm, monkeypatch):
    client = farm.client()
    sent = []
    real = rayfarm.client._bundle_stream

    def counting(first, bundle, missing, wrap):
        for message in real(first, bundle, missing, wrap):
            sent.append(message)
            yield message

    monkeypatch.setattr(rayfarm.client, "_bundle_stream", counting)
    bundle = client.bundle(CORNELL)
    assert bundle["scene"] == "scene.json"
    assert all(len(f["sha256"]) == 64 for f in bundle["files"])
    first = client.submit(CORNELL, spp=4, passes=1, resolution=(8, 8))
    first_messages = len(sent)
    assert first_messages >= 1
    sent.clear()
    second = client.submit(CORNELL, spp=4, passes=1, resolution=(8, 8))
    assert second.id != first.id
    assert len(sent) == 1, "only the spec: every blob is on the coordinator already"
    second.wait()


def test_job_operations(farm):
    client = farm.client()
    # A job no worker may take (a tag none has) stays queued while we operate on it.
    job = client.submit(CORNELL, tags=["gpu"], priority=3, **SMALL)
    st = job.status()
    assert st.state == "queued" and st.priority == 3 and st.required_tags == ("gpu",)
    assert "gpu" in st.waiting_for
    assert job.pause().paused and job.status().eta_seconds is None
    assert not job.resume().paused
    assert job.set_priority(9).priority == 9
    job.cancel()
    with pytest.raises(rayfarm.JobFailed) as failed:
        job.wait()
    assert failed.value.status.state == "cancelled"
    assert job.wait(raise_on_failure=False).state == "cancelled"
    assert job.id in [j.job_id for j in client.jobs()]
    assert job.retry().state in ("queued", "running")
    job.delete(force=True)
    with pytest.raises(rayfarm.NotFound):
        job.status()

    done = client.submit(CORNELL, spp=4, passes=2, resolution=(8, 8))
    done.wait()
    attempts = done.logs()
    assert attempts and all(a.outcome == "done" for a in attempts)
    assert done.requeue(done.status().frames[0].frame).state in ("queued", "running")
    assert done.wait().frames[0].run == 1
    workers = client.workers()
    assert len(workers) == 1 and workers[0].cores >= 1


def test_bad_input_is_a_clear_exception(farm, tmp_path):
    client = farm.client()
    missing = str(tmp_path / "nowhere.json")
    with pytest.raises(rayfarm.SceneError, match="nowhere.json"):
        client.submit(missing)
    broken = tmp_path / "broken.json"
    broken.write_text('{"camera": {"fov": 40,\n  "oops"}\n')
    with pytest.raises(rayfarm.SceneError, match="broken.json"):
        client.submit(str(broken))
    with pytest.raises(TypeError, match="sppp"):
        client.submit(CORNELL, sppp=4)
    with pytest.raises(rayfarm.InvalidArgument, match="frame"):
        client.submit(CORNELL, frames="1-x")
    with pytest.raises(rayfarm.NotFound):
        client.job("j999999").status()


def test_tokens_and_tenants(farm):
    job = farm.client("a").submit(CORNELL, spp=4, passes=1, resolution=(8, 8))
    wrong = rayfarm.Farm(farm.address, token="not-a-token", tls=False, binary=BINARY, timeout=5)
    with pytest.raises(rayfarm.Unauthenticated):
        wrong.job(job.id).status()
    with pytest.raises(rayfarm.Unauthenticated):
        wrong.submit(CORNELL, spp=1)
    nobody = rayfarm.Farm(farm.address, token="", tls=False, binary=BINARY, timeout=5)
    with pytest.raises(rayfarm.Unauthenticated):
        nobody.jobs()
    as_worker = farm.client("worker")
    with pytest.raises(rayfarm.PermissionDenied):
        as_worker.jobs()
    other = farm.client("b")
    assert job.id not in [j.job_id for j in other.jobs()]
    with pytest.raises((rayfarm.PermissionDenied, rayfarm.NotFound)):
        other.job(job.id).status()
    with pytest.raises((rayfarm.PermissionDenied, rayfarm.NotFound)):
        other.job(job.id).cancel()
    with pytest.raises((rayfarm.PermissionDenied, rayfarm.NotFound)):
        other.job(job.id).fetch("/tmp/never-written")
    job.wait()


def test_a_coordinator_gone_mid_watch_raises_unavailable_without_hanging(bare_farm):
    client = bare_farm.client(timeout=3)
    job = client.submit(CORNELL, spp=4, passes=2, resolution=(8, 8))  # no worker: it waits
    seen, raised = [], []

    def watch():
        try:
            for status in job.watch():
                seen.append(status)
        except rayfarm.RayfarmError as e:
            raised.append(e)

    t = threading.Thread(target=watch, daemon=True)
    t.start()
    for _ in range(100):
        if seen:
            break
        time.sleep(0.05)
    assert seen and seen[0].state == "queued"
    start = time.monotonic()
    bare_farm.coordinator.stop(signal.SIGKILL)
    t.join(30)
    assert not t.is_alive(), "watch hung after the coordinator went away"
    assert len(raised) == 1 and isinstance(raised[0], rayfarm.Unavailable), raised
    assert bare_farm.address in str(raised[0])
    assert time.monotonic() - start < 15, "gives up after about the farm's timeout (3 s)"
    with pytest.raises(rayfarm.Unavailable):
        job.status()

    # A coordinator back within the timeout: the watch resumes and sees the job to its end.
    bare_farm.start_coordinator()
    client = bare_farm.client(timeout=20)
    job = client.job(job.id)
    bare_farm.worker("--exit-when-idle")
    watching = job.watch()
    first = next(watching)
    bare_farm.coordinator.stop(signal.SIGKILL)
    restart = threading.Timer(1.0, bare_farm.start_coordinator)
    restart.start()
    last = first
    for last in watching:
        pass
    restart.join()
    assert last.state == "completed"


def test_denoise_with_albedo_and_normal(farm, tmp_out):
    pyoidn = pytest.importorskip("pyoidn", reason="pyoidn is not installed (tools/python-venv.sh)")
    assert pyoidn
    noisy = dict(spp=4, passes=2, resolution=(48, 48))
    job = farm.client().submit(CORNELL, aovs=["albedo", "normal"], **noisy)
    job.wait()
    frame = job.fetch(tmp_out, arrays=True)[0]
    assert set(frame.image.layers) >= {"rgb", "variance", "albedo", "normal"}
    out = os.path.join(tmp_out, "denoised.exr")
    result = rayfarm.denoise(frame, out)
    assert result.shape == (48, 48, 3) and np.isfinite(result).all()
    written = rayfarm.read_exr(out)
    np.testing.assert_allclose(written.rgb, result)
    assert written.attributes["rayfarm:denoised"] == "oidn rgb+albedo+normal"
    # Closer to a converged render than the noisy frame, by relative MSE (the error relative to
    # the pixel's value, as rayfarm's relMSE: plain MSE is dominated by the light's edge, which
    # any filter blurs). Measured on the Cornell box at 4 spp, 48x48: 0.059 noisy, 0.0096
    # denoised (6x); 2x leaves room for one frame's randomness, and a denoiser that did nothing
    # (1x) fails.
    reference = local_render(tmp_out, 1, spp=1024, passes=1, resolution=(48, 48)).rgb

    def rel_mse(x):
        return float(np.mean((x - reference) ** 2 / (reference ** 2 + 0.01)))

    assert rel_mse(result) < rel_mse(frame.image.rgb) / 2, (rel_mse(frame.image.rgb),
                                                            rel_mse(result))


def test_the_documented_example_runs(farm, tmp_out):
    pytest.importorskip("pyoidn", reason="pyoidn is not installed (tools/python-venv.sh)")
    import subprocess
    import sys
    example = os.path.join(os.path.dirname(__file__), "..", "examples", "submit_and_denoise.py")
    env = {**os.environ, "RAYFARM_TOKEN": farm.tokens["a"]}
    env.pop("RAYFARM_TOKEN_FILE", None)
    r = subprocess.run([sys.executable, example, CORNELL, "--frames", "1-2", "--spp", "8",
                        "--res", "24x24", "--coordinator", farm.address, "-o", tmp_out],
                       capture_output=True, text=True, env=env, timeout=300)
    assert r.returncode == 0, r.stdout + r.stderr
    for f in (1, 2):
        assert os.path.exists(os.path.join(tmp_out, f"frame.{f:04d}.denoised.exr")), r.stdout
    missing = subprocess.run([sys.executable, example, "/nonexistent/scene.json",
                              "--coordinator", farm.address], capture_output=True, text=True,
                             env=env, timeout=60)
    assert missing.returncode == 2 and "no such scene file" in missing.stderr
