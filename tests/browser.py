"""Headless Chromium for the browser tests: Debian's /usr/bin/chromium driven through /usr/bin/chromedriver by
selenium (nothing is downloaded; scripts/install_chromium.sh installs both). `browser_or_skip()` skips with the
reason where no browser can be had."""
from __future__ import annotations

import io
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import pytest

CHROMIUM = Path(os.environ.get("LITEGS_CHROMIUM", "/usr/bin/chromium"))
CHROMEDRIVER = Path(os.environ.get("LITEGS_CHROMEDRIVER", "/usr/bin/chromedriver"))
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
         "--window-size=1280,1000",
         # no name resolves except localhost: a page that reaches for another host gets an error
         "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE localhost")


def browser_or_skip():
    """A selenium Chrome driver on a fresh profile (`driver.profile_dir`), or pytest.skip with the reason."""
    if not CHROMIUM.is_file() or not CHROMEDRIVER.is_file():
        pytest.skip(f"no headless browser: {CHROMIUM} or {CHROMEDRIVER} missing (bash scripts/install_chromium.sh)")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:
        pytest.skip(f"selenium not importable ({exc}); rerun scripts/setup_env.sh")
    profile = tempfile.mkdtemp(prefix="litegs-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in FLAGS:
        options.add_argument(flag)
    options.add_argument(f"--user-data-dir={profile}")
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(options=options, service=Service(executable_path=str(CHROMEDRIVER)))
    except Exception as exc:  # noqa: BLE001  (selenium raises many kinds when the browser cannot start)
        shutil.rmtree(profile, ignore_errors=True)
        pytest.skip(f"headless Chromium does not start here: {str(exc).splitlines()[0]}")
    driver.profile_dir = profile
    return driver


def close(driver) -> None:
    """Quit the browser and remove its profile."""
    driver.quit()
    shutil.rmtree(driver.profile_dir, ignore_errors=True)


def console_errors(driver) -> list[str]:
    """Browser console messages of level SEVERE since the last call."""
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def external_requests(driver) -> list[str]:
    """URLs of resources the page fetched that are neither data: URIs nor the page itself."""
    urls = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    return [u for u in urls if not u.startswith("data:")]


def element_pixels(element) -> np.ndarray:
    """A screenshot of one element. [H, W, 3] uint8"""
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(element.screenshot_as_png)).convert("RGB"))


def is_drawn(pixels: np.ndarray) -> bool:
    """Not a uniform picture: many distinct colours and some spread."""
    return len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20 and float(pixels.std()) > 5.0
