"""The pages in a real browser: Debian's headless Chromium driven by Selenium against a
served app on 127.0.0.1. Moving the disc-speed slider changes the CV text and the pattern
picture; the time from the key press to the new picture is measured (median printed,
not asserted). Every resource the pages load comes from the server itself (offline).

Set SPREADGYM_WEB_SHOTS=DIR to keep the screenshots and timings there (docs/web/).
"""

import json
import os
import shutil
import socket
import statistics
import threading
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
CHROMIUM = shutil.which("chromium") or "/usr/bin/chromium"
CHROMEDRIVER = shutil.which("chromedriver") or "/usr/bin/chromedriver"
MOVES = 9
WAIT_S = 120

# Records the moment of each key press and of each new picture (data-rev) in the page's clock.
PROBE = """
window.__keys = []; window.__renders = [];
document.addEventListener('keydown', () => window.__keys.push(performance.now()), true);
new MutationObserver(() => window.__renders.push([performance.now(), document.body.dataset.mode]))
  .observe(document.body, {attributes: true, attributeFilter: ['data-rev']});
"""


def _browser():
    missing = [path for path in (CHROMIUM, CHROMEDRIVER) if not os.access(path, os.X_OK)]
    if missing:
        pytest.skip(f"no browser: {', '.join(missing)} not found; install Debian's chromium and chromium-driver "
                    "(apt-get install chromium chromium-driver; .ci/run does)")
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for flag in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1400,1000",
                 "--disable-gpu"):
        options.add_argument(flag)
    driver = webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)
    driver.set_page_load_timeout(WAIT_S)
    driver.set_script_timeout(WAIT_S)
    return driver


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    import uvicorn

    from spreadgym.agents.web.app import create_app

    charts = tmp_path_factory.mktemp("charts")
    shutil.copytree(ROOT / "docs" / "charts" / "paper", charts / "paper")
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        port = probe.getsockname()[1]
    server = uvicorn.Server(uvicorn.Config(create_app(charts), host="127.0.0.1", port=port, log_level="warning"))
    thread = threading.Thread(target=server.run, daemon=True)
    thread.start()
    deadline = time.monotonic() + 60
    while not server.started and time.monotonic() < deadline:
        time.sleep(0.05)
    assert server.started, "the server did not start in 60 s"
    yield f"http://127.0.0.1:{port}"
    server.should_exit = True
    thread.join(timeout=15)


@pytest.fixture(scope="module")
def driver():
    browser = _browser()
    yield browser
    browser.quit()


def _wait(driver, script: str, timeout: float = WAIT_S):
    from selenium.webdriver.support.ui import WebDriverWait

    return WebDriverWait(driver, timeout, poll_frequency=0.02).until(lambda d: d.execute_script(script))


def _shots() -> Path | None:
    where = os.environ.get("SPREADGYM_WEB_SHOTS")
    if where:
        Path(where).mkdir(parents=True, exist_ok=True)
    return Path(where) if where else None


def test_moving_the_disc_speed_changes_the_cv_and_the_pattern(server, driver):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    loads = []
    for _ in range(2):  # the first load meets a server just started; the second, a warm one
        started = time.perf_counter()
        driver.get(server + "/")
        _wait(driver, "return document.body.dataset.rev")
        loads.append(time.perf_counter() - started)
    origins = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    assert origins and all(url.startswith(server) for url in origins), origins  # nothing from the network
    cv_before = driver.find_element(By.ID, "cv").text
    picture_before = driver.find_element(By.ID, "pattern").screenshot_as_png
    driver.execute_script(PROBE)
    slider = driver.find_element(By.CSS_SELECTOR, 'input[data-key="spinner.rpm"]')
    first, settled = [], []
    for move in range(MOVES):
        rev = driver.execute_script("return document.body.dataset.rev")
        slider.send_keys(Keys.PAGE_UP if move < MOVES // 2 + 1 else Keys.PAGE_DOWN)
        _wait(driver, f"return document.body.dataset.rev !== '{rev}' && document.body.dataset.mode === 'full'")
        pressed, renders = driver.execute_script("return [window.__keys.at(-1), window.__renders]")
        after = [(t, mode) for t, mode in renders if t >= pressed]
        first.append((after[0][0] - pressed) / 1e3)
        settled.append((next(t for t, mode in after if mode == "full") - pressed) / 1e3)
    cv_after = driver.find_element(By.ID, "cv").text
    picture_after = driver.find_element(By.ID, "pattern").screenshot_as_png
    assert cv_after != cv_before and "+-" in cv_after
    assert picture_after != picture_before
    rev = driver.execute_script("return document.body.dataset.rev")
    driver.find_element(By.ID, "precise").click()
    _wait(driver, f"return document.body.dataset.rev !== '{rev}' && document.body.dataset.mode === 'precise'")
    assert "0.1 pp asked" in driver.find_element(By.ID, "summary").text
    timings = {"page_load_first_s": round(loads[0], 3), "page_load_s": round(loads[1], 3),
               "slider_to_picture_median_s": round(statistics.median(first), 3),
               "slider_to_settled_picture_median_s": round(statistics.median(settled), 3), "moves": MOVES}
    print(f"\nweb timings: {json.dumps(timings)}")
    shots = _shots()
    if shots:
        driver.save_screenshot(str(shots / "pattern.png"))
        (shots / "timings.json").write_text(json.dumps(timings, indent=2) + "\n")


def test_the_chart_page_shows_a_chart(server, driver):
    from selenium.webdriver.common.by import By

    driver.get(server + "/charts")
    _wait(driver, "return document.querySelectorAll('#folders a').length > 0")
    driver.find_element(By.CSS_SELECTOR, "#folders a").click()
    _wait(driver, "return document.querySelector('#chart table') && document.querySelector('#chart img')"
                  " && document.querySelector('#chart img').complete")
    assert "compound-10-16-10" in driver.find_element(By.CSS_SELECTOR, "#chart table").text
    shots = _shots()
    if shots:
        driver.save_screenshot(str(shots / "charts.png"))


def test_an_uploaded_scene_drives_the_page(server, driver, tmp_path):
    from selenium.webdriver.common.by import By

    text = (ROOT / "configs" / "scenes" / "paper.yaml").read_text().replace("rpm: 500", "rpm: 700")
    assert "rpm: 700" in text
    upload = tmp_path / "mine.yaml"
    upload.write_text(text)
    driver.get(server + "/")
    _wait(driver, "return document.body.dataset.rev")
    rev = driver.execute_script("return document.body.dataset.rev")
    driver.find_element(By.ID, "upload").send_keys(str(upload))
    _wait(driver, f"return document.body.dataset.rev !== '{rev}'")
    assert driver.find_element(By.ID, "c0").get_attribute("value") == "700"
    broken = tmp_path / "broken.yaml"  # another name: the same file chosen again fires no change
    broken.write_text("spinner: [unclosed")
    driver.find_element(By.ID, "upload").send_keys(str(broken))
    _wait(driver, "return document.getElementById('error').textContent.includes('uploaded scene')")


def test_the_fit_page_fits_a_tray_test(server, driver, tmp_path):
    from selenium.webdriver.common.by import By

    from spreadgym.config.scene import load_scene
    from spreadgym.fit.synthetic import synthetic_tray_test
    from spreadgym.fit.trays import write_trays

    key = "contact.vane_restitution"
    test = synthetic_tray_test(load_scene("paper"), {key: 0.5}, model="compiled", granules=4096, noise_seed=3)
    trays = write_trays(tmp_path / "trays.csv", test, "synthetic, restitution 0.5")
    driver.get(server + "/fit")
    _wait(driver, "return document.getElementById('scene').options.length > 0")
    driver.find_element(By.ID, "trays").send_keys(str(trays))
    granules = driver.find_element(By.ID, "granules")
    granules.clear()
    granules.send_keys("1024")
    driver.find_element(By.ID, "start").click()
    _wait(driver, "return document.body.dataset.fitted === 'yes' || document.getElementById('error').textContent")
    assert driver.find_element(By.ID, "error").text == ""
    assert key in driver.find_element(By.ID, "estimates").text
    assert driver.find_element(By.CSS_SELECTOR, "#download a").get_attribute("download") == "paper-fitted.yaml"
    shots = _shots()
    if shots:
        driver.save_screenshot(str(shots / "fit.png"))
