"""A person's phone, as a program: Chromium (driven by Playwright) opens a
game page's link, taps START, stands at one place by emulated geolocation
until the game is over, and prints what the page showed, as JSON.

Run as ``python -m tests.support.phone_page URL LAT LON SECONDS``, so that
another machine (a network namespace) can run it.
"""

from __future__ import annotations

import json
import sys
import time

from tests.support.system import CHROMIUM


def play(url: str, lat: float, lon: float, seconds: float) -> dict:
    from playwright import sync_api

    found: dict = {}
    with sync_api.sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=["--no-sandbox"])
        context = browser.new_context(
            geolocation={"latitude": lat, "longitude": lon, "accuracy": 4.0},
            permissions=["geolocation"],
            ignore_https_errors=True,  # the certificate the bridge made for this session
            viewport={"width": 390, "height": 760},
            is_mobile=True,
            has_touch=True,
        )
        page = context.new_page()
        found["status"] = page.goto(url).status
        page.click("#go")
        end = time.monotonic() + seconds
        while time.monotonic() < end and page.inner_text("#phase") != "game over":
            context.set_geolocation({"latitude": lat, "longitude": lon, "accuracy": 4.0})
            time.sleep(0.5)
        found["phase"] = page.inner_text("#phase")
        found["shown"] = page.inner_text("body")
        browser.close()
    return found


if __name__ == "__main__":
    url, lat, lon, seconds = sys.argv[1], float(sys.argv[2]), float(sys.argv[3]), float(sys.argv[4])
    print(json.dumps(play(url, lat, lon, seconds)))
