"""What the GUI may ask of the app: :class:`GuiCommands`, the one interface between the panels and the server.

The panels (``app.ui.panels``) are built with an object that has these members; the server
(``app.server.OcslamApp``) is one. The panels never import the server: they issue these commands and
read the few live values below, and the server decides what a command does (confine a path, queue work
for the loop thread, notify the client). A test or another front end can drive the panels with any
object of this shape.

Every command is called on viser's thread pool, never on the loop thread: it returns at once, having
queued work for the loop (:meth:`GuiCommands.submit`) or flipped a flag. ``client`` is the viser client
whose click it was: failures and results are notified to it (``None``: to every client). Paths are the
text the user typed; the server confines them to its runs directory and refuses anything else with a
notification, so a command never raises for bad input.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any, Protocol

if TYPE_CHECKING:
    from app.config import Config
    from app.pipeline import Pipeline


class GuiCommands(Protocol):
    """The commands the GUI may issue, and the live state it shows (read only)."""

    # -- what the panels show ---------------------------------------------------------------------
    @property
    def cfg(self) -> Config:
        """The running config (the Tune tab's controls are bound to it; change it with :meth:`set_config`)."""
        ...

    @property
    def pipeline(self) -> Pipeline:
        """The running pipeline, to read its state (replaced when a world loads: read it anew each time)."""
        ...

    @property
    def worlds_roots(self) -> tuple[Path, ...]:
        """The directories whose ``*.yaml`` worlds the World dropdown offers."""
        ...

    @property
    def paused(self) -> bool:
        """Whether the simulation is paused."""
        ...

    @property
    def real_time_factor(self) -> float:
        """Sim seconds per wall second over the last second."""
        ...

    # -- driving and the simulation ---------------------------------------------------------------
    def teleop_key(self, key: str) -> None:
        """A teleop_twist_keyboard key (``i , j l u o m .``; ``k`` or ``space`` stops) pressed or held."""
        ...

    def toggle_pause(self) -> None:
        """Pause the simulation, or resume it."""
        ...

    def single_step(self) -> None:
        """Pause and advance one LIDAR period."""
        ...

    def reset_world(self) -> None:
        """Restart the world and every estimator (the map is lost)."""
        ...

    def load_world(self, choice: str, *, client: Any = None) -> None:
        """Replace the running world with the World dropdown's ``choice`` (an option it offered)."""
        ...

    def submit(self, fn: Callable[[Pipeline], Any], *, client: Any = None) -> None:
        """Run ``fn(pipeline)`` on the loop thread before its next step (autonomy: follow a route, explore,
        stop); an exception is notified to ``client``."""
        ...

    # -- the 3D view ------------------------------------------------------------------------------
    def top_down_view(self, client: Any = None) -> None:
        """Look straight down on the whole world."""
        ...

    def focus_object(self, object_id: int, client: Any = None) -> None:
        """Point the camera at the tracked object ``object_id`` (nothing if it is gone)."""
        ...

    # -- the config -------------------------------------------------------------------------------
    def set_config(self, path: str, value: Any, *, client: Any = None) -> None:
        """Set the live config field ``path`` (``"section.key"``) to ``value`` on the loop thread
        (a refused value is notified)."""
        ...

    def save_config(self, path: str, *, client: Any = None) -> None:
        """Write the config as YAML to ``path`` (under the runs directory, ending in ``.yaml``)."""
        ...

    def reset_config(self, *, client: Any = None) -> None:
        """Restore every live config field to its default."""
        ...

    # -- sessions, recordings, maps ---------------------------------------------------------------
    def save_session(self, path: str, *, client: Any = None) -> None:
        """Write a run directory (config, map, objects, trajectories, state, scene recording) at ``path``."""
        ...

    def load_session(self, path: str, *, client: Any = None) -> None:
        """Restore the map, objects and pose graph from the run directory ``path``."""
        ...

    def start_recording(self, path: str, *, client: Any = None) -> None:
        """Start recording a rosbag2 MCAP bag into the new folder ``path`` (never overwritten)."""
        ...

    def stop_recording(self, *, client: Any = None) -> None:
        """Finish the bag being recorded (nothing if none is)."""
        ...

    def export_map(self, path: str, *, client: Any = None) -> None:
        """Write the SLAM grid as map_server / Nav2 YAML + PGM at ``path`` (ending in ``.yaml``)."""
        ...
