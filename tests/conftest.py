"""Shared fixtures. Tests never need a display, a GPU or the network."""

from __future__ import annotations

import os
from collections.abc import Iterator
from pathlib import Path

import pytest

os.environ.setdefault("OPENCV_LOG_LEVEL", "ERROR")

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def project_root() -> Path:
    return ROOT


@pytest.fixture()
def tmp_out(tmp_path: Path) -> Path:
    return tmp_path


#: module → the browser test that hung there (hit pytest-timeout): the module's later tests share its
#: wedged browser, so they fail at once instead of each waiting out its own timeout (CI's time limit).
_HUNG_BROWSER: dict[str, str] = {}


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[None]:
    outcome = yield
    rep = outcome.get_result()  # type: ignore[attr-defined]
    if rep.failed and item.get_closest_marker("browser") and "Timeout" in str(rep.longrepr):
        _HUNG_BROWSER.setdefault(item.nodeid.split("::")[0], item.name)


def pytest_runtest_setup(item: pytest.Item) -> None:
    hung = _HUNG_BROWSER.get(item.nodeid.split("::")[0]) if item.get_closest_marker("browser") else None
    if hung:
        pytest.fail(f"not run: this module's browser hung in {hung} (pytest-timeout)", pytrace=False)
