"""The pages in a real browser, for the browser test and `make bench` section web: the app served on 127.0.0.1
in a thread, and Debian's headless Chromium driven by Selenium (selenium is a dev dependency; Chromium and
chromedriver come from apt: `apt-get install chromium chromium-driver`)."""

from __future__ import annotations

import os
import shutil
import socket
import tempfile
import threading
import time
import weakref
from contextlib import contextmanager
from pathlib import Path
from typing import Iterator, Optional

CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
WAIT_S = 120


def missing() -> list[str]:
    """What of Chromium and chromedriver is not here (empty: both are)."""
    return [path for path in (CHROMIUM, CHROMEDRIVER) if not os.access(path, os.X_OK)]


def browser(width: int = 1400, height: int = 1000):
    """A headless Chromium of that window size, driven by Selenium."""
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    profile = tempfile.mkdtemp(prefix="spreadgym-chromium-")  # its own profile: two browsers at once do not clash
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", f"--window-size={width},{height}",
                 "--disable-gpu", f"--user-data-dir={profile}"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(WAIT_S)
    driver.set_script_timeout(WAIT_S)
    weakref.finalize(driver, shutil.rmtree, profile, True)  # the profile goes with the driver
    return driver


@contextmanager
def served(charts: Optional[Path] = None) -> Iterator[str]:
    """The app on a free port of 127.0.0.1 in a thread of this process; yields its address."""
    import uvicorn

    from spreadgym.agents.web.app import create_app

    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    app = create_app(charts) if charts is not None else create_app()
    server = uvicorn.Server(uvicorn.Config(app, host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    if not server.started:
        raise RuntimeError("the server did not start in 60 s")
    try:
        yield f"http://127.0.0.1:{port}"
    finally:
        server.should_exit = True
        thread.join(timeout=15)


def wait(driver, script: str, timeout: float = WAIT_S):
    """Poll `script` (JavaScript returning a value) until it is truthy; its value."""
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.02).until(lambda d: d.execute_script(script))


SETTLED = ("return document.body.dataset.stale === 'no' && ['full', 'precise'].includes(document.body.dataset.mode)"
           " && window.__requests.every(r => r.ended !== null)")
"""The pattern page shows a settled answer for its controls, nothing in flight."""
