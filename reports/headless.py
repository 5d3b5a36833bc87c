"""Headless Chromium driven by selenium through Debian's chromedriver (nothing downloaded; scripts/
install_chromium.sh installs both): used by the browser tests and scripts/report_screenshots.py."""
from __future__ import annotations

import os
import shutil
import tempfile
from pathlib import Path

from utils.errors import UserError

CHROMIUM = Path(os.environ.get("LITEGS_CHROMIUM", "/usr/bin/chromium"))
CHROMEDRIVER = Path(os.environ.get("LITEGS_CHROMEDRIVER", "/usr/bin/chromedriver"))
FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--disable-dev-shm-usage", "--enable-unsafe-swiftshader", "--use-angle=swiftshader",
         # no name resolves except localhost: a page that reaches for another host gets an error
         "--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE localhost")


def start_chromium(width: int = 1280, height: int = 1000):
    """A selenium Chrome driver on a fresh profile (`driver.profile_dir`; `quit_chromium` removes it).

    Raises:
        UserError: no browser or driver installed, selenium missing, or the browser does not start.
    """
    if not CHROMIUM.is_file() or not CHROMEDRIVER.is_file():
        raise UserError(f"no headless browser: {CHROMIUM} or {CHROMEDRIVER} missing (bash scripts/install_chromium.sh)")
    try:
        from selenium import webdriver
        from selenium.webdriver.chrome.service import Service
    except ImportError as exc:
        raise UserError(f"selenium not importable ({exc}); rerun scripts/setup_env.sh") from None
    profile = tempfile.mkdtemp(prefix="litegs-chromium-")
    options = webdriver.ChromeOptions()
    options.binary_location = str(CHROMIUM)
    for flag in FLAGS + (f"--window-size={width},{height}", f"--user-data-dir={profile}"):
        options.add_argument(flag)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    try:
        driver = webdriver.Chrome(options=options, service=Service(executable_path=str(CHROMEDRIVER)))
    except Exception as exc:  # noqa: BLE001  (selenium raises many kinds when the browser cannot start)
        shutil.rmtree(profile, ignore_errors=True)
        raise UserError(f"headless Chromium does not start here: {str(exc).splitlines()[0]}") from None
    driver.profile_dir = profile
    return driver


def quit_chromium(driver) -> None:
    """Quit the browser and remove its profile."""
    driver.quit()
    shutil.rmtree(driver.profile_dir, ignore_errors=True)
