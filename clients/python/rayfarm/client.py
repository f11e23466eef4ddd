"""Farm and Job: the coordinator's JobService from Python.

Calls go over gRPC with the stubs generated from proto/rayfarm.proto. Two things are asked of the
rayfarm binary instead, so that Python never holds a second copy of C++ rules:
  - which files a scene references, and their digests (`rayfarm bundle --json`): the scene
    importers decide it, for the four scene formats;
  - the EXR and PNG files of a fetch (`rayfarm fetch --json`): the engine's image writer, so a
    frame fetched from Python is byte for byte the file the CLI writes.
"""

from __future__ import annotations

import dataclasses
import json
import os
import random
import re
import secrets
import shutil
import subprocess
import time
from typing import Any, Iterable, Iterator

import grpc

from . import errors
from ._proto import rayfarm_pb2 as pb
from ._proto import rayfarm_pb2_grpc as pb_grpc

CHUNK_BYTES = 1 << 20  # as farm/chunking.h: about 1 MiB a message, never a raised limit

_STATES = {pb.JOB_QUEUED: "queued", pb.JOB_RUNNING: "running", pb.JOB_COMPLETED: "completed",
           pb.JOB_FAILED: "failed", pb.JOB_CANCELLED: "cancelled"}
ENDED = ("completed", "failed", "cancelled")

# The settings a submit may override (RenderOverrides in proto/rayfarm.proto).
SETTINGS = ("spp", "passes", "integrator", "seed", "width", "height", "max_depth", "filter",
            "noise_target", "sampler", "aovs", "light_selection", "shutter")


# -------------------------------------------------------------------------------------------
# What the coordinator answers, as plain Python values


@dataclasses.dataclass(frozen=True)
class FrameStatus:
    frame: int
    passes_merged: int
    passes_total: int
    spp: float
    rel_mse: float | None  # None before two passes: the error cannot be estimated yet
    eta_seconds: float | None  # None when unknown, or when nothing renders the frame
    done: bool
    stopped_on_target: bool
    scene_version: int
    run: int

    @staticmethod
    def from_proto(f) -> "FrameStatus":
        return FrameStatus(f.frame, f.passes_merged, f.passes_total, f.spp,
                           f.rel_mse if f.passes_merged >= 2 else None,
                           f.eta_seconds if f.eta_seconds >= 0 else None, f.done,
                           f.stopped_on_target, f.scene_version, f.run)


@dataclasses.dataclass(frozen=True)
class JobStatus:
    job_id: str
    name: str
    state: str  # queued, running, completed, failed, cancelled
    frames: tuple[FrameStatus, ...]
    error: str
    core_seconds: float
    submitted_unix: int
    ended_unix: int | None
    tenant: str
    paused: bool
    priority: int
    held_frames: str
    build_id: str
    cpu_kind: str
    waiting_for: str
    settings: dict[str, Any]  # as submitted: only the settings given over the scene file's
    scene_path: str
    tile_size: int
    required_tags: tuple[str, ...]

    @property
    def ended(self) -> bool:
        return self.state in ENDED

    @property
    def progress(self) -> float:
        """Merged passes over all passes, in [0, 1] (a frame stopped on its noise target counts
        as whole)."""
        total = sum(f.passes_total for f in self.frames)
        merged = sum(f.passes_total if f.done else f.passes_merged for f in self.frames)
        return merged / total if total else 0.0

    @property
    def eta_seconds(self) -> float | None:
        """Seconds to the end: the sum over unfinished frames; None when one is unknown."""
        if self.state == "completed":
            return 0.0
        if self.ended or self.paused:
            return None
        left = [f.eta_seconds for f in self.frames if not f.done]
        return None if any(e is None for e in left) else sum(left)

    @staticmethod
    def from_proto(j) -> "JobStatus":
        settings = {name: getattr(j.settings, name) for name in SETTINGS
                    if j.settings.HasField(name)}
        return JobStatus(j.job_id, j.name, _STATES.get(j.state, "unknown"),
                         tuple(FrameStatus.from_proto(f) for f in j.frames), j.error,
                         j.core_seconds, j.submitted_unix, j.ended_unix or None, j.tenant,
                         j.paused, j.priority, j.held_frames, j.build_id, j.cpu_kind,
                         j.waiting_for, settings, j.scene_path, j.tile_size,
                         tuple(j.required_tags))


@dataclasses.dataclass(frozen=True)
class WorkerStatus:
    worker_id: str
    hostname: str
    cores: int
    build_id: str
    isa: str
    tasks: tuple[str, ...]
    failures: int
    seconds_since_contact: float | None
    refused: str
    principal: str
    tags: tuple[str, ...]

    @staticmethod
    def from_proto(w) -> "WorkerStatus":
        return WorkerStatus(w.worker_id, w.hostname, w.cores, w.build_id, w.isa, tuple(w.tasks),
                            w.failures,
                            w.seconds_since_contact if w.seconds_since_contact >= 0 else None,
                            w.refused, w.principal, tuple(w.tags))


@dataclasses.dataclass(frozen=True)
class TaskAttempt:
    task_id: str
    worker_id: str
    lease_id: str
    started_unix: float
    ended_unix: float | None
    outcome: str
    message: str
    log: tuple[str, ...]

    @staticmethod
    def from_proto(a) -> "TaskAttempt":
        return TaskAttempt(a.task_id, a.worker_id, a.lease_id, a.started_unix,
                           a.ended_unix or None, a.outcome, a.message, tuple(a.log))


@dataclasses.dataclass
class Frame:
    """A fetched frame: its files, as the CLI writes them, and its figures."""

    job_id: str
    frame: int
    exr: str
    png: str | None
    passes: int
    spp: float
    rel_mse: float | None
    done: bool
    _image: Any = dataclasses.field(default=None, repr=False)

    @property
    def image(self):
        """The EXR's channels as numpy arrays (rayfarm.images.Image); needs numpy and
        OpenImageIO's Python module (Debian: python3-numpy, python3-openimageio)."""
        if self._image is None:
            from .images import read_exr
            self._image = read_exr(self.exr)
        return self._image


@dataclasses.dataclass(frozen=True)
class TLS:
    """TLS to the coordinator: the CA that signed its certificate (PEM file), and for mutual TLS
    this client's certificate and key. ca=None: the system's roots."""

    ca: str | None = None
    cert: str | None = None
    key: str | None = None


def frame_range(frames) -> str:
    """Open Job Description range text from an int, a str (passed as is), a range or an iterable
    of ints: 7 -> "7", range(1, 25, 2) -> "1-23:2", [1, 5, 9] -> "1,5,9"."""
    if frames is None:
        return ""
    if isinstance(frames, str):
        return frames
    if isinstance(frames, int):
        return str(frames)
    if isinstance(frames, range):
        if len(frames) == 0:
            raise ValueError("frames: empty range")
        if frames.step == 1:
            return f"{frames.start}-{frames[-1]}"
        if frames.step > 0:
            return f"{frames.start}-{frames[-1]}:{frames.step}"
    items = [int(f) for f in frames]
    if not items:
        raise ValueError("frames: no frame given")
    return ",".join(str(f) for f in items)


# -------------------------------------------------------------------------------------------
# The farm


class Farm:
    """A connection to a coordinator.

    address: host:port (default $RAYFARM_COORDINATOR, else 127.0.0.1:7070).
    token / token_file: the client token (default: the file $RAYFARM_TOKEN_FILE, else
        $RAYFARM_TOKEN, else none), as the CLI takes it.
    tls: None ($RAYFARM_TLS_CA, _CERT, _KEY when set, else plaintext), False (plaintext), True
        (the system's roots), a CA file's path, or a TLS(ca, cert, key).
    timeout: seconds a call keeps retrying while the coordinator is unavailable (the CLI's
        --timeout), and the longest a watch waits for a lost coordinator to come back.
    binary: the rayfarm executable, for bundles and fetches (default $RAYFARM_BINARY, else
        `rayfarm` on PATH).
    """

    def __init__(self, address: str | None = None, *, token: str | None = None,
                 token_file: str | None = None, tls=None, timeout: float = 300.0,
                 binary: str | None = None):
        self.address = address or os.environ.get("RAYFARM_COORDINATOR") or "127.0.0.1:7070"
        self.timeout = float(timeout)
        self._token = _client_token(token, token_file)
        self._tls = _tls_config(tls)
        self._binary = binary or os.environ.get("RAYFARM_BINARY") or shutil.which("rayfarm")
        options = [("grpc.keepalive_time_ms", 30000), ("grpc.keepalive_timeout_ms", 10000),
                   ("grpc.keepalive_permit_without_calls", 1),
                   ("grpc.http2.max_pings_without_data", 0)]
        if self._tls is None:
            self._channel = grpc.insecure_channel(self.address, options=options)
        else:
            def read(path):
                if path is None:
                    return None
                with open(path, "rb") as f:
                    return f.read()
            creds = grpc.ssl_channel_credentials(read(self._tls.ca), read(self._tls.key),
                                                 read(self._tls.cert))
            self._channel = grpc.secure_channel(self.address, creds, options=options)
        self._stub = pb_grpc.JobServiceStub(self._channel)
        self._metadata = (("authorization", "Bearer " + self._token),) if self._token else ()

    def close(self) -> None:
        self._channel.close()

    def __enter__(self) -> "Farm":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def __repr__(self) -> str:
        return f"Farm({self.address!r}, tls={self._tls is not None})"

    # --- jobs ----------------------------------------------------------------------------

    def submit(self, scene: str, frames=None, *, name: str | None = None, priority: int = 0,
               tile_size: int = 0, tags: Iterable[str] = (), build_id: str = "",
               resolution: tuple[int, int] | None = None, **settings) -> "Job":
        """Submits a scene file (with the files it references) over a frame range.

        frames: None (the scene's one frame), an int, range text ("1-24:2"), a range or a list.
        settings: any of SETTINGS (spp=256, integrator="path", aovs=["albedo", "normal"],
        noise_target=0.01, shutter=(0, 0.5), ...); resolution=(w, h) sets width and height.
        Only the scene's files the coordinator lacks are uploaded, by content digest.
        """
        unknown = sorted(set(settings) - set(SETTINGS))
        if unknown:
            raise TypeError(f"submit: unknown setting {', '.join(unknown)} "
                            f"(settings: {', '.join(SETTINGS)})")
        if resolution is not None:
            settings["width"], settings["height"] = resolution
        range_text = frame_range(frames)
        bundle = self.bundle(scene, range_text)
        spec = pb.JobSpec(name=name or _default_name(scene), scene_path=bundle["scene"],
                          frames=range_text, priority=int(priority), tile_size=int(tile_size),
                          build_id=build_id, request_id=secrets.token_hex(16),
                          required_tags=list(tags))
        for f in bundle["files"]:
            spec.files.add(path=f["path"], sha256=f["sha256"])
        _set_overrides(spec.overrides, settings)
        answer = self._upload("submit", self._stub.Submit, pb.SubmitRequest(spec=spec),
                              bundle, lambda chunk: pb.SubmitRequest(blob_chunk=chunk))
        return Job(self, answer.job_id)

    def bundle(self, scene: str, frames: str = "") -> dict:
        """The files a submit of `scene` uploads, from the binary's scene importers:
        {"scene": path in the bundle, "dir": directory, "files": [{path, sha256, bytes}]}."""
        if not os.path.exists(scene) and "#" not in os.path.basename(scene):
            raise errors.SceneError(f"{scene}: no such scene file")
        args = ["bundle", os.path.abspath(scene), "--json"]
        if frames:
            args += ["--frames", frames]
        result = self._run(args)
        if result.returncode != 0:
            message = _message(result.stderr) or f"bundle {scene}: exit {result.returncode}"
            if message.startswith("--frames"):
                raise errors.InvalidArgument(f"frames {frames!r}: {message}")
            raise errors.SceneError(message)
        return json.loads(result.stdout)

    def job(self, job_id: str) -> "Job":
        return Job(self, job_id)

    def jobs(self) -> list[JobStatus]:
        """Every job this token may see, in submission order."""
        out, after = [], ""
        while True:
            page = self._call("jobs", self._stub.ListJobs,
                              pb.ListJobsRequest(limit=1000, after=after))
            out += [JobStatus.from_proto(j) for j in page.jobs]
            if not page.next_after:
                return out
            after = page.next_after

    def workers(self) -> list[WorkerStatus]:
        answer = self._call("workers", self._stub.ListWorkers, pb.ListWorkersRequest())
        return [WorkerStatus.from_proto(w) for w in answer.workers]

    # --- plumbing ------------------------------------------------------------------------

    def _call(self, what: str, method, request, per_call: float = 30.0):
        """One unary call, made again while the coordinator is unavailable, for up to
        self.timeout seconds in all (with backoff, as the CLI)."""
        end = time.monotonic() + self.timeout
        for attempt in range(1 << 30):
            left = end - time.monotonic()
            try:
                return method(request, metadata=self._metadata,
                              timeout=max(0.001, min(per_call, left)))
            except grpc.RpcError as e:
                if not self._retry_after(e, attempt, end):
                    raise self._error(e, what) from None

    def _upload(self, what: str, method, first, bundle: dict, wrap):
        """A client stream (Submit, RequeueJob): `first`, then the bundle's files the
        coordinator lacks, each as chunks. Retried whole while unavailable; the request id in
        `first` makes a retry of an attempt that did arrive get that attempt's job."""
        digests = [f["sha256"] for f in bundle["files"]]
        end = time.monotonic() + self.timeout
        for attempt in range(1 << 30):
            try:
                missing = set(self._call(what, self._stub.MissingBlobs,
                                         pb.MissingBlobsRequest(sha256=digests)).sha256)
                stream = _bundle_stream(first, bundle, missing, wrap)
                return method(stream, metadata=self._metadata,
                              timeout=max(0.001, min(3600.0, end - time.monotonic())))
            except grpc.RpcError as e:
                if not self._retry_after(e, attempt, end):
                    raise self._error(e, what) from None

    def _retry_after(self, e: grpc.RpcError, attempt: int, end: float) -> bool:
        if e.code() != grpc.StatusCode.UNAVAILABLE:
            return False
        wait = _backoff(attempt, 0.1, 5.0)
        if end - time.monotonic() <= wait:
            return False
        time.sleep(wait)
        return True

    def _error(self, e: grpc.RpcError, what: str) -> errors.RayfarmError:
        err = errors.from_rpc_error(e, what)
        if isinstance(err, errors.Unavailable):
            err.args = (f"{err.args[0]} (coordinator {self.address}, gave up after "
                        f"{self.timeout:g} s)",)
        return err

    def _run(self, args: list[str]) -> subprocess.CompletedProcess:
        """Runs the rayfarm binary with this farm's address, token and TLS (the token in its
        environment, never on its command line)."""
        if not self._binary:
            raise errors.CommandError("the rayfarm binary was not found: pass Farm(binary=...) "
                                      "or set RAYFARM_BINARY")
        env = dict(os.environ)
        for name in ("RAYFARM_TOKEN", "RAYFARM_TOKEN_FILE", "RAYFARM_TLS_CA", "RAYFARM_TLS_CERT",
                     "RAYFARM_TLS_KEY"):
            env.pop(name, None)
        if self._token:
            env["RAYFARM_TOKEN"] = self._token
        if self._tls is not None:
            for name, value in (("CA", self._tls.ca), ("CERT", self._tls.cert),
                                ("KEY", self._tls.key)):
                if value:
                    env["RAYFARM_TLS_" + name] = value
        return subprocess.run([self._binary] + args, env=env, capture_output=True, text=True)


class Job:
    """A job on a farm, by id. Every method asks the coordinator afresh."""

    def __init__(self, farm: Farm, job_id: str):
        self.farm = farm
        self.id = job_id

    def __repr__(self) -> str:
        return f"Job({self.id!r})"

    def _ref(self):
        return pb.JobRef(job_id=self.id)

    def status(self) -> JobStatus:
        f = self.farm
        return JobStatus.from_proto(f._call(f"status {self.id}", f._stub.GetJob, self._ref()))

    def watch(self) -> Iterator[JobStatus]:
        """The job's status at every merge, until it ends (the last one is its final status).
        A lost connection is resumed for up to the farm's timeout, then Unavailable is raised."""
        f = self.farm
        lost_since = None
        attempt = 0
        while True:
            try:
                for message in f._stub.WatchJob(self._ref(), metadata=f._metadata):
                    lost_since, attempt = None, 0
                    status = JobStatus.from_proto(message)
                    yield status
                    if status.ended:
                        return
                return  # the coordinator ended the stream: the job ended
            except grpc.RpcError as e:
                if e.code() != grpc.StatusCode.UNAVAILABLE:
                    raise f._error(e, f"watch {self.id}") from None
                if lost_since is None:
                    lost_since = time.monotonic()
                if not f._retry_after(e, attempt, lost_since + f.timeout):
                    raise f._error(e, f"watch {self.id}") from None
                attempt += 1

    def wait(self, raise_on_failure: bool = True) -> JobStatus:
        """Waits for the job to end and returns its final status; JobFailed when it failed or
        was cancelled (unless raise_on_failure is False)."""
        last = None
        for last in self.watch():
            pass
        if last is None or not last.ended:
            last = self.status()
        if raise_on_failure and last.state != "completed":
            raise errors.JobFailed(f"job {self.id} {last.state}"
                                   + (f": {last.error}" if last.error else ""), last)
        return last

    def fetch(self, output: str, frames=None, *, png: bool = True, half: bool = False,
              exposure: float | None = None, arrays: bool = False) -> list[Frame]:
        """Writes the job's frames (those with a complete pass) as EXR and PNG, by the same code
        as `rayfarm fetch`: output is a directory (JOB.####.exr in it) or a frame template
        (shot.####.exr). arrays=True also reads each EXR into numpy arrays (Frame.image)."""
        args = ["fetch", self.id, "-o", output, "--json", "--coordinator", self.farm.address,
                "--timeout", f"{self.farm.timeout:g}"]
        if frames is not None:
            args += ["--frames", frame_range(frames)]
        if not png:
            args.append("--no-png")
        if half:
            args.append("--half")
        if exposure is not None:
            args += ["--exposure", f"{exposure:g}"]
        result = self.farm._run(args)
        if result.returncode != 0:
            raise _command_error(result.stderr, f"fetch {self.id}")
        out = []
        for line in result.stdout.splitlines():
            d = json.loads(line)
            out.append(Frame(d["job_id"], d["frame"], d["exr"], d["png"], d["passes"], d["spp"],
                             d["rel_mse"], d["done"]))
        if arrays:
            for frame in out:
                frame.image  # noqa: B018 (loads it)
        return out

    def cancel(self) -> None:
        f = self.farm
        f._call(f"cancel {self.id}", f._stub.CancelJob, self._ref())

    def pause(self) -> JobStatus:
        f = self.farm
        return JobStatus.from_proto(f._call(f"pause {self.id}", f._stub.PauseJob, self._ref()))

    def resume(self) -> JobStatus:
        f = self.farm
        return JobStatus.from_proto(f._call(f"resume {self.id}", f._stub.ResumeJob, self._ref()))

    def set_priority(self, priority: int) -> JobStatus:
        f = self.farm
        req = pb.SetPriorityRequest(job_id=self.id, priority=int(priority))
        return JobStatus.from_proto(f._call(f"priority {self.id}", f._stub.SetJobPriority, req))

    def retry(self, frames=None) -> JobStatus:
        """Runs the failed or cancelled job's unfinished frames again (those in `frames`; the
        others are held until a later retry names them)."""
        f = self.farm
        req = pb.RetryRequest(job_id=self.id, frames=frame_range(frames))
        return JobStatus.from_proto(f._call(f"retry {self.id}", f._stub.RetryJob, req))

    def requeue(self, frames, scene: str | None = None) -> JobStatus:
        """Renders `frames` again from scratch, with a new version of the scene when given."""
        f = self.farm
        range_text = frame_range(frames)
        req = pb.RequeueRequest(job_id=self.id, frames=range_text,
                                request_id=secrets.token_hex(16))
        bundle = {"dir": "", "files": []}
        if scene is not None:
            bundle = f.bundle(scene, range_text)
            req.scene_path = bundle["scene"]
            for file in bundle["files"]:
                req.files.add(path=file["path"], sha256=file["sha256"])
        answer = f._upload(f"requeue {self.id}", f._stub.RequeueJob,
                           pb.RequeueMessage(request=req), bundle,
                           lambda chunk: pb.RequeueMessage(blob_chunk=chunk))
        return JobStatus.from_proto(answer)

    def delete(self, force: bool = False) -> None:
        f = self.farm
        f._call(f"delete {self.id}", f._stub.DeleteJob, pb.DeleteRequest(job_id=self.id,
                                                                         force=force))

    def logs(self, frame: int | None = None, task: str = "", limit: int = 100) -> list[TaskAttempt]:
        f = self.farm
        req = pb.TaskLogRequest(job_id=self.id, task_id=task, limit=limit)
        if frame is not None:
            req.frame = frame
        answer = f._call(f"logs {self.id}", f._stub.GetTaskLog, req)
        return [TaskAttempt.from_proto(a) for a in answer.attempts]


# -------------------------------------------------------------------------------------------
# Helpers


def _bundle_stream(first, bundle: dict, missing: set, wrap):
    """The messages of an upload: `first`, then each missing file once, read 1 MiB at a time
    (never whole in memory), the first chunk with the file's size and SHA-256."""
    yield first
    sent = set()
    for f in bundle["files"]:
        digest = f["sha256"]
        if digest not in missing or digest in sent:
            continue
        sent.add(digest)
        path = os.path.join(bundle["dir"], f["path"])
        size = os.path.getsize(path)
        with open(path, "rb") as data:
            offset = 0
            while True:
                piece = data.read(CHUNK_BYTES)
                chunk = pb.Chunk(offset=offset, data=piece)
                if offset == 0:
                    chunk.total_size, chunk.sha256 = size, digest
                yield wrap(chunk)
                offset += len(piece)
                if offset >= size:
                    break


def _set_overrides(o, settings: dict) -> None:
    for key, value in settings.items():
        if value is None:
            continue
        if key == "aovs" and not isinstance(value, str):
            value = ",".join(value)
        if key == "shutter" and not isinstance(value, str):
            value = ",".join(f"{float(v):g}" for v in (value if isinstance(value, (list, tuple))
                                                      else [value]))
        if key in ("spp", "passes", "seed", "width", "height", "max_depth"):
            if isinstance(value, bool) or int(value) != value:
                raise TypeError(f"submit: {key} must be an integer, not {value!r}")
            value = int(value)
        try:
            setattr(o, key, value)
        except (TypeError, ValueError) as e:
            raise TypeError(f"submit: {key}={value!r}: {e}") from None


def _default_name(scene: str) -> str:
    # As the CLI: the scene's stem, or its directory's name for the usual "scene.json".
    stem = os.path.splitext(os.path.basename(scene))[0]
    parent = os.path.basename(os.path.dirname(os.path.abspath(scene)))
    return parent if stem == "scene" and parent else stem


def _client_token(token: str | None, token_file: str | None) -> str:
    if token is not None:
        return token.strip()
    path = token_file or os.environ.get("RAYFARM_TOKEN_FILE")
    if path:
        try:
            with open(path) as f:
                return f.read().strip()
        except OSError as e:
            raise errors.RayfarmError(f"token file {path}: {e.strerror}") from None
    return os.environ.get("RAYFARM_TOKEN", "").strip()


def _tls_config(tls) -> TLS | None:
    if tls is None:
        ca = os.environ.get("RAYFARM_TLS_CA")
        if not ca:
            return None
        return TLS(ca, os.environ.get("RAYFARM_TLS_CERT"), os.environ.get("RAYFARM_TLS_KEY"))
    if tls is False:
        return None
    if tls is True:
        return TLS()
    if isinstance(tls, str):
        return TLS(tls)
    if isinstance(tls, TLS):
        return tls
    raise TypeError(f"tls: expected None, a bool, a CA file's path or a TLS, not {tls!r}")


def _backoff(attempt: int, first: float, cap: float) -> float:
    # Full jitter, as the CLI's: a random wait up to an exponentially growing bound.
    return random.uniform(0, min(cap, first * (2 ** min(attempt, 30))))


def _message(stderr: str) -> str:
    """The binary's error: its last non-empty line, without the "rayfarm: " prefix."""
    lines = [line for line in stderr.splitlines() if line.strip()]
    return re.sub(r"^(rayfarm: )?(error: )?", "", lines[-1]) if lines else ""


_CODES = {c.name: c for c in grpc.StatusCode}


def _command_error(stderr: str, what: str) -> errors.RayfarmError:
    """An exception for a failed binary: of the class of the gRPC code its message names."""
    message = _message(stderr) or what + ": failed"
    for name in re.findall(r"\b([A-Z_]{6,})\b", message):
        if name in _CODES:
            cls = errors._BY_CODE.get(_CODES[name], errors.CommandError)
            return cls(message, _CODES[name])
    return errors.CommandError(message)
