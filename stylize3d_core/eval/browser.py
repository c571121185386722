"""A web page of ``export/web_page.py`` opened in headless Chromium (Selenium + chromedriver), for tests and
benchmarks: load time, screenshots of given poses, a mouse drag, orbit frame rate.

Chromium runs with software WebGL (SwiftShader through ANGLE), offline (the page is a ``file://`` URL and
needs nothing else). The page's ``window.stylize3d`` hooks (``web_page.html``) set poses and report frames.
"""

from __future__ import annotations

import base64
import io
import shutil
import time
from pathlib import Path
from typing import Optional, Tuple

import numpy as np
from PIL import Image
from selenium import webdriver
from selenium.webdriver.chrome.service import Service
from selenium.webdriver.common.action_chains import ActionChains
from selenium.webdriver.common.by import By

from ..errors import InputError

CHROMIUM_FLAGS = ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--use-angle=swiftshader",
                  "--enable-unsafe-swiftshader", "--disable-gpu-vsync", "--hide-scrollbars", "--mute-audio")


def find_chromium() -> Optional[Tuple[str, str]]:
    """``(chromium, chromedriver)`` paths of the Debian packages (or on PATH), None when either is missing."""
    browser = shutil.which("chromium") or shutil.which("chromium-browser")
    driver = shutil.which("chromedriver")
    return (browser, driver) if browser and driver else None


class PageBrowser:
    """One headless Chromium showing pages at a fixed viewport of ``size`` (W, H) CSS pixels (device ratio 1)."""

    def __init__(self, size: Tuple[int, int] = (1280, 720)) -> None:
        found = find_chromium()
        if found is None:
            raise InputError("chromium", "not found; install the Debian packages chromium and chromium-driver")
        options = webdriver.ChromeOptions()
        options.binary_location = found[0]
        for flag in CHROMIUM_FLAGS:
            options.add_argument(flag)
        self.driver = webdriver.Chrome(options=options, service=Service(found[1]))
        self.set_size(size)

    def set_size(self, size: Tuple[int, int]) -> None:
        w, h = (int(v) for v in size)
        self.driver.execute_cdp_cmd("Emulation.setDeviceMetricsOverride",
                                    {"width": w, "height": h, "deviceScaleFactor": 1, "mobile": False})

    def open(self, page: Path, timeout: float = 60.0) -> float:
        """Open ``page``; seconds from the request to the first frame drawn (``InputError`` if it fails)."""
        t0 = time.perf_counter()
        self.driver.get(Path(page).resolve().as_uri())
        while True:
            state = self.driver.execute_script("const s = window.stylize3d; return s && [s.ready, s.error];")
            if state and state[1]:
                raise InputError(page, f"the page failed: {state[1]}")
            if state and state[0]:
                return time.perf_counter() - t0
            if time.perf_counter() - t0 > timeout:
                raise InputError(page, f"no first frame within {timeout:g} s")
            time.sleep(0.01)

    def script(self, js: str, *args):
        return self.driver.execute_script(js, *args)

    def set_pose(self, yaw: float = 0.0, pitch: float = 0.0, pan_x: float = 0.0, pan_y: float = 0.0,
                 dolly: float = 0.0) -> dict:
        """Set the page's camera (clamped to its range, as a drag would) and draw; returns the pose it took."""
        return self.script("stylize3d.setPose({yaw: arguments[0], pitch: arguments[1], panX: arguments[2], "
                           "panY: arguments[3], dolly: arguments[4]}); stylize3d.render(); return stylize3d.getPose();",
                           yaw, pitch, pan_x, pan_y, dolly)

    def set_background(self, rgb: Tuple[float, float, float]) -> None:
        self.script("stylize3d.setBackground(arguments[0]); stylize3d.render();", list(rgb))

    def screenshot(self) -> np.ndarray:
        """(H, W, 3) uint8 screenshot of the viewport (buttons included)."""
        png = self.driver.get_screenshot_as_png()
        return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"))

    def canvas(self) -> np.ndarray:
        """(H, W, 3) uint8 of the canvas alone (its drawing buffer, without the buttons)."""
        url = self.script("stylize3d.render(); return document.getElementById('view').toDataURL('image/png');")
        return np.asarray(Image.open(io.BytesIO(base64.b64decode(url.split(",", 1)[1]))).convert("RGB"))

    def drag(self, dx: int, dy: int, steps: int = 10) -> None:
        """A left-button mouse drag of ``(dx, dy)`` CSS pixels from the middle of the canvas."""
        canvas = self.driver.find_element(By.ID, "view")
        chain = ActionChains(self.driver).move_to_element(canvas).click_and_hold()
        for _ in range(steps):
            chain = chain.move_by_offset(dx // steps, dy // steps)
        chain.release().perform()
        time.sleep(0.1)  # the page draws on its next animation frame

    def orbit_fps(self, seconds: float = 3.0) -> float:
        """Frames the page shows per second while its camera sweeps the range (``stylize3d.orbitFps``)."""
        return float(self.script("return await stylize3d.orbitFps(arguments[0]);", seconds))

    def close(self) -> None:
        self.driver.quit()

    def __enter__(self) -> "PageBrowser":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
