"""A headless browser for the tests of the report pages (Snakemake's report.html and the summary pages)."""
from __future__ import annotations

import shutil
import subprocess
from collections.abc import Callable
from pathlib import Path

import pytest

#: executable names of a Chromium-based browser, in the order they are looked for (Debian package: chromium)
BROWSERS = ("chromium", "chromium-browser", "google-chrome", "chrome")


@pytest.fixture(scope="session")
def headless() -> Callable[..., subprocess.CompletedProcess]:
    """``headless(page, *flags)``: the page opened in a headless Chromium (no sandbox, no GPU, no network services,
    a profile of its own next to the page), console messages on stderr; skips when no such browser is installed."""
    found = next((path for path in map(shutil.which, BROWSERS) if path), None)
    if found is None:
        pytest.skip(f"no headless browser: none of {', '.join(BROWSERS)} is installed (Debian package chromium)")

    def run(page: Path, *flags: str) -> subprocess.CompletedProcess:
        assert page.is_file(), page
        profile = page.parent / f".chromium-profile-{page.stem}"
        done = subprocess.run([found, "--headless", "--no-sandbox", "--disable-gpu", "--disable-dev-shm-usage",
                               "--disable-background-networking", "--no-first-run", f"--user-data-dir={profile}",
                               "--enable-logging=stderr", "--v=0", "--virtual-time-budget=20000", *flags,
                               page.as_uri()], capture_output=True, text=True, timeout=180)
        assert done.returncode == 0, done.stderr[-2000:]
        return done

    return run
