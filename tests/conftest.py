"""Shared fixtures. Tests never need a display, a GPU or the network."""

from __future__ import annotations

import os
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
