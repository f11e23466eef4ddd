"""The web monitor in a real browser: Debian's chromium, driven by chromium-driver through
python3-selenium, against a real coordinator (--monitor-listen) and worker (conftest.py).
ctest runs this file alone as Browser.Monitor (about a minute); it writes a screenshot to
$RAYFARM_SCREENSHOT_DIR/monitor.png (ctest: the build directory), which
tools/monitor-screenshot.sh copies to docs/img for the README."""

import hashlib
import http.server
import os
import shutil
import tempfile
import threading
import time
import urllib.error
import urllib.request

import pytest

from conftest import BINARY, CORNELL, LocalFarm

webdriver = pytest.importorskip("selenium.webdriver", reason="python3-selenium is not installed")
from selenium.webdriver.common.by import By  # noqa: E402

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"


def wait_for(what, predicate, timeout=90.0, interval=0.2):
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        value = predicate()
        if value:
            return value
        time.sleep(interval)
    raise AssertionError(f"timed out after {timeout:g} s waiting for {what}")


@pytest.fixture(scope="module")
def monitor_farm():
    if not BINARY or not os.access(BINARY, os.X_OK):
        pytest.skip("RAYFARM_BINARY is not set to the rayfarm binary")
    root = tempfile.mkdtemp(prefix="rayfarm-browser-")
    f = LocalFarm(root, monitor=True)  # workers are the test's
    yield f
    f.stop()
    shutil.rmtree(root, ignore_errors=True)


@pytest.fixture(scope="module")
def browser():
    if not (os.access(CHROMIUM, os.X_OK) and os.access(CHROMEDRIVER, os.X_OK)):
        pytest.skip("chromium and chromium-driver are not installed")
    from selenium.webdriver.chrome.service import Service
    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    # CI runs as root, where Chromium's sandbox cannot start.
    for arg in ("--headless=new", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                "--window-size=1400,1100", "--disable-extensions"):
        options.add_argument(arg)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_script_timeout(30)
    yield driver
    driver.quit()


def log_in(driver, farm, tenant):
    # Cookies are deleted for the page's own site: load the monitor first.
    driver.get(f"http://127.0.0.1:{farm.monitor_port}/")
    driver.delete_all_cookies()
    driver.get(f"http://127.0.0.1:{farm.monitor_port}/")
    wait_for("the login form", lambda: driver.find_element(By.ID, "login").is_displayed())
    driver.find_element(By.ID, "token").send_keys(farm.tokens[tenant])
    driver.find_element(By.ID, "login-button").click()
    wait_for("the jobs table", lambda: driver.find_element(By.ID, "app").is_displayed())


# The page rebuilds its tables every 2 s: each look and each click is one script, so no element
# found in one call goes stale before the next.
def row_state(driver, job_id):
    return driver.execute_script(
        "const r = document.getElementById('job-' + arguments[0]);"
        "return r ? r.dataset.state : null;", job_id)


def click(driver, selector):
    """Clicks the element the selector finds now; False when there is none."""
    return driver.execute_script(
        "const e = document.querySelector(arguments[0]); if (!e) return false;"
        "e.click(); return true;", selector)


def preview_digest(driver):
    """The SHA-256 of the preview image the page shows, fetched by the page itself (with its
    session cookie), and its URL."""
    src = driver.execute_script(
        "const i = document.querySelector('img.preview'); return i ? i.src : null;")
    if not src:
        return None
    data = driver.execute_async_script(
        "const done = arguments[arguments.length - 1];"
        "fetch(arguments[0], {credentials: 'same-origin'}).then(r => r.arrayBuffer())"
        ".then(b => done(Array.from(new Uint8Array(b)))).catch(e => done(null));", src)
    return (src, hashlib.sha256(bytes(data)).hexdigest()) if data else None


def test_browser_monitor(monitor_farm, browser, tmp_path):
    farm = monitor_farm
    client = farm.client("a")
    # Seen mid-way for sure: a first worker renders 4 of the 16 passes (a task is a whole pass:
    # one tile) and exits; a second one renders the rest while the page watches.
    job = client.submit(CORNELL, spp=512, passes=16, resolution=(192, 128), tile_size=256,
                        name="browser-test")
    first_worker = farm.worker("--max-tasks", "4")
    first_worker.proc.wait(120)
    assert job.status().frames[0].passes_merged == 4, first_worker.log()

    # The API needs the session cookie.
    with pytest.raises(urllib.error.HTTPError) as refused:
        urllib.request.urlopen(f"http://127.0.0.1:{farm.monitor_port}/api/jobs")
    assert refused.value.code == 401

    log_in(browser, farm, "a")
    wait_for("the job's row", lambda: row_state(browser, job.id))
    assert click(browser, f"#job-{job.id} button.link")
    first = wait_for("a preview", lambda: preview_digest(browser), timeout=60)
    assert "passes=4&" in first[0], first[0]
    farm.worker()
    # The preview changes as passes land (a new URL, a new image).
    changed = wait_for("a newer preview",
                       lambda: (lambda d: d if d and d[1] != first[1] else None)(
                           preview_digest(browser)), timeout=60)
    assert changed[0] != first[0]
    wait_for("the job to complete", lambda: row_state(browser, job.id) == "completed", 120)
    assert browser.find_elements(By.CSS_SELECTOR, "#frames svg.plot polyline")
    out = os.environ.get("RAYFARM_SCREENSHOT_DIR", str(tmp_path))
    os.makedirs(out, exist_ok=True)
    time.sleep(2.5)  # the final preview and plot
    browser.save_screenshot(os.path.join(out, "monitor.png"))

    # A cancel from the page cancels a second job (one no worker can take).
    second = client.submit(CORNELL, spp=4, passes=2, resolution=(8, 8), tags=["gpu"],
                           name="to-cancel")
    wait_for("the second job's row", lambda: row_state(browser, second.id) == "queued")
    assert click(browser, f"#job-{second.id} button[data-op=cancel]"), "no Cancel button"
    wait_for("the cancel", lambda: second.status().state == "cancelled", 30)
    wait_for("the page to show it", lambda: row_state(browser, second.id) == "cancelled", 30)

    # A page of another site cannot act with the session: its cross-site POST carries no cookie
    # (SameSite=Strict) and no CSRF token.
    third = client.submit(CORNELL, spp=4, passes=2, resolution=(8, 8), tags=["gpu"],
                          name="not-cancelled")
    evil_dir = tmp_path / "evil"
    evil_dir.mkdir()
    (evil_dir / "evil.html").write_text(
        "<!DOCTYPE html><script>window.answer = 'pending';"
        f"fetch('http://127.0.0.1:{farm.monitor_port}/api/jobs/{third.id}/cancel',"
        "{method: 'POST', credentials: 'include', mode: 'no-cors',"
        "headers: {'Content-Type': 'text/plain'}, body: '{}'})"
        ".then(() => window.answer = 'sent').catch(() => window.answer = 'failed');</script>")

    class Quiet(http.server.SimpleHTTPRequestHandler):
        def __init__(self, *a, **k):
            super().__init__(*a, directory=str(evil_dir), **k)

        def log_message(self, *a):
            pass

    evil = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Quiet)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    try:
        # localhost and 127.0.0.1 are different sites to the browser.
        browser.get(f"http://localhost:{evil.server_address[1]}/evil.html")
        wait_for("the cross-site request",
                 lambda: browser.execute_script("return window.answer") in ("sent", "failed"))
        time.sleep(0.5)
        assert third.status().state == "queued", "a cross-site POST cancelled a job"
    finally:
        evil.shutdown()

    # Another tenant's token sees none of tenant a's jobs.
    log_in(browser, farm, "b")
    wait_for("the status line", lambda: "jobs" in browser.find_element(By.ID, "status-line").text)
    for j in (job, second, third):
        assert row_state(browser, j.id) is None, f"tenant b sees {j.id}"
    assert browser.find_element(By.ID, "who").text == "tenant b"
