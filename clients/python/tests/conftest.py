"""A real coordinator and worker on loopback for the client's tests, from the rayfarm binary
named by $RAYFARM_BINARY (ctest sets it) with the repository's scenes ($RAYFARM_SOURCE_DIR)."""

import os
import re
import shutil
import signal
import subprocess
import tempfile
import time

import pytest

BINARY = os.environ.get("RAYFARM_BINARY", "")
SOURCE = os.environ.get("RAYFARM_SOURCE_DIR",
                        os.path.abspath(os.path.join(os.path.dirname(__file__), "../../..")))
CORNELL = os.path.join(SOURCE, "scenes", "cornell-box", "scene.json")


def run(*args, **kwargs) -> subprocess.CompletedProcess:
    return subprocess.run([BINARY, *args], capture_output=True, text=True, check=False, **kwargs)


class Process:
    def __init__(self, args, log):
        self.log_path = log
        self._log = open(log, "w")
        self.proc = subprocess.Popen([BINARY, *args], stdout=self._log, stderr=subprocess.STDOUT)

    def log(self) -> str:
        with open(self.log_path) as f:
            return f.read()

    def stop(self, sig=signal.SIGTERM, wait=30):
        if self.proc.poll() is None:
            self.proc.send_signal(sig)
            try:
                self.proc.wait(wait)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log.close()


class LocalFarm:
    """A coordinator with a token file (tenants "a" and "b", a worker token), and workers."""

    def __init__(self, root, lease_seconds=10, monitor=False):
        self.root = root
        self.monitor = monitor
        self.monitor_port = 0
        self.tokens = {}
        lines = []
        for name, role, tenant in (("a", "client", "a"), ("b", "client", "b"),
                                   ("worker", "worker", "farm")):
            made = run("token", "new", "--role", role, "--tenant", tenant)
            assert made.returncode == 0, made.stderr
            token, line = made.stdout.splitlines()[:2]
            self.tokens[name] = token
            lines.append(line)
        self.token_file = os.path.join(root, "tokens")
        with open(self.token_file, "w") as f:
            f.write("\n".join(lines) + "\n")
        self.worker_token_file = os.path.join(root, "worker-token")
        with open(self.worker_token_file, "w") as f:
            f.write(self.tokens["worker"] + "\n")
        self.lease_seconds = lease_seconds
        self.workers = []
        self.coordinator = None
        self.port = 0
        self.start_coordinator()

    def start_coordinator(self):
        args = ["coordinator", "--listen", f"127.0.0.1:{self.port}", "--state-dir",
                os.path.join(self.root, "state"), "--token-file", self.token_file,
                "--lease-seconds", str(self.lease_seconds)]
        if self.monitor:
            args += ["--monitor-listen", f"127.0.0.1:{self.monitor_port}"]
        self.coordinator = Process(args, os.path.join(self.root,
                                                      f"coordinator-{time.monotonic_ns()}.log"))
        for _ in range(500):
            log = self.coordinator.log()
            m = re.search(r"\(port ([0-9]+)\)", log)
            w = re.search(r"\(monitor port ([0-9]+)\)", log)
            if m and (w or not self.monitor):
                self.port = int(m.group(1))
                self.monitor_port = int(w.group(1)) if w else 0
                return
            assert self.coordinator.proc.poll() is None, self.coordinator.log()
            time.sleep(0.02)
        raise AssertionError("the coordinator did not say its port:\n" + self.coordinator.log())

    @property
    def address(self) -> str:
        return f"127.0.0.1:{self.port}"

    def worker(self, *extra):
        w = Process(["worker", "--coordinator", self.address, "--token-file",
                     self.worker_token_file, "--cache-dir", os.path.join(self.root, "cache"),
                     *extra],
                    os.path.join(self.root, f"worker{len(self.workers)}.log"))
        self.workers.append(w)
        return w

    def client(self, tenant="a", **kwargs):
        import rayfarm
        kwargs.setdefault("timeout", 20)
        return rayfarm.Farm(self.address, token=self.tokens[tenant], tls=False, binary=BINARY,
                            **kwargs)

    def stop(self):
        for w in self.workers:
            w.stop()
        if self.coordinator:
            self.coordinator.stop()


def _skip_without_binary():
    if not BINARY or not os.access(BINARY, os.X_OK):
        pytest.skip("RAYFARM_BINARY is not set to the rayfarm binary")


@pytest.fixture(scope="module")
def farm():
    """One farm with one worker for a test module."""
    _skip_without_binary()
    root = tempfile.mkdtemp(prefix="rayfarm-py-")
    f = LocalFarm(root)
    f.worker()
    yield f
    f.stop()
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def bare_farm():
    """A farm of its own without workers, for a test that stops its coordinator."""
    _skip_without_binary()
    root = tempfile.mkdtemp(prefix="rayfarm-py-")
    f = LocalFarm(root)
    yield f
    f.stop()
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture
def tmp_out(tmp_path):
    return str(tmp_path)
