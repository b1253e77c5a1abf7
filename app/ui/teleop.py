"""Keyboard and button teleop with teleop_twist_keyboard's bindings and a deadman timer.

viser hotkeys fire on keydown (and on every auto-repeat) but never on key-up, so a key sets a
velocity that lasts ``deadman_s`` after the last keydown; holding the key keeps it alive through the
OS auto-repeat. Hold-to-drive buttons refresh the same timer at 10 Hz. ``k`` or space stops at once.

This module holds no viser objects: :class:`Teleop` is plain, thread-safe state the loop reads.

    u  i  o        i forward, , back, j/l turn in place,
    j  k  l        u/o forward arcs, m/. backward arcs,
    m  ,  .        k or space: stop
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable

from app.ocslam.messages import Twist

#: key → (linear sign, angular sign), exactly teleop_twist_keyboard's moveBindings.
MOVE_BINDINGS: dict[str, tuple[int, int]] = {
    "i": (1, 0),
    "o": (1, -1),
    "j": (0, 1),
    "l": (0, -1),
    "u": (1, 1),
    ",": (-1, 0),
    ".": (-1, 1),
    "m": (-1, -1),
}
STOP_KEYS = ("k", "space")


class Teleop:
    """Thread-safe teleop state: the last command and when it expires."""

    def __init__(
        self,
        linear_mps: float = 0.15,
        angular_rps: float = 1.0,
        deadman_s: float = 0.6,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.linear_mps = linear_mps
        self.angular_rps = angular_rps
        self.deadman_s = deadman_s
        self._clock = clock
        self._lock = threading.Lock()
        self._twist = Twist()
        self._expires = 0.0
        self.last_key: str | None = None
        self.presses = 0

    def press(self, key: str) -> Twist:
        """A keydown (or auto-repeat) of ``key``; unknown keys are ignored. Returns the new command."""
        key = key.lower()
        with self._lock:
            if key in STOP_KEYS:
                self._twist, self._expires = Twist(), 0.0
            elif key in MOVE_BINDINGS:
                lin, ang = MOVE_BINDINGS[key]
                self._twist = Twist(lin * self.linear_mps, ang * self.angular_rps)
                self._expires = self._clock() + self.deadman_s
            else:
                return self._twist
            self.last_key = key
            self.presses += 1
            return self._twist

    def stop(self) -> None:
        self.press("k")

    @property
    def active(self) -> bool:
        with self._lock:
            return self._clock() < self._expires

    def command(self) -> Twist:
        """The current command: the last key's twist until the deadman expires, then zero."""
        with self._lock:
            if self._clock() < self._expires:
                return self._twist
            return Twist()
