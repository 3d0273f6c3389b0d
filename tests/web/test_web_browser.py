"""The pages in a real browser: Debian's headless Chromium driven by Selenium against a
served app on 127.0.0.1. Moving the disc-speed slider changes the CV text and the pattern
picture; the time from the key press to the new picture is measured (median printed,
not asserted). Every resource the pages load comes from the server itself (offline).
The stale-answer sequences (a drag back to its start, an emptied or out-of-range field, a
fast drag whose superseded requests are aborted) end on the picture `spreadgym simulate
--json` gives for the controls shown; the layout at 390 x 844 (a phone) and 1400 x 900 has
no horizontal scroll, no text under 12 px and no legend over a title; the print views
carry their records.

Set SPREADGYM_WEB_SHOTS=DIR to keep the screenshots and timings there (docs/web/).
"""

import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest

from spreadgym.agents.web import browser

ROOT = Path(__file__).resolve().parents[2]
MOVES = 9
WAIT_S = browser.WAIT_S

# Records the moment of each key press and of each new picture (data-rev) in the page's clock.
PROBE = """
window.__keys = []; window.__renders = [];
document.addEventListener('keydown', () => window.__keys.push(performance.now()), true);
new MutationObserver(() => window.__renders.push([performance.now(), document.body.dataset.mode]))
  .observe(document.body, {attributes: true, attributeFilter: ['data-rev']});
"""


@pytest.fixture(scope="module")
def server(tmp_path_factory):
    charts = tmp_path_factory.mktemp("charts")
    shutil.copytree(ROOT / "docs" / "charts" / "paper", charts / "paper")
    with browser.served(charts) as address:
        yield address


@pytest.fixture(scope="module")
def driver():
    if browser.missing():
        pytest.skip(f"no browser: {', '.join(browser.missing())} not found; install Debian's chromium and "
                    "chromium-driver (apt-get install chromium chromium-driver; .ci/run does)")
    chromium = browser.browser()
    yield chromium
    chromium.quit()


def _wait(driver, script: str, timeout: float = WAIT_S):
    return browser.wait(driver, script, timeout)


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
    slider = driver.find_element(By.CSS_SELECTOR, 'input[type=range][data-key="spinner.rpm"]')
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
    assert "fitted model" in driver.find_element(By.ID, "fit-cv").text
    shots = _shots()
    if shots:
        driver.save_screenshot(str(shots / "fit.png"))
    # a failed fit clears the last result: no estimates, no download, no pictures; the error names the control
    broken = tmp_path / "broken.csv"
    broken.write_text("x_m,mass_g\n0,1\n0.5,2\n")
    driver.find_element(By.ID, "trays").send_keys(str(broken))
    driver.find_element(By.ID, "start").click()
    _wait(driver, "return document.getElementById('error').textContent")
    error = driver.find_element(By.ID, "error").text
    assert error.startswith("tray test:") and "--trays" not in error, error
    assert driver.find_elements(By.ID, "estimates") == [] and driver.find_elements(By.CSS_SELECTOR, "#download a") == []
    assert driver.execute_script("return document.getElementById('pattern').data === undefined")
    assert driver.execute_script("return document.body.dataset.fitted === undefined")


def _settled(driver, timeout: float = WAIT_S):
    """Wait until the page shows a settled answer (full or precise) for its controls, nothing in flight."""
    _wait(driver, browser.SETTLED, timeout)


def _cli_json(shown: dict) -> dict:
    """`spreadgym simulate --json` for the controls the page shows (its scene and --set values)."""
    argv = [sys.executable, "-m", "spreadgym.cli.main", "simulate", "--scene", shown["scene"], "--json"]
    for key, value in shown["set"].items():
        argv += ["--set", f"{key}={json.dumps(value)}"]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def _assert_answers_the_controls(driver):
    """The picture shown is `simulate --json` of the controls shown (wall time aside), and the controls the page
    sent are the fields' values."""
    shown = driver.execute_script("return window.__shown")
    fields = driver.execute_script("return [...document.querySelectorAll('#controls input[type=number]')]"
                                   ".map(f => [f.dataset.key, Number(f.value)])")
    for key, value in fields:
        sent = shown["set"][key]
        assert (value in sent) if isinstance(sent, list) else sent == value, (key, value, sent)
    cli = _cli_json(shown)
    page = {k: v for k, v in shown["metrics"].items() if k != "wall_s"}
    assert page == {k: v for k, v in cli.items() if k != "wall_s"}


def _no_superseded_answer_after_its_successor(driver):
    """No request completes (is shown) after a later one started."""
    requests = driver.execute_script("return window.__requests")
    for a in requests:
        for b in requests:
            if b["seq"] > a["seq"] and a["outcome"] == "shown":
                assert a["ended"] <= b["started"] + 1.0, (a, b)
    return requests


def test_a_drag_back_to_its_start_settles(server, driver):
    from selenium.webdriver.common.action_chains import ActionChains
    from selenium.webdriver.common.by import By

    driver.get(server + "/")
    _settled(driver)
    slider = driver.find_element(By.CSS_SELECTOR, 'input[type=range][data-key="spinner.rpm"]')
    start = slider.get_attribute("value")
    driver.execute_script("window.__requests.length = 0")
    chain = ActionChains(driver).click_and_hold(slider)
    for dx in (40, 40, 40, -40, -40, -40):
        chain.move_by_offset(dx, 0).pause(0.15)
    chain.release().perform()
    _settled(driver)
    assert slider.get_attribute("value") == driver.find_element(By.ID, "c0").get_attribute("value")
    assert any(r["mode"] == "draft" for r in driver.execute_script("return window.__requests"))
    assert driver.execute_script("return document.body.dataset.mode") == "full"
    _no_superseded_answer_after_its_successor(driver)
    _assert_answers_the_controls(driver)
    del start


def test_an_emptied_or_out_of_range_field_is_never_sent(server, driver):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    driver.get(server + "/")
    _settled(driver)
    field = driver.find_element(By.CSS_SELECTOR, 'input[type=number][data-key="feed.radius_m"]')
    sent = driver.execute_script("return window.__requests.length")
    field.send_keys(Keys.CONTROL, "a")
    field.send_keys(Keys.BACKSPACE)
    field.send_keys(Keys.TAB)
    _wait(driver, "return document.body.dataset.stale === 'yes'")
    error = driver.find_element(By.ID, "error").text
    assert error.startswith("drop point radius: enter a number in [") and "m" in error
    assert "not updated" in driver.find_element(By.ID, "stale").text
    assert field.get_attribute("aria-invalid") == "true"
    disc = driver.find_element(By.CSS_SELECTOR, 'input[type=number][data-key="spinner.rpm"]')
    disc.send_keys(Keys.CONTROL, "a")
    disc.send_keys("1500", Keys.TAB)  # over the slider's 1100: refused, not pinned
    _wait(driver, "return document.getElementById('error').textContent.includes('disc speed: enter a number in')")
    time.sleep(1.5)  # a pause longer than the page's settle timer: still nothing sent
    assert driver.execute_script("return window.__requests.length") == sent
    for element, value in ((field, "0.06"), (disc, "800")):
        element.send_keys(Keys.CONTROL, "a")
        element.send_keys(value, Keys.TAB)
    _settled(driver)
    assert driver.find_element(By.ID, "error").text == ""
    assert driver.execute_script("return window.__shown.set['spinner.rpm']") == 800
    _assert_answers_the_controls(driver)


def test_a_fast_drag_aborts_superseded_requests(server, driver):
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    driver.get(server + "/")
    _settled(driver)
    driver.execute_script("window.__requests.length = 0")
    slider = driver.find_element(By.CSS_SELECTOR, 'input[type=range][data-key="vanes.pitch_deg"]')
    for key in [Keys.ARROW_RIGHT] * 12 + [Keys.PAGE_UP, Keys.ARROW_LEFT, Keys.ARROW_LEFT]:
        slider.send_keys(key)  # each press is a release too (keyup): drafts and settled answers supersede each other
    _settled(driver)
    requests = _no_superseded_answer_after_its_successor(driver)
    assert any(r["outcome"] == "aborted" for r in requests), requests
    assert requests[-1]["outcome"] == "shown" and requests[-1]["mode"] == "full"
    _assert_answers_the_controls(driver)


LAYOUT_CHECKS = """
const out = {scroll: document.documentElement.scrollWidth - window.innerWidth, small: [], overlaps: [],
  unnamed: [...document.querySelectorAll('input, select')].filter(el => !el.labels.length
    && !el.getAttribute('aria-label')).map(el => el.id)};
for (const el of document.querySelectorAll('#controls input'))
  if (!el.getAttribute('aria-label')) out.unnamed.push(el.id);
const walker = document.createTreeWalker(document.body, NodeFilter.SHOW_TEXT);
while (walker.nextNode()) {
  const node = walker.currentNode, el = node.parentElement;
  if (!node.textContent.trim() || !el) continue;
  const style = getComputedStyle(el), box = el.getBoundingClientRect();
  if (style.display === 'none' || style.visibility === 'hidden' || box.width === 0 || el.closest('[hidden]')) continue;
  const size = parseFloat(style.fontSize);
  if (size < 12) out.small.push([node.textContent.trim().slice(0, 30), size]);
}
const hit = (a, b) => a.left < b.right - 1 && b.left < a.right - 1 && a.top < b.bottom - 1 && b.top < a.bottom - 1;
for (const plot of document.querySelectorAll('.js-plotly-plot')) {
  const legend = plot.querySelector('g.legend');
  if (!legend) continue;
  const box = legend.getBoundingClientRect();
  const titles = [...plot.querySelectorAll('.gtitle, .xtitle, .ytitle, .g-xtitle, .g-ytitle')];
  const heading = plot.closest('figure') && plot.closest('figure').querySelector('h2');
  if (heading) titles.push(heading);
  for (const t of titles) if (t.getBoundingClientRect().width && hit(box, t.getBoundingClientRect()))
    out.overlaps.push([plot.id, t.textContent]);
}
return out;
"""


@pytest.mark.parametrize("size", [(390, 844), (1400, 900)])
def test_the_layout_fits_a_phone_and_a_desktop(server, driver, size):
    width, height = size
    phone = width < 900
    driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": width, "height": height,
                                                                  "deviceScaleFactor": 1, "mobile": phone})
    try:
        driver.get(server + "/")
        _settled(driver)
        found = driver.execute_script(LAYOUT_CHECKS)
        assert found["scroll"] <= 0, f"horizontal scroll of {found['scroll']} px at {width} px"
        assert found["small"] == [], found["small"]
        assert found["overlaps"] == [], found["overlaps"]
        assert found["unnamed"] == [], found["unnamed"]  # every slider and field has an accessible name
        columns = driver.execute_script("return getComputedStyle(document.getElementById('figures'))"
                                        ".gridTemplateColumns.split(' ').length")
        assert columns == (1 if phone else 2)
        shots = _shots()
        if shots:
            name = "pattern-phone.png" if phone else "pattern.png"
            if phone:
                full = driver.execute_script("return document.documentElement.scrollHeight")
                driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {
                    "width": width, "height": full, "deviceScaleFactor": 1, "mobile": True})
            driver.save_screenshot(str(shots / name))
    finally:
        driver.execute_cdp_cmd("Emulation.clearDeviceMetricsOverride", {})


def test_the_pattern_page_prints_its_record(server, driver):
    from selenium.webdriver.common.by import By

    driver.get(server + "/")
    _settled(driver)
    driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": "print"})
    try:
        record = driver.find_element(By.ID, "record")
        assert record.is_displayed() and not driver.find_element(By.TAG_NAME, "aside").is_displayed()
        text = record.text
        cv = driver.execute_script("return window.__shown.metrics")
        for expected in ("scene paper", "compound-10-16-10", "disc speed", "vane pitch", "drop point radius",
                         "drop point angle", "working width", "racetrack", "+-", "effective swath", "printed 20",
                         "spreadgym 0."):
            assert expected in text, (expected, text)
        assert f"{cv['runs']} runs" in text
        shots = _shots()
        if shots:
            driver.save_screenshot(str(shots / "pattern-print.png"))
    finally:
        driver.execute_cdp_cmd("Emulation.setEmulatedMedia", {"media": ""})


def test_a_cv_above_the_curves_scale_stays_on_the_picture(server, driver):
    """At a working width far beyond the pattern the CV at the width is over the plotted range: its marker is
    pinned at the top with its value written beside it (it vanished)."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.common.keys import Keys

    driver.get(server + "/")
    _settled(driver)
    width = driver.find_element(By.CSS_SELECTOR, 'input[type=number][data-key="pattern.target_swath_m"]')
    width.send_keys(Keys.CONTROL, "a")
    width.send_keys(width.get_attribute("max"), Keys.TAB)
    _settled(driver)
    cv = driver.execute_script("return window.__shown.metrics.cv_percent_at_target")
    marker = driver.execute_script("const g = document.getElementById('curve'); const t = g.data.find(t => "
                                   "t.name.startsWith('CV at')); return [t.y[0], g.layout.yaxis.range[1], t.text]")
    assert cv > marker[1], "the case needs a CV over the scale"
    assert marker[0] <= marker[1] and marker[2] and f"{cv:.1f} %" in marker[2][0]
