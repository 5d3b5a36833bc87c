"""Browser helpers of the tests: `browser_or_skip()` (reports.headless.start_chromium, or pytest.skip with the
reason where no browser can be had), console errors, requests, element screenshots."""
from __future__ import annotations

import io

import numpy as np
import pytest

from reports.headless import quit_chromium, start_chromium
from utils.errors import UserError


def browser_or_skip():
    """A headless Chromium driver on a fresh profile, or skip the test with the reason."""
    try:
        return start_chromium()
    except UserError as exc:
        pytest.skip(str(exc))


def close(driver) -> None:
    """Quit the browser and remove its profile."""
    quit_chromium(driver)


def console_errors(driver) -> list[str]:
    """Browser console messages of level SEVERE since the last call."""
    return [e["message"] for e in driver.get_log("browser") if e.get("level") == "SEVERE"]


def external_requests(driver) -> list[str]:
    """URLs of resources the page fetched that are not data: URIs."""
    urls = driver.execute_script("return performance.getEntriesByType('resource').map(e => e.name)")
    return [u for u in urls if not u.startswith("data:")]


def element_pixels(element) -> np.ndarray:
    """A screenshot of one element. [H, W, 3] uint8"""
    from PIL import Image
    return np.asarray(Image.open(io.BytesIO(element.screenshot_as_png)).convert("RGB"))


def is_drawn(pixels: np.ndarray) -> bool:
    """Not a uniform picture: many distinct colours and some spread."""
    return len(np.unique(pixels.reshape(-1, 3), axis=0)) > 20 and float(pixels.std()) > 5.0
