"""A headless Chromium for page tests: find it, and read a page as it renders it (scripts run)."""

from __future__ import annotations

import shutil
import socket
import subprocess
import tempfile
import time
import urllib.request

CHROMIUM_FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
                  "--disable-background-networking", "--disable-component-update", "--disable-sync")


def chromium() -> str | None:
    return next((path for name in ("chromium", "chromium-browser", "google-chrome")
                 if (path := shutil.which(name))), None)


def free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


def dom(url: str, *, timeout_s: float = 60) -> str:
    """The page at `url` as headless Chromium renders it, in a fresh profile."""
    browser = chromium()
    assert browser is not None, "no Chromium on this machine"
    with tempfile.TemporaryDirectory(prefix="chromium-") as profile:
        result = subprocess.run([browser, *CHROMIUM_FLAGS, f"--user-data-dir={profile}", "--dump-dom", url],
                                capture_output=True, text=True, timeout=timeout_s)
    assert result.returncode == 0, result.stderr[-2000:]
    return result.stdout


def wait_for_http(url: str, *, timeout_s: float, process: subprocess.Popen | None = None) -> None:
    """Return once `url` answers; AssertionError naming it after `timeout_s` or if `process` exits."""
    deadline = time.monotonic() + timeout_s
    while True:
        try:
            urllib.request.urlopen(url, timeout=2)
            return
        except OSError:
            if time.monotonic() > deadline or (process is not None and process.poll() is not None):
                raise AssertionError(f"{url} did not answer within {timeout_s:g} s") from None
            time.sleep(0.2)  # a poll period, inside the bounded wait
