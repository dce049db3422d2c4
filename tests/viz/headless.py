"""What the viewer's browser tests share: headless Chromium's settings, a tab that may fetch only
the viewer's own address, and reading the height ramp's colours off a screenshot."""

from __future__ import annotations

import os
import shutil
import time

import numpy as np

from occmap.octree.views import height_colors

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
ARGS = ["--no-sandbox", "--disable-gpu", "--use-angle=swiftshader", "--enable-unsafe-swiftshader",
        "--disable-background-networking", "--disable-component-update", "--disable-sync", "--no-first-run"]
VIEW = {"width": 800, "height": 600}
PALETTE = height_colors(np.linspace(0.0, 1.0, 256)).astype(np.int64)


def ramp_pixels(png: bytes) -> int:
    """Pixels of the left half of a screenshot (the panel is on the right) that lie on the height
    ramp: within 12 of one of its colours per channel, and coloured (not a grey of the page)."""
    from io import BytesIO

    from PIL import Image

    rgb = np.asarray(Image.open(BytesIO(png)).convert("RGB"))[:, : VIEW["width"] // 2].reshape(-1, 3).astype(np.int64)
    rgb = rgb[rgb.max(axis=1) - rgb.min(axis=1) > 35]
    near = np.zeros(len(rgb), bool)
    for c in PALETTE[::4]:
        near |= np.all(np.abs(rgb - c) <= 12, axis=1)
    return int(near.sum())


class Page:
    """A browser tab on a viewer at ``url``, or on a page of its own ``content`` (HTML), that may
    fetch nothing but the viewer's own address."""

    def __init__(self, browser, url: str | None = None, content: str | None = None):
        self.page = browser.new_page(viewport=VIEW)
        self.refused: list[str] = []
        self.page.route("**/*", self._route)
        self.origin = url.rstrip("/") if url else "about:"
        if url:
            self.page.goto(url)
        else:
            self.page.set_content(content)

    def _route(self, route):
        url = route.request.url
        if url.startswith(self.origin) or url.startswith(("data:", "blob:")):
            route.continue_()
        else:
            self.refused.append(url)
            route.abort()

    def drawn(self, at_least: int = 2000, timeout: float = 20.0) -> tuple[bytes, int]:
        """A screenshot once the map is drawn (ramp pixels ≥ ``at_least``), and its ramp pixels."""
        end = time.monotonic() + timeout
        while True:
            png = self.page.screenshot()
            n = ramp_pixels(png)
            if n >= at_least or time.monotonic() > end:
                return png, n
            self.page.wait_for_timeout(500)

    def open_in_panel(self, path) -> None:
        """Type ``path`` into the panel's "Open path" field and press "Open", as a person would."""
        field = self.page.locator('xpath=//label[text()="Open path"]/ancestor::div'
                                  '[contains(@class, "mantine-Flex-root")][1]//input')
        field.fill(str(path))
        self.page.get_by_role("button", name="Open").click()


def keep(name: str, png: bytes) -> None:
    """Save a screenshot in ``$OCCMAP_SCREENSHOTS`` when set, to look at."""
    folder = os.environ.get("OCCMAP_SCREENSHOTS")
    if folder:
        with open(os.path.join(folder, f"viewer-{name}.png"), "wb") as f:
            f.write(png)


def image(png: bytes):
    from io import BytesIO

    from PIL import Image

    return Image.open(BytesIO(png)).convert("RGB")
