"""What one frame proposes (improved and seed modes): a candidate object per bounding area, and the
frame's report for the UI and the tests."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from shapely.geometry import Polygon

from app.ocslam.footprint import Footprint
from app.ocslam.islands import Island
from app.ocslam.se2 import Pose2

FloatArray = NDArray[np.float64]

#: Improved-mode sources of an object's position.
SOURCES = ("lidar_island", "lidar_legs", "ground_plane")


@dataclass(eq=False)
class Candidate:
    """The object proposed by one bounding area in one frame (positions in the object frame)."""

    area_index: int
    label: str
    confidence: float
    source: str
    points: FloatArray  # (K, 2) island points, object frame
    footprint: Footprint | None
    near_range: float  # the area's near range (projection distance from the camera)
    islands: list[int] = field(default_factory=list)
    ray_origin: FloatArray | None = None
    ray_dir: FloatArray | None = None
    ray_weight: float = 0.0
    ground_center: FloatArray | None = None
    apparent_width: float = float("nan")  # the box's width at the island's range (m), NaN if cut by the border
    base_range: float = float("nan")  # the range of the box's bottom edge on the floor from the ray's origin (m), NaN if cut
    support: bool | None = None  # legged classes: one small island on the centre line (a pedestal); None: not legged, or no telling (area_candidate._support)
    legs: bool = False  # legged classes: every chosen island is leg-sized
    open_side: int = 0  # +1/-1: the box is cut by the image's left/right border only
    #: a box cut by one border only: ``(2, 2)`` ``[origin, outward normal]`` (object frame) of its other,
    #: *closed* edge's half-line: the object does not extend beyond it (:meth:`beyond_closed_edge`)
    closed_edge: FloatArray | None = None
    #: the box's image columns ``(x1, x2)`` (camera pixels): two boxes side by side in one frame saw two things
    box_cols: tuple[float, float] | None = None
    #: the whole scan's clusters (``cluster_extents`` labels) its chosen islands belong to; None: not known
    clusters: frozenset[int] | None = None
    track_id: int | None = None
    status: str = "new"  # new | created | updated | collision

    def beyond_closed_edge(self, points: FloatArray, margin_m: float = 0.1) -> float:
        """The fraction of ``(N, 2)`` points (object frame) in front of the camera and more than
        ``margin_m`` beyond the box's closed edge (0 for a box that is not cut on one side only)."""
        if self.closed_edge is None or len(points) == 0:
            return 0.0
        o, n = self.closed_edge
        d = np.asarray(points, dtype=np.float64).reshape(-1, 2) - o
        return float(np.count_nonzero(d @ n > margin_m)) / len(d)

    @property
    def center(self) -> FloatArray:
        if self.footprint is not None:
            return self.footprint.center
        if self.ground_center is not None:
            return self.ground_center
        return self.points.mean(axis=0)


@dataclass(eq=False)
class FrameReport:
    """What one update did, for the UI and for tests.

    ``areas`` are :class:`BoundingArea` (improved) or :class:`SeedProjection` (seed), with polygons in
    the LIDAR frame; ``T_frame_scan`` maps them (and ``points_scan``) into the objects' frame.
    ``islands[k]`` are area ``k``'s islands, ``chosen[k]`` its candidate (``None``: nothing chosen).
    ``rejected`` counts islands/boxes by reason.
    """

    stamp: float
    mode: str
    frame_id: str
    T_frame_scan: Pose2
    points_scan: FloatArray
    camera_bound: Polygon
    areas: list[Any] = field(default_factory=list)
    islands: list[list[Island]] = field(default_factory=list)
    chosen: list[Candidate | None] = field(default_factory=list)
    rejected: dict[str, int] = field(default_factory=dict)
    ground_plane: int = 0
    created: int = 0
    updated: int = 0
    merged: int = 0
    removed: int = 0
    decayed: int = 0
    bearing_only: int = 0  # boxes that gave no object but saw a tracked one (presence frames)
    new_frame: bool = True

    def reject(self, reason: str, n: int = 1) -> None:
        self.rejected[reason] = self.rejected.get(reason, 0) + n

    @property
    def area_polygons(self) -> list[Polygon]:
        return [a.polygon for a in self.areas]

