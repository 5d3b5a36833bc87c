"""The three reports in headless Chromium with no network: no console error, no request leaves the page, the
plots drew (their screenshots are not uniform), one camera marker per camera. Skipped without a browser."""
from __future__ import annotations

import json
import time

import pytest

from reports import write_grid_report, write_recommendation_report, write_run_report
from tests.browser import browser_or_skip, close, console_errors, element_pixels, external_requests, is_drawn
from tests.report_fixtures import make_grid, make_recommendation

COUNT_MARKERS = ("var d = document.getElementById('scene3d').data;"
                 "return d.filter(t => t.meta === 'cameras').reduce((n, t) => n + t.x.length, 0);")


@pytest.fixture(scope="module")
def browser():
    driver = browser_or_skip()
    yield driver
    close(driver)


def load(driver, path, plot_id: str) -> None:
    """Open a report and wait (up to 20 s) until plotly has drawn `plot_id`."""
    console_errors(driver)  # drop what an earlier page logged
    driver.get(path.resolve().as_uri())
    deadline = time.time() + 20
    while not driver.execute_script(f"var e = document.getElementById('{plot_id}'); return !!(e && e._fullLayout);"):
        assert time.time() < deadline, f"{plot_id} never drew"
        time.sleep(0.2)
    time.sleep(0.5)  # WebGL frame


def wait_until_clickable(driver, image) -> None:
    """Scroll a lazily loaded image into view and wait (up to 10 s) until it has loaded and has a size: clicking it
    before then fails with "element not interactable" (seen once in CI)."""
    driver.execute_script("arguments[0].scrollIntoView({block: 'center'});", image)
    deadline = time.time() + 10
    while not driver.execute_script("var e = arguments[0], r = e.getBoundingClientRect();"
                                    "return e.complete && e.naturalWidth > 0 && r.width > 0 && r.height > 0;", image):
        assert time.time() < deadline, "the render never loaded"
        time.sleep(0.1)


def check_page(driver, plot_id: str) -> None:
    assert console_errors(driver) == []
    assert external_requests(driver) == []
    assert is_drawn(element_pixels(driver.find_element("id", plot_id)))


def test_run_report_in_browser(browser, active_model, tmp_path):
    out = write_run_report(active_model, tmp_path / "run.html")
    load(browser, out, "scene3d")
    check_page(browser, "scene3d")
    assert browser.execute_script(COUNT_MARKERS) == len(json.loads((active_model / "cameras.json").read_text()))
    assert browser.execute_script("return document.getElementById('psnr_views')._fullLayout !== undefined")
    render = browser.find_elements("css selector", "img.zoom")[1]
    wait_until_clickable(browser, render)
    render.click()  # enlarge a render
    assert browser.execute_script("return document.getElementById('lightbox').style.display") == "flex"


def test_grid_report_in_browser(browser, active_model, tmp_path):
    setup = tmp_path / "setup1"
    make_grid(setup, active_model)
    out = write_grid_report(setup)
    load(browser, out, "psnr_0")
    check_page(browser, "psnr_0")
    assert len(browser.find_elements("css selector", "a[href$='report.html']")) == 3


def test_recommendation_report_in_browser(browser, active_model, tmp_path):
    record = make_recommendation(tmp_path / "next", active_model, captured=True)
    out = write_recommendation_report(tmp_path / "next")
    load(browser, out, "scene3d")
    check_page(browser, "scene3d")
    assert browser.execute_script(COUNT_MARKERS) == len(record["captured"]) + len(record["candidate_gains"])
