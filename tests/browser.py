"""Headless Chromium for browser tests (Selenium 4 driving Debian's chromium and chromedriver).

How to import it: ``tests/`` is not a package (no ``__init__.py``), so pytest's default
``prepend`` import mode puts ``tests/`` itself on ``sys.path`` when it collects a test file there
(the same way ``tests/planks.py`` is imported as ``planks``). Test files import this module as::

    from browser import console_errors, start_browser

and define their own fixture, e.g.::

    @pytest.fixture(scope="module")
    def browser() -> Iterator[WebDriver]:
        driver = start_browser()  # skips the test when Chromium is not installed
        yield driver
        driver.quit()

Nothing is ever downloaded: the driver is ``/usr/bin/chromedriver`` given to Selenium's
``Service`` (which skips Selenium Manager) and the browser is ``/usr/bin/chromium``. When either
is missing, or selenium cannot be imported, :func:`start_browser` calls :func:`pytest.skip`.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import TYPE_CHECKING, Any

import pytest

if TYPE_CHECKING:
    from selenium.webdriver.remote.webdriver import WebDriver

CHROMIUM = "/usr/bin/chromium"
CHROMEDRIVER = "/usr/bin/chromedriver"
SKIP_REASON = (
    "headless Chromium not found: install Debian's chromium and chromium-driver "
    "(make test does this as root)"
)
ARGUMENTS = (
    "--headless=new",
    "--no-sandbox",
    "--disable-gpu",
    "--disable-dev-shm-usage",
    "--window-size=1280,900",
)


def _executable(path: str) -> bool:
    """``path`` is an executable file (also found by :func:`shutil.which`)."""
    return os.path.isfile(path) and os.access(path, os.X_OK) and shutil.which(path) is not None


def chromium_available() -> bool:
    """Whether selenium imports and Debian's chromium and chromedriver are installed."""
    try:
        import selenium.webdriver  # noqa: F401
    except ImportError:
        return False
    return _executable(CHROMIUM) and _executable(CHROMEDRIVER)


def start_browser() -> WebDriver:
    """A new headless Chromium driver (1280x900 window, browser console logged at every level).

    The caller quits it (``driver.quit()``). Skips the calling test (:func:`pytest.skip`) when
    Chromium, chromedriver or selenium is missing.
    """
    if not chromium_available():
        pytest.skip(SKIP_REASON)
    from selenium import webdriver
    from selenium.webdriver.chrome.service import Service

    options = webdriver.ChromeOptions()
    options.binary_location = CHROMIUM
    for argument in ARGUMENTS:
        options.add_argument(argument)
    options.set_capability("goog:loggingPrefs", {"browser": "ALL"})
    return webdriver.Chrome(service=Service(CHROMEDRIVER), options=options)


#: The historical name of :func:`start_browser`.
chromium_driver = start_browser


def console_log(driver: WebDriver) -> list[dict[str, Any]]:
    """The browser console entries since the last call (reading the log empties it)."""
    return list(driver.get_log("browser"))


def console_errors(driver: WebDriver) -> list[dict[str, Any]]:
    """The SEVERE browser console entries since the last read of the log (which empties it)."""
    return [entry for entry in console_log(driver) if entry.get("level") == "SEVERE"]


def page_problems(driver: Any) -> list[dict[str, Any]]:
    """Console errors and warnings since the last read."""
    return [e for e in console_log(driver) if e.get("level") in ("SEVERE", "WARNING")]


def wait_for_script(driver: Any) -> None:
    """Until board.js has run (it marks the document)."""
    from selenium.webdriver.support.ui import WebDriverWait

    WebDriverWait(driver, 10).until(
        lambda d: d.execute_script("return document.documentElement.classList.contains('js')")
    )


def order(driver: Any, table: str) -> list[int]:
    """The submission ids of a board table's rows, top to bottom."""
    from selenium.webdriver.common.by import By

    rows = driver.find_elements(By.CSS_SELECTOR, f"#{table} tbody tr[data-submission]")
    return [int(r.get_attribute("data-submission")) for r in rows]


def screenshot(driver: Any, tmp_path: Path, name: str) -> Path:
    """The whole page as ``tmp_path/name`` (copied to $DG16M_SCREENSHOTS when that is set)."""
    height = int(driver.execute_script("return document.documentElement.scrollHeight"))
    driver.set_window_size(1280, max(900, min(height + 120, 6000)))
    path = tmp_path / name
    assert driver.save_screenshot(str(path))
    driver.set_window_size(1280, 900)
    folder = os.environ.get("DG16M_SCREENSHOTS")
    if folder:
        Path(folder).mkdir(parents=True, exist_ok=True)
        shutil.copy2(path, Path(folder) / name)
    return path
