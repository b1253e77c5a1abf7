"""What a GUI client may name and what it is told: paths confined to one root, one-line notifications.

Free of viser and websockets, so the headless commands that import the server's module stay light
(:mod:`app.ui.security` re-exports these beside the network hardening).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any


class PathRefused(ValueError):
    """A path named in the GUI is outside the directories the GUI may use."""


def confine_path(text: Any, root: Path, *, what: str = "path", must_exist: bool = False) -> Path:
    """The real path ``text`` names inside ``root``, or :class:`PathRefused` (one line).

    Relative paths are relative to ``root``; a leading component equal to the root's own name is
    accepted (``runs/session`` with root ``…/runs``). Absolute paths must lie inside ``root``.
    No ``..``, no ``~``, no control characters; symlinks are resolved and must stay inside; the root
    itself is not a valid target.
    """
    if not isinstance(text, str) or not text.strip():
        raise PathRefused(f"{what}: no path given")
    text = text.strip()
    if len(text) > 512 or any(ord(c) < 32 or ord(c) == 127 for c in text):
        raise PathRefused(f"{what}: not a usable path")
    p = Path(text)
    if ".." in p.parts:
        raise PathRefused(f"{what}: '..' is not allowed")
    if text.startswith("~"):
        raise PathRefused(f"{what}: '~' is not allowed")
    root_real = Path(os.path.realpath(root))
    if not p.is_absolute():
        parts = p.parts
        if parts and parts[0] == root.name:
            parts = parts[1:]
        p = root_real.joinpath(*parts) if parts else root_real
    real = Path(os.path.realpath(p))
    shown = root.name + "/"
    if real == root_real or not real.is_relative_to(root_real):
        raise PathRefused(f"{what}: must be inside {shown} (the only directory the web UI may use)")
    if must_exist and not real.exists():
        rel = real.relative_to(root_real)
        raise PathRefused(f"{what}: {shown}{rel} does not exist")
    return real


def safe_message(message: Any, *, files: tuple[Path, ...] = (), limit: int = 200) -> str:
    """One line for a notification: the first line of ``message``, at most ``limit`` characters, and
    never a quote of any of ``files`` (a message containing any line of them is replaced)."""
    text = str(message).strip()
    line = text.splitlines()[0].strip() if text else ""
    for f in files:
        try:
            with open(f, "rb") as fh:
                content = fh.read(1 << 20).decode("utf-8", "replace")
        except OSError:
            continue
        if any(len(s.strip()) >= 8 and s.strip() in text for s in content.splitlines()):
            return "the file is not valid (details in the server log)"
    if len(line) > limit:
        line = line[: limit - 1] + "…"
    return line
