"""The screens in a real browser (headless Chromium): the operator's bolt map as the station
works, a fault's reason, the cameras' frames, the results and their export."""

from __future__ import annotations

import csv
import io
import time

import numpy as np
from selenium.webdriver.common.by import By
from selenium.webdriver.support.ui import WebDriverWait

from stationd.station.events import BoltSkipped
from stationd.web.results import Results
from tests.web.scenario import VIN, fault, opened, results_db, work


def wait(browser, cond, timeout: float = 15.0):
    return WebDriverWait(browser, timeout, poll_frequency=0.05).until(lambda d: cond(d))


def bolts(browser) -> dict[str, tuple[str, str]]:
    """Bolt -> (state, label text), read in one script (the map is redrawn live)."""
    got = browser.execute_script(
        "return [...document.querySelectorAll('#bolts g.bolt')].map(g => [g.dataset.bolt,"
        " g.dataset.state, g.querySelector('text.label').textContent])")
    return {b: (s, t) for b, s, t in got}


def bolt_states(browser) -> dict[str, str]:
    return {b: s for b, (s, _) in bolts(browser).items()}


def test_operator_screen_follows_the_work_and_shows_the_fault(live_server, browser, shots):
    srv = live_server()
    srv.publish(opened())
    browser.get(srv.url)
    wait(browser, lambda d: len(bolt_states(d)) == 4)
    assert set(bolt_states(browser).values()) == {"pending"}
    assert browser.find_element(By.ID, "vin").text == VIN
    shots("operator-opened")

    srv.publish(work())
    wait(browser, lambda d: bolt_states(d).get("B3") == "tightening")
    assert bolt_states(browser) == {"B1": "ok", "B2": "nok", "B3": "tightening", "B4": "next"}
    # colour is never the only cue: each bolt carries its label
    labels = {b: t for b, (_, t) in bolts(browser).items()}
    assert labels["B1"].startswith("OK") and labels["B2"].startswith("NOK")
    assert labels["B4"] == "next"
    assert browser.find_element(By.ID, "done").text == "1"
    assert browser.find_element(By.ID, "total").text == "4"
    assert browser.find_element(By.ID, "nok").text == "1"
    assert "B3 (pset 1): tighten" in browser.find_element(By.ID, "headline").text
    assert browser.find_elements(By.ID, "wrench-mark")
    cls, text = browser.execute_script(
        "const r = document.querySelector('#results tr'); return [r.className, r.innerText]")
    assert cls == "res-nok" and "B2 NOK" in text and "[45.0-55.0]" in text
    shots("operator-working")

    srv.publish([BoltSkipped(bolt="B4", reason="thread damaged"), *fault()])
    head = browser.find_element(By.ID, "headline")     # the element stays, its text changes
    wait(browser, lambda d: "FAULT" in head.text)
    assert "lift: no answer from 10.0.0.7:502" in head.text
    assert "stop" in (head.get_attribute("class") or "")
    cls, text = browser.execute_script(
        "const li = document.querySelector('#devices li[data-device=lift]');"
        " return [li.className, li.textContent]")
    assert cls == "dev-bad" and "timeout" in text
    assert bolts(browser)["B4"] == ("skipped", "skipped")
    shots("operator-fault")


def test_cameras_screen_shows_frames_overlay_and_refusal(live_server, browser, shots):
    srv = live_server()
    rng = np.random.default_rng(5)
    img = (rng.integers(0, 60, (1200, 1600), dtype=np.uint8))
    img[500:700, 700:900] = 200
    ellipses = [[800, 600, 90, 80, 10], [800, 600, 45, 40, 10]]
    srv.frames.put("front", "left", img, {"found": True, "roi": [600, 400, 400, 400],
                                          "ellipses": ellipses, "centre": [800, 600],
                                          "exposure_us": 800})
    srv.frames.put("front", "right", img, {"found": False, "reason": "marker not found"})
    browser.get(srv.url + "cameras")
    wait(browser, lambda d: len(d.find_elements(By.CSS_SELECTOR, ".cam img")) == 2)
    # reduced on the server to the width shown (half of 1920 rounded up to 320 px steps)
    wait(browser, lambda d: d.execute_script(
        "return [...document.querySelectorAll('.cam img')].every(i => i.naturalWidth === 960)"))
    left = browser.find_element(By.CSS_SELECTOR, ".cam[data-camera='front/left']")
    assert len(left.find_elements(By.CSS_SELECTOR, "ellipse")) == 2
    assert left.find_elements(By.CSS_SELECTOR, "rect.roi")
    assert "sharpness" in left.text and "marker found" in left.text
    right = browser.find_element(By.CSS_SELECTOR, ".cam[data-camera='front/right']")
    assert "refused: marker not found" in right.text
    browser.find_element(By.ID, "live").click()          # stop the refresh to click a frame
    left = browser.find_element(By.CSS_SELECTOR, ".cam[data-camera='front/left'] img")
    left.click()
    crop = browser.find_element(By.ID, "crop-img")
    wait(browser, lambda d: d.execute_script("return arguments[0].naturalWidth", crop) == 512)
    shots("cameras")


def test_results_screens_and_csv_download(live_server, browser, shots, tmp_path):
    repo = results_db(tmp_path)
    try:
        srv = live_server(results=Results(repo))
        browser.get(srv.url + "vehicles")
        wait(browser, lambda d: d.find_elements(By.CSS_SELECTOR, "#vehicles tbody tr"))
        row = browser.find_element(By.CSS_SELECTOR, f"#vehicles tr[data-vin='{VIN}']")
        assert "SEDAN" in row.text and "open" in row.text
        shots("vehicles")
        row.find_element(By.TAG_NAME, "a").click()
        wait(browser, lambda d: len(d.find_elements(By.CSS_SELECTOR, "tr.rundown")) == 5)
        b2 = browser.find_elements(By.CSS_SELECTOR, "tr.rundown[data-bolt=B2]")
        assert "NOK" in b2[0].text and "2 (rework)" in b2[1].text
        shots("vehicle")
        browser.find_element(By.ID, "csv").click()
        target = browser.downloads / f"{VIN}.csv"
        deadline = time.monotonic() + 15
        while not target.exists() and time.monotonic() < deadline:
            time.sleep(0.05)
        rows = list(csv.DictReader(io.StringIO(target.read_text())))
        assert [(r["bolt"], r["status"]) for r in rows] == [("B1", "ok"), ("B2", "nok"),
                                                           ("B2", "ok")]
    finally:
        repo.close()
