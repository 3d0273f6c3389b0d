"""`make bench`, section web: the pattern page's answers in a real browser (agents/web/browser.py), median and
range over `repeats`:

* page load to the settled picture (server warm), at 1400 x 900 and on a 390 x 844 phone;
* a slider dragged: from the last move to the draft picture (the two pilot runs), and from the release to the
  settled picture (`simulate`'s precision);
* a fast drag on the plate scene (ten moves of a plate's angle in a second, then the release): from the release
  to the final picture, with the superseded requests aborted (their count) and their runs stopped on the
  server.
"""

from __future__ import annotations

import statistics
import time
from typing import Callable, Optional

from spreadgym.agents.web import browser

INSTRUMENT = """
window.__marks = [];
for (const el of document.querySelectorAll('input[type=range]')) {
  el.addEventListener('input', () => window.__marks.push(['input', performance.now()]), true);
  el.addEventListener('pointerup', () => window.__marks.push(['release', performance.now()]), true);
}
new MutationObserver(() => window.__marks.push([document.body.dataset.mode, performance.now()]))
  .observe(document.body, {attributes: true, attributeFilter: ['data-rev']});
"""


def _row(measure: str, values: list[float], **extra) -> dict:
    return {"measure": measure, "median_s": statistics.median(values), "low_s": min(values), "high_s": max(values),
            "n": len(values), **extra}


def _load(driver, address: str, timeout: float = browser.WAIT_S) -> float:
    started = time.perf_counter()
    driver.get(address + "/")
    browser.wait(driver, browser.SETTLED, timeout)
    return time.perf_counter() - started


def _drag(driver, slider, steps: list[int], pause_s: float) -> list:
    """Hold `slider`, move it by `steps` pixels with `pause_s` between, release, wait for the settled picture;
    the page's marks (input, release, picture modes) in its clock (ms)."""
    from selenium.webdriver.common.action_chains import ActionChains

    driver.execute_script(INSTRUMENT)
    chain = ActionChains(driver).click_and_hold(slider)
    for dx in steps:
        chain.move_by_offset(dx, 0).pause(pause_s)
    chain.release().perform()
    browser.wait(driver, browser.SETTLED)
    return driver.execute_script("return window.__marks")


def _after(marks: list, kind: str, start: float) -> Optional[float]:
    return next((t for k, t in marks if k == kind and t >= start), None)


def web_rows(repeats: int = 5, progress: Optional[Callable[[str], None]] = None) -> list[dict]:
    """The section's rows (seconds); skipped, with a row saying why, where Chromium is missing."""
    from selenium.webdriver.common.by import By
    from selenium.webdriver.support.ui import Select

    if browser.missing():
        return [{"measure": f"skipped: {', '.join(browser.missing())} not found (apt-get install chromium "
                            "chromium-driver)", "median_s": None, "low_s": None, "high_s": None, "n": 0}]
    rows = []
    with browser.served() as address:
        driver = browser.browser(1400, 900)
        try:
            _load(driver, address, 10 * browser.WAIT_S)  # the server's first answer warms it (and compiles)
            rows.append(_row("page load, 1400 x 900", [_load(driver, address) for _ in range(repeats)]))
            draft, settled = [], []
            for k in range(repeats):
                slider = driver.find_element(By.CSS_SELECTOR, 'input[type=range][data-key="spinner.rpm"]')
                marks = _drag(driver, slider, [25 if k % 2 == 0 else -25] * 3, 0.25)  # pauses under the settle's
                inputs = [t for kind, t in marks if kind == "input"]
                release = _after(marks, "release", inputs[-1]) or inputs[-1]
                shown = _after(marks, "draft", inputs[0])
                if shown is not None:
                    draft.append((shown - inputs[0]) / 1e3)
                settled.append((_after(marks, "full", release) - release) / 1e3)
            rows.append(_row("slider moved to the draft picture (paper)", draft))
            rows.append(_row("slider released to the settled picture (paper)", settled))
            Select(driver.find_element(By.ID, "scene")).select_by_value("paper-deflectors")
            browser.wait(driver, "return document.querySelector('input[data-key=\"deflectors.0.angle_deg\"]')")
            browser.wait(driver, browser.SETTLED)
            finals, aborted = [], []
            for k in range(max(2, repeats // 2)):
                slider = driver.find_element(By.CSS_SELECTOR,
                                             'input[type=range][data-key="deflectors.0.angle_deg"]')
                driver.execute_script("window.__requests.length = 0")
                marks = _drag(driver, slider, [6 if k % 2 == 0 else -6] * 10, 0.1)
                release = max(t for kind, t in marks if kind in ("input", "release"))
                finals.append((_after(marks, "full", release) - release) / 1e3)
                aborted.append(driver.execute_script("return window.__requests.filter(r => r.outcome === "
                                                     "'aborted').length"))
            rows.append(_row("fast plate drag released to the final picture (paper-deflectors)", finals,
                             aborted_requests=statistics.median(aborted)))
            driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride", {"width": 390, "height": 844,
                                                                          "deviceScaleFactor": 1, "mobile": True})
            rows.append(_row("page load, 390 x 844 phone", [_load(driver, address) for _ in range(repeats)]))
        finally:
            driver.quit()
    if progress:
        for row in rows:
            progress(f"web: {row['measure']}: median {row['median_s']:.2f} s ({row['low_s']:.2f}-{row['high_s']:.2f})")
    return rows
