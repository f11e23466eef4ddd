#!/usr/bin/env python3
"""The web monitor's costs (docs/performance.md "Web monitor"), two benchmarks:

1. overhead: lease + complete round trips per second of one worker on tiny tasks (8x8 pixels,
   1 spp, as bench/farm_bench.sh, which runs this part at its end) with no page open, against the same with N pages open and
   refreshing, in interleaved rounds (the order alternating), as a ratio with its standard
   error. A "page" is a client making the requests the monitor's page makes, at its cadence:
   every 2 s the jobs list (first page), the workers, the open job, its frame's history and,
   when the frame has a new prefix, its preview. Browsers run elsewhere in a real farm, so
   Chromium itself is not on this machine's cores here.
2. scale: 1,000 jobs and 1,000 simulated workers (bench/soak_load), then the server's answer
   time for the page's HTML, a page of 100 jobs, and the 1,000 workers (p50 and p95 over 50
   requests on a kept-alive connection), and in headless Chromium the page's DOMContentLoaded
   and the time until its jobs table is filled.

    build/pyvenv/bin/python bench/monitor_bench.py [--rounds 6] [--tasks 3000] [--pages 5]
        [--jobs 1000] [--workers 1000] [--skip-overhead] [--skip-scale]

Needs the built binaries (build/bin/rayfarm, build/bin/soak_load) and the client venv
(tools/python-venv.sh build/pyvenv; Chromium for the page timing).
"""

import argparse
import http.client
import json
import math
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time

ROOT = os.path.abspath(os.path.join(os.path.dirname(__file__), ".."))
BIN = os.environ.get("RAYFARM_BIN", os.path.join(ROOT, "build", "bin", "rayfarm"))
SOAK = os.path.join(os.path.dirname(BIN), "soak_load")
CORNELL = os.path.join(ROOT, "scenes", "cornell-box", "scene.json")


def start_coordinator(state, log, extra=()):
    out = open(log, "w")
    p = subprocess.Popen([BIN, "coordinator", "--listen", "127.0.0.1:0", "--state-dir", state,
                          "--monitor-listen", "127.0.0.1:0", *extra], stdout=out,
                         stderr=subprocess.STDOUT)
    for _ in range(500):
        text = open(log).read()
        m, w = re.search(r"\(port (\d+)\)", text), re.search(r"\(monitor port (\d+)\)", text)
        if m and w:
            return p, int(m.group(1)), int(w.group(1))
        time.sleep(0.02)
    raise SystemExit("coordinator did not start:\n" + open(log).read())


class Page(threading.Thread):
    """The requests of one open monitor page (coordinator/monitor_page.h), every 2 s."""

    def __init__(self, port, job):
        super().__init__(daemon=True)
        self.port, self.job, self.stop = port, job, threading.Event()
        self.requests = 0

    def run(self):
        c = http.client.HTTPConnection("127.0.0.1", self.port, timeout=10)
        c.request("POST", "/api/login", body="{}", headers={"Content-Type": "application/json"})
        r = c.getresponse()
        body = json.loads(r.read())
        cookie = r.getheader("Set-Cookie").split(";")[0]
        h = {"Cookie": cookie, "X-CSRF-Token": body["csrf"]}
        last = None
        while not self.stop.is_set():
            for path in ("/api/jobs?limit=100", "/api/workers?limit=100", f"/api/jobs/{self.job}",
                         f"/api/jobs/{self.job}/frames/0/history"):
                c.request("GET", path, headers=h)
                data = c.getresponse().read()
                self.requests += 1
                if path == f"/api/jobs/{self.job}":
                    passes = json.loads(data)["frames"][0]["passes_merged"]
            if passes and passes != last:
                c.request("GET", f"/api/jobs/{self.job}/frames/0/preview.png?passes={passes}",
                          headers=h)
                c.getresponse().read()
                self.requests += 1
                last = passes
            self.stop.wait(2.0)


def round_trips(tasks, pages, tmp, k):
    """Tasks/s of one worker on `tasks` tiny tasks, with `pages` pages open."""
    coord, port, mport = start_coordinator(f"{tmp}/state-{k}", f"{tmp}/coord-{k}.log")
    env = {**os.environ, "RAYFARM_COORDINATOR": f"127.0.0.1:{port}"}
    try:
        job = subprocess.run([BIN, "submit", CORNELL, "--res", "8x8", "--tile-size", "8", "--spp",
                              str(tasks), "--passes", str(tasks), "--name", "tiny"], env=env,
                             capture_output=True, text=True, check=True).stdout.strip()
        openers = [Page(mport, job) for _ in range(pages)]
        for p in openers:
            p.start()
        time.sleep(0.5 if pages else 0.0)
        t0 = time.monotonic()
        w = subprocess.Popen([BIN, "worker", "--exit-when-idle", "--cache-dir", f"{tmp}/cache",
                              "--threads", "1"], env=env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.DEVNULL)
        subprocess.run([BIN, "watch", job], env=env, stdout=subprocess.DEVNULL,
                       stderr=subprocess.DEVNULL, check=True)
        seconds = time.monotonic() - t0
        w.wait(60)
        for p in openers:
            p.stop.set()
        requests = sum(p.requests for p in openers)
        return tasks / seconds, requests / seconds
    finally:
        coord.terminate()
        coord.wait(30)


def overhead(a):
    tmp = tempfile.mkdtemp(prefix="monitor-bench-")
    try:
        ratios, base, loaded, rps = [], [], [], []
        for r in range(a.rounds):
            order = (0, a.pages) if r % 2 == 0 else (a.pages, 0)
            got = {}
            for pages in order:
                got[pages] = round_trips(a.tasks, pages, tmp, f"{r}-{pages}")
            base.append(got[0][0])
            loaded.append(got[a.pages][0])
            rps.append(got[a.pages][1])
            ratios.append(got[a.pages][0] / got[0][0])
            print(f"  round {r + 1}: {got[0][0]:.0f} tasks/s without pages, "
                  f"{got[a.pages][0]:.0f} with {a.pages} ({got[a.pages][1]:.1f} page requests/s)",
                  flush=True)
        mean = statistics.mean(ratios)
        se = statistics.stdev(ratios) / math.sqrt(len(ratios)) if len(ratios) > 1 else float("nan")
        print(f"overhead: {a.rounds} interleaved rounds of {a.tasks} tiny tasks, 1 worker: "
              f"{statistics.mean(base):.0f} tasks/s without pages, {statistics.mean(loaded):.0f} "
              f"with {a.pages} pages; ratio {mean:.3f} +- {se:.3f} (standard error): "
              f"{(1 - mean) * 100:+.1f}% slower")
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def timed_get(c, path, headers):
    t0 = time.perf_counter()
    c.request("GET", path, headers=headers)
    r = c.getresponse()
    body = r.read()
    return time.perf_counter() - t0, r.status, len(body)


def scale(a):
    import rayfarm  # the installed client (tools/python-venv.sh)
    tmp = tempfile.mkdtemp(prefix="monitor-scale-")
    coord, port, mport = start_coordinator(f"{tmp}/state", f"{tmp}/coord.log",
                                           ["--lease-seconds", "60"])
    soak = None
    try:
        farm = rayfarm.Farm(f"127.0.0.1:{port}", tls=False, binary=BIN, timeout=60)
        t0 = time.monotonic()

        def submit(first):
            for i in range(first, a.jobs, 4):
                # Never leased (a tag no worker has): 1,000 queued jobs on the page.
                farm.submit(CORNELL, spp=1, passes=1, resolution=(8, 8), name=f"job-{i:04d}",
                            tags=["never"])

        threads = [threading.Thread(target=submit, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        print(f"scale: {a.jobs} jobs submitted in {time.monotonic() - t0:.1f} s", flush=True)
        soak = subprocess.Popen([SOAK, "--coordinator", f"127.0.0.1:{port}", "--workers",
                                 str(a.workers), "--seconds", "600", "--cache", f"{tmp}/soak"],
                                stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        for _ in range(300):
            if len(farm.workers()) >= a.workers:
                break
            time.sleep(0.2)
        print(f"scale: {len(farm.workers())} workers registered", flush=True)
        c = http.client.HTTPConnection("127.0.0.1", mport, timeout=30)
        c.request("POST", "/api/login", body="{}", headers={"Content-Type": "application/json"})
        r = c.getresponse()
        r.read()
        h = {"Cookie": r.getheader("Set-Cookie").split(";")[0]}
        for path in ("/", "/api/jobs?limit=100", "/api/workers?limit=100",
                     "/api/workers?limit=1000"):
            times, size = [], 0
            for _ in range(50):
                dt, status, size = timed_get(c, path, h)
                assert status == 200, (path, status)
                times.append(dt)
            times.sort()
            print(f"  GET {path}: {size} bytes, p50 {times[24] * 1e3:.1f} ms, "
                  f"p95 {times[47] * 1e3:.1f} ms")
        page_timing(mport)
    finally:
        if soak:
            soak.terminate()
            soak.wait(30)
        coord.terminate()
        coord.wait(30)
        shutil.rmtree(tmp, ignore_errors=True)


def page_timing(mport):
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError:
        print("  page: python3-selenium is not installed; skipped")
        return
    options = webdriver.ChromeOptions()
    options.binary_location = shutil.which("chromium") or "/usr/bin/chromium"
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage"):
        options.add_argument(arg)
    d = webdriver.Chrome(service=Service(shutil.which("chromedriver") or "/usr/bin/chromedriver"),
                         options=options)
    try:
        url = f"http://127.0.0.1:{mport}/"
        d.get(url)  # the session (open mode) and a warm cache
        dcl, filled = [], []
        for _ in range(5):
            d.get(url)
            while True:  # the first moment the table has its 100 rows, on the page's clock
                rows, now = d.execute_script(
                    "return [document.querySelectorAll('#jobs tbody tr').length,"
                    " performance.now()]")
                if rows >= 100:
                    break
                time.sleep(0.005)
            dcl.append(d.execute_script(
                "return performance.getEntriesByType('navigation')[0].domContentLoadedEventEnd"))
            filled.append(now)
        print(f"  page in Chromium: DOMContentLoaded {statistics.median(dcl):.0f} ms, jobs table "
              f"filled {statistics.median(filled):.0f} ms after navigation start (median of 5)")
    finally:
        d.quit()


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--rounds", type=int, default=6)
    p.add_argument("--tasks", type=int, default=3000)
    p.add_argument("--pages", type=int, default=5)
    p.add_argument("--jobs", type=int, default=1000)
    p.add_argument("--workers", type=int, default=1000)
    p.add_argument("--skip-overhead", action="store_true")
    p.add_argument("--skip-scale", action="store_true")
    a = p.parse_args()
    cpu = next((line.split(":", 1)[1].strip() for line in open("/proc/cpuinfo")
                if line.startswith("model name")), "?")
    print(f"monitor bench: {os.cpu_count()} cores, {cpu}")
    if not a.skip_overhead:
        overhead(a)
    if not a.skip_scale:
        scale(a)


if __name__ == "__main__":
    main()
