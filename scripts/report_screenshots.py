"""Screenshots of reports (or a running view.py) in headless Chromium, as JPEGs small enough for docs/images.

    python scripts/report_screenshots.py docs/images run_report=output/lego/report.html \
        grid_report=OUT/setup1/report.html viewer=http://localhost:8080 --width 1280 --height 900

Each NAME=PAGE (a file or an http URL) becomes NAME.jpg (at most --max_kb KB, shrunk until it fits).
"""
from __future__ import annotations

import argparse
import io
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from reports.headless import quit_chromium, start_chromium  # noqa: E402
from utils.errors import UserError, run_cli  # noqa: E402


def small_jpeg(png: bytes, max_kb: int) -> bytes:
    """The screenshot as a JPEG of at most `max_kb` KB (quality 85, then smaller sizes)."""
    from PIL import Image

    im = Image.open(io.BytesIO(png)).convert("RGB")
    while True:
        buf = io.BytesIO()
        im.save(buf, "JPEG", quality=85, optimize=True)
        if buf.tell() <= max_kb * 1024 or im.width < 300:
            return buf.getvalue()
        im = im.resize((int(im.width * 0.85), int(im.height * 0.85)), Image.LANCZOS)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("out", help="folder for the JPEGs")
    parser.add_argument("pages", nargs="+", help="NAME=PAGE: a report file or an http:// URL")
    parser.add_argument("--width", type=int, default=1280)
    parser.add_argument("--height", type=int, default=900)
    parser.add_argument("--wait", type=float, default=8.0, help="seconds to let the page draw (default 8)")
    parser.add_argument("--max_kb", type=int, default=150)
    args = parser.parse_args()
    pages = []
    for item in args.pages:
        name, sep, page = item.partition("=")
        if not sep or not name:
            raise UserError(f"expected NAME=PAGE, got {item!r}")
        if not page.startswith("http") and not Path(page).is_file():
            raise UserError(f"{page} is not a file or an http URL")
        pages.append((name, page if page.startswith("http") else Path(page).resolve().as_uri()))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    driver = start_chromium(args.width, args.height)
    try:
        for name, url in pages:
            driver.get(url)
            time.sleep(args.wait)
            data = small_jpeg(driver.get_screenshot_as_png(), args.max_kb)
            (out / f"{name}.jpg").write_bytes(data)
            print(f"{out / (name + '.jpg')}: {len(data) / 1024:.0f} KB")
    finally:
        quit_chromium(driver)


if __name__ == "__main__":
    run_cli(main)
