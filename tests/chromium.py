"""Report pages as a reader sees them: opened in headless Chromium (Debian's, which ``make test`` installs)."""

from __future__ import annotations

import re
import shutil
from pathlib import Path
from typing import Any

from playwright.sync_api import sync_playwright

#: Chromium's flags for a closed network, as root, with no screen.
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-quic",
    "--no-first-run",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
]

#: What a raw Python value looks like on a page: a dict or list repr, a float with many digits, nan.
RAW_REPR = re.compile(r"\{'|\['|\bnan\b|\bNone\b|\d\.\d{5,}")

#: What a test checks of a rendered page's layout.
_LAYOUT = """() => ({
    overflow: document.documentElement.scrollWidth - document.documentElement.clientWidth,
    images: [...document.images].map(i => i.complete && i.naturalWidth > 0),
    card: getComputedStyle(document.querySelector('dl.card')).display,
    headings: [...document.querySelectorAll('h2')].map(h => h.textContent),
    alerts: [...document.querySelectorAll('dd.alert')].map(d => d.previousElementSibling.textContent),
})"""


def render(page_path: Path, screenshot: Path, width: int = 1100) -> tuple[str, dict[str, Any]]:
    """Open ``page_path`` in a ``width``-pixel window and save a full-page screenshot.

    Returns the body's text and its layout: ``overflow`` (pixels wider than the window), ``images`` (each
    loaded), ``card`` (the summary card's CSS display), ``headings`` (the h2 texts) and ``alerts`` (the
    labels of the card's alerting rows).
    """
    chromium = shutil.which("chromium")
    assert chromium is not None, "Debian's chromium is missing: make test installs it"
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=chromium, args=CHROMIUM_ARGS)
        try:
            page = browser.new_page(viewport={"width": width, "height": 900})
            page.goto(page_path.as_uri())
            text = page.inner_text("body")
            layout = page.evaluate(_LAYOUT)
            page.screenshot(path=str(screenshot), full_page=True)
        finally:
            browser.close()
    return text, layout
