"""The viser web server and the ``ocslam`` CLI entry point."""

from __future__ import annotations

from typing import Sequence


def main(argv: Sequence[str] | None = None) -> int:
    """Console-script entry: ``ocslam …``."""
    from app.cli import main as cli_main

    return cli_main(argv)
