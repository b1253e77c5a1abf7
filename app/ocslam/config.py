"""Typed configuration sections of the algorithm core.

Each section is a dataclass; each field is declared with :func:`~app.ocslam.params.param`, which records its
range, step, unit, help text and whether it may change while the loop runs (``live``). The same metadata
validates YAML files and CLI overrides and builds the GUI sliders, so the three can never disagree.

The root object that gathers these with the simulator's and UI's sections is ``app.config.Config``.
"""

from __future__ import annotations

from dataclasses import dataclass

from app.ocslam.messages import CLASS_NAMES
from app.ocslam.params import ConfigError, coerce_value, param, validate_section

__all__ = [
    "ConfigError",
    "ConsciousnessConfig",
    "DetectorConfig",
    "RobotConfig",
    "SlamConfig",
    "coerce_value",
    "param",
    "validate_section",
]


# ----------------------------------------------------------------------------------------------
# Robot
# ----------------------------------------------------------------------------------------------


@dataclass
class RobotConfig:
    """TurtleBot3 Burger geometry and limits (public dimensions)."""

    wheel_radius_m: float = param(0.033, min=0.01, max=0.2, unit="m", help="wheel radius r")
    wheel_separation_m: float = param(0.160, min=0.05, max=1.0, unit="m", help="distance l between the wheels")
    max_linear_mps: float = param(0.22, min=0.01, max=2.0, step=0.01, unit="m/s", help="linear speed limit", live=True)
    max_angular_rps: float = param(2.84, min=0.1, max=10.0, step=0.01, unit="rad/s", help="yaw rate limit", live=True)
    footprint_radius_m: float = param(0.105, min=0.05, max=1.0, unit="m", help="circumscribed radius (path planning)")
    odometry_mode: str = param(
        "correct",
        choices=("correct", "seed"),
        help="'correct': l/2 inverse kinematics with l=0.160; 'seed': the original's ω·l with l=0.178",
    )


# ----------------------------------------------------------------------------------------------
# SLAM
# ----------------------------------------------------------------------------------------------


@dataclass
class SlamConfig:
    """Occupancy-grid graph SLAM (correlative scan matching, pose graph, loop closure)."""

    enabled: bool = param(True, help="run SLAM (off: map = odom)")
    resolution_m: float = param(0.05, min=0.01, max=0.5, unit="m", help="occupancy grid cell size")
    max_range_m: float = param(20.0, min=0.5, max=100.0, unit="m", help="returns beyond this are not used")
    free_clear_range_m: float = param(
        3.0, min=0.0, max=100.0, unit="m", help="inf/max-range beams clear free space up to this distance"
    )
    free_clear_dropout_window_deg: float = param(
        5.0, min=0.0, max=45.0, unit="deg",
        help="a no-return beam with returns within ±this clears only up to just before the nearest of them (a dropout, not open space; 0: off)",
    )
    log_odds_hit: float = param(0.85, min=0.01, max=5.0, help="log-odds added to a hit cell")
    log_odds_miss: float = param(-0.4, min=-5.0, max=-0.01, help="log-odds added to a traversed cell")
    log_odds_clamp: float = param(5.0, min=0.5, max=50.0, help="log-odds are clamped to ±this")
    keyframe_distance_m: float = param(
        0.2, min=0.0, max=5.0, step=0.05, unit="m", help="new keyframe after this travel", live=True
    )
    keyframe_heading_rad: float = param(
        0.25, min=0.0, max=3.15, step=0.05, unit="rad", help="new keyframe after this rotation", live=True
    )
    min_points: int = param(20, min=3, max=10000, help="scans with fewer returns are not matched (odometry only)")
    match_resolution_m: float = param(0.05, min=0.01, max=0.5, unit="m", help="scan-matching grid cell size")
    match_sigma_m: float = param(0.07, min=0.005, max=1.0, unit="m", help="likelihood field width (correlative score)")
    match_search_xy_m: float = param(0.3, min=0.0, max=2.0, unit="m", help="scan-match window half-size (xy)")
    match_search_yaw_rad: float = param(0.35, min=0.0, max=3.15, unit="rad", help="scan-match window half-size (yaw)")
    match_yaw_step_rad: float = param(0.0175, min=0.001, max=0.2, unit="rad", help="correlative search yaw step")
    match_min_score: float = param(0.25, min=0.0, max=1.0, help="below this the scan keeps the odometry prediction")
    match_direct_min_inliers: float = param(
        0.8, min=0.0, max=1.0, help="<1: skip the correlative search if a refinement from the prediction fits this well"
    )
    match_point_weight: float = param(
        0.1, min=0.0, max=10.0, help="point-to-point weight where the map has no clean line (corners, sparse points)"
    )
    match_robust_m: float = param(0.03, min=0.001, max=1.0, unit="m", help="Cauchy scale of the refinement")
    prior_sigma_xy_m: float = param(0.1, min=0.001, max=10.0, unit="m", help="odometry prior σ per scan (xy)")
    prior_sigma_yaw_rad: float = param(
        0.3, min=0.001, max=10.0, unit="rad", help="odometry prior σ per scan (yaw; weak: the scan decides the heading)"
    )
    local_map_keyframes: int = param(30, min=1, max=1000, help="keyframes in the local map scans are matched against")
    local_map_half_size_m: float = param(12.0, min=1.0, max=200.0, unit="m", help="local map crop around the robot")
    edge_sigma_xy_m: float = param(0.02, min=0.0001, max=10.0, unit="m", help="σ of a sequential edge (xy)")
    edge_sigma_yaw_rad: float = param(0.005, min=0.0001, max=10.0, unit="rad", help="σ of a sequential edge (yaw)")
    loop_closure: bool = param(True, help="search for and add loop closures", live=True)
    loop_search_radius_m: float = param(4.0, min=0.0, max=50.0, unit="m", help="loop candidates within this distance")
    loop_window_xy_m: float = param(1.5, min=0.05, max=20.0, unit="m", help="loop search window half-size (xy)")
    loop_window_yaw_rad: float = param(0.5, min=0.0, max=3.15, unit="rad", help="loop search window half-size (yaw)")
    loop_window_growth: float = param(
        0.02, min=0.0, max=1.0, help="loop window growth per metre travelled since the last closure (yaw: /5 rad)"
    )
    loop_window_max_xy_m: float = param(5.0, min=0.05, max=50.0, unit="m", help="loop search window cap (xy)")
    loop_window_max_yaw_rad: float = param(1.0, min=0.0, max=3.15, unit="rad", help="loop search window cap (yaw)")
    loop_min_score: float = param(0.45, min=0.0, max=1.0, step=0.01, help="loop closure acceptance score", live=True)
    loop_min_inliers: float = param(0.6, min=0.0, max=1.0, help="loop closure: inlier fraction after refinement")
    loop_min_constraint: float = param(
        0.0, min=0.0, max=1.0, help="loop closure: weakest/strongest translational constraint (rejects corridors)"
    )
    loop_sigma_xy_m: float = param(0.05, min=0.0001, max=10.0, unit="m", help="σ of a loop edge (xy)")
    loop_sigma_yaw_rad: float = param(0.02, min=0.0001, max=10.0, unit="rad", help="σ of a loop edge (yaw)")
    loop_robust_scale: float = param(3.0, min=0.1, max=100.0, help="Cauchy kernel scale of loop edges (whitened)")
    submap_keyframes: int = param(30, min=2, max=1000, help="keyframes per loop-closure submap")
    loop_query_keyframes: int = param(5, min=1, max=100, help="keyframes in a loop query cloud")
    loop_query_range_m: float = param(10.0, min=0.5, max=100.0, unit="m", help="loop query points within this range")
    loop_query_max_points: int = param(600, min=10, max=100000, help="loop query cloud size cap")
    loop_min_gap_keyframes: int = param(10, min=0, max=100000, help="extra keyframes between the local map and loop submaps")
    loop_max_candidates: int = param(3, min=1, max=100, help="submaps searched per keyframe")
    match_info_point_sigma_m: float = param(
        0.1, min=0.001, max=10.0, unit="m", help="effective σ per scan point for the matcher's information (edges)"
    )
    match_info_floor: float = param(
        1e-4, min=1e-9, max=1.0, help="edge information floor, relative to the ceiling σs (degenerate directions)"
    )
    odom_sigma_xy_m: float = param(0.05, min=0.0001, max=10.0, unit="m", help="odometry σ per keyframe step (xy, constant part)")
    odom_sigma_xy_per_m: float = param(0.5, min=0.0, max=10.0, help="odometry σ growth per metre of the step (xy)")
    odom_sigma_yaw_rad: float = param(0.02, min=0.0001, max=10.0, unit="rad", help="odometry σ per keyframe step (yaw)")
    odom_sigma_yaw_per_rad: float = param(0.2, min=0.0, max=10.0, help="odometry yaw σ growth per radian turned")
    loop_cluster_min: int = param(2, min=1, max=100, help="loop closures accepted only in mutually consistent groups this large")
    loop_confirm_keyframes: int = param(25, min=1, max=100000, help="a loop candidate not confirmed within this many keyframes is rejected")
    loop_pair_chi2: float = param(25.0, min=0.1, max=1e6, help="pairwise consistency gate of two loop candidates (χ², 3 dof)")
    loop_gate_chi2: float = param(200.0, min=0.1, max=1e9, help="loop correction vs the graph's uncertainty over the loop (χ², 3 dof)")
    loop_residual_chi2: float = param(100.0, min=0.1, max=1e9, help="a loop edge with a larger χ² after optimisation is rejected")
    loop_ambiguity_ratio: float = param(
        0.9, min=0.0, max=1.01, help="a loop match with a competitor scoring this fraction of it is ambiguous (>1: off)"
    )
    loop_ambiguity_m: float = param(1.0, min=0.05, max=20.0, unit="m", help="competitors this far from the match make it ambiguous")
    loop_big_correction_m: float = param(
        0.5, min=0.0, max=100.0, unit="m", help="a loop group correcting more than this needs two submaps to agree"
    )
    loop_big_correction_rad: float = param(0.05, min=0.0, max=3.15, unit="rad", help="same, in heading")
    loop_max_contradiction: float = param(
        0.15, min=0.0, max=1.01, help="a loop whose aligned query has more of its points in the submap's free space, or rays through its walls, is rejected (>1: off)"
    )
    optimize_every_keyframes: int = param(10, min=1, max=1000, help="optimise at most this often while loops arrive")
    optimize_iterations: int = param(5, min=1, max=100, help="Levenberg–Marquardt iterations per online optimisation")
    map_update_budget: int = param(50, min=1, max=100000, help="keyframes re-inserted into the grid per map update")
    map_hz: float = param(1.0, min=0.1, max=10.0, help="map rebuild / publish rate (live app)")


# ----------------------------------------------------------------------------------------------
# Detector
# ----------------------------------------------------------------------------------------------


@dataclass
class DetectorConfig:
    """YOLO detector run with onnxruntime (or the simulator's oracle for measurements)."""

    kind: str = param("yolo", choices=("yolo", "oracle", "none"), help="yolo: the ONNX model; oracle: sim segmentation")
    model_path: str = param("assets/models/detector.onnx", help="ONNX model (relative paths: project root)")
    confidence: float = param(
        0.4, min=0.01, max=0.99, step=0.01, help="YOLO confidence threshold (paper: 40 %)", live=True
    )
    nms_iou: float = param(0.5, min=0.05, max=0.95, step=0.05, help="class-aware NMS IoU threshold", live=True)
    threads: int = param(2, min=1, max=16, help="onnxruntime intra-op threads")
    input_size: int = param(0, min=0, max=1280, help="model input width (0: from the model file)")
    verify_hash: bool = param(
        True, help="refuse a model whose sha256 differs from its model card (assets/models/*.yaml)"
    )
    calibration: str = param(
        "card",
        choices=("card", "off"),
        help="card: the soft decision reads each box's score as the probability its model card's Platt scaling "
        "gives (fitted on renders of unseen worlds; improved mode); off: the raw score (the paper)",
    )
    spin: bool = param(False, help="onnxruntime intra-op threads spin-wait between runs (costs CPU the loop needs)")
    denormal_as_zero: bool = param(False, help="onnxruntime flushes float denormals to zero")
    oracle_min_pixels: int = param(60, min=1, max=100000, help="oracle: minimum visible pixels for a box")
    oracle_min_visible_fraction: float = param(0.25, min=0.0, max=1.0, help="oracle: minimum visible fraction")
    oracle_confidence_mean: float = param(0.85, min=0.0, max=1.0, help="oracle: mean confidence")
    oracle_confidence_std: float = param(0.08, min=0.0, max=0.5, help="oracle: confidence noise σ")
    oracle_box_jitter_px: float = param(3.0, min=0.0, max=50.0, unit="px", help="oracle: box edge noise σ")
    ignore_classes: list = param(
        [], help="classes dropped after detection (the original drops duck and chair)", items=CLASS_NAMES
    )


# ----------------------------------------------------------------------------------------------
# Consciousness
# ----------------------------------------------------------------------------------------------


@dataclass
class ConsciousnessConfig:
    """The paper's Consciousness node (Algorithm 1 + soft decision) and our improvements."""

    mode: str = param(
        "improved",
        choices=("improved", "seed"),
        help="seed: the original implementation's behaviour; improved: our fixes",
        live=True,
    )
    tracking_threshold_m: float = param(
        0.30, min=0.01, max=2.0, step=0.01, unit="m", help="same-class association distance (paper: 30 cm)", live=True
    )
    island_threshold_m: float = param(
        0.10, min=0.01, max=1.0, step=0.01, unit="m", help="island buffer radius (paper: 10 cm)", live=True
    )
    presence_threshold: float = param(
        0.8, min=0.0, max=1.0, step=0.01, help="objects shown at presence ≥ this (paper: 80 %)", live=True
    )
    rolling_average_weight: float = param(
        0.9, min=0.0, max=1.0, step=0.01, help="weight of the old centre when merging (paper: 90 %)", live=True
    )
    frames_for_presence: int = param(
        5, min=1, max=100, step=1, help="F: frames before an object counts as present (paper: 5)", live=True
    )
    min_frames_for_presence: int = param(
        3, min=0, max=100, step=1,
        help="improved: an object passed quickly (a turn) is also judged on the frames it could have been seen in "
        "(those that boxed it and its clear misses), at least this many, with their mean confidence, instead of F "
        "(0 or ≥ F: always F, the paper)",
        live=True,
    )
    decay_rate_per_s: float = param(
        0.15, min=0.0, max=5.0, step=0.01, unit="1/s", help="improved: presence lost per second in view but unseen", live=True
    )
    max_object_range_m: float = param(
        3.5, min=0.5, max=20.0, step=0.1, unit="m", help="improved: ignore islands / ghost checks beyond this", live=True
    )
    box_height_check: bool = param(
        True,
        help="improved: an island is not the object of an uncut box that would be lower at the island's range than "
        "the class's lowest instance (over size_consistency_tolerance): a stool boxed as a shelf",
        live=True,
    )
    top_edge_check: bool = param(
        True,
        help="improved: an island is not the object of a box whose top edge is in the image and, at the island's range "
        "plus the class's depth, lies lower than the class's lowest instance (a cabinet or a chair's back boxed as a door)",
        live=True,
    )
    top_edge_front: bool = param(
        True,
        help="improved, top-edge check: for a class whose highest point stands above its front (shelves, doors), the top "
        "row is read at the island's range, not up to the class's depth farther back (a low cabinet boxed as a shelf)",
        live=True,
    )
    size_consistency_tolerance: float = param(
        0.6, min=0.05, max=5.0, step=0.05, help="improved: relative range error allowed by the box-size check", live=True
    )
    legs: bool = param(True, help="improved: group leg islands into one object", live=True)
    corner_check: bool = param(True, help="improved: reject islands inconsistent with the box (corner problem)", live=True)
    ground_plane: bool = param(True, help="improved: place objects with no island by ground-plane ranging", live=True)
    ghost_decay: bool = param(True, help="improved: decay presence of objects in view but not detected", live=True)
    clear_view_in_frame: float = param(
        0.5, min=0.0, max=1.0, step=0.05,
        help="improved: a frame without a box counts as a miss only when this share of the object's outline is "
        "inside the image (the detector's labels leave out objects less than half in the frame; 0: its centre alone)",
        live=True,
    )
    clear_view_min_px: float = param(
        20.0, min=0.0, max=240.0, step=1.0, unit="px",
        help="improved: a frame without a box counts as a miss only when the part of the object's image box inside "
        "the image is at least this many pixels on its smaller side, in the detector's 320-px-wide input (the detector "
        "boxes half the objects that look smaller: a duck two metres away; 0: any size)",
        live=True,
    )
    clear_view_visible: float = param(
        0.5, min=0.0, max=1.0, step=0.05,
        help="improved: a frame without a box counts as a miss only when the LIDAR sees this share of the object, "
        "counting as hidden what may continue behind a nearer return at its edge (0: only the central-half occlusion test)",
        live=True,
    )
    clear_view_own_points: bool = param(
        True,
        help="improved: a frame without a box counts as a miss only when the LIDAR reaches the object's own points: "
        "a return more than occlusion_margin_m in front of them hides it, even where its completed footprint reaches "
        "nearer (an object against the far side of a partition, seen through its face)",
        live=True,
    )
    presence_evidence: bool = param(
        True,
        help="improved: the published presence is at most P(object there | frames that boxed it, frames in clear view "
        "that did not), from detection_rate and false_detection_rate",
        live=True,
    )
    detection_rate: float = param(
        0.9, min=0.01, max=0.99, step=0.01,
        help="improved, presence evidence: how often the detector boxes an object that is there, in clear view",
        live=True,
    )
    false_detection_rate: float = param(
        0.5, min=0.01, max=0.99, step=0.01,
        help="improved, presence evidence: how often it boxes that class again where it fired without an object "
        "(clutter taken for an object)",
        live=True,
    )
    sync_tolerance_s: float = param(0.1, min=0.0, max=2.0, unit="s", help="improved: max image/scan stamp gap")
    range_tolerance: float = param(
        0.2, min=0.0, max=2.0, step=0.01, help="improved: relative slack of the near range given by the box's bottom edge", live=True
    )
    bottom_margin_px: float = param(
        6.0, min=0.0, max=100.0, step=1.0, unit="px", help="improved: bottom-edge uncertainty used for the near range", live=True
    )
    ground_plane_max_range_m: float = param(
        3.0, min=0.2, max=10.0, step=0.1, unit="m", help="improved: farthest ground-plane placement", live=True
    )
    decay_max_range_m: float = param(
        2.5, min=0.2, max=20.0, step=0.1, unit="m", help="improved: ghost decay only for objects nearer than this", live=True
    )
    occlusion_margin_m: float = param(
        0.1, min=0.0, max=2.0, step=0.01, unit="m",
        help="improved: LIDAR returns this much in front of an object's footprint are not its own and occlude it (a "
        "partition 0.17 m in front of a ball in the room's corner)",
        live=True,
    )
    overlap_fraction: float = param(
        0.3, min=0.0, max=1.0, step=0.05, help="improved: footprints overlapping by this share of the smaller one collide", live=True
    )
    stationary_frame_s: float = param(
        1.0, min=0.0, max=60.0, step=0.1, unit="s", help="improved: while the robot stands still, count a new frame after this time", live=True
    )
    edge_margin_px: float = param(
        8.0, min=0.0, max=100.0, step=1.0, unit="px", help="improved: a box this close to the image border is cut by it", live=True
    )
    point_ownership: bool = param(
        True,
        help="improved: each LIDAR island belongs to one box's object per frame (the narrowest boxes choose first, then "
        "the nearest); objects of different classes collide only over the points they share",
        live=True,
    )
    outside_ratio: float = param(
        0.5, min=0.0, max=5.0, step=0.05,
        help="improved: a point of an object's evidence that the LIDAR sees inside the image but outside the object's "
        "own box, in at least two views and more often than this ratio of its hits, no longer shapes the object "
        "(a stool's legs that joined a round table from behind it; 0: off)",
        live=True,
    )
    ray_centre_sigma_m: float = param(
        0.05, min=0.0, max=1.0, step=0.01, unit="m",
        help="improved: where an object's bisector rays fix its centre to this (their residual over their spread of "
        "directions), points beyond the object's reach of that centre do not shape it (a stool behind a round table, "
        "a box beside a shelf; 0: off)",
        live=True,
    )
    ray_centre_behind_surface: bool = param(
        True,
        help="improved: the bisector rays' crossing fixes an object's centre only if it lies behind the surface the "
        "LIDAR saw of it along most of those rays, not on the camera's side of it (boxes of a part of an armchair "
        "half hidden in its bay cross in front of it)",
        live=True,
    )
    range_contest_slack: float = param(
        0.1, min=0.0, max=2.0, step=0.01,
        help="improved, with point ownership: a point inside several boxes' wedges is lost by a box whose bottom-edge "
        "range misses it by this much more (relative) than the best box's (a table's leg in front of a chair behind it; "
        "2: off)",
        live=True,
    )
    leg_corner_m: float = param(
        0.12, min=0.0, max=1.0, step=0.01, unit="m",
        help="improved: a leg island farther than this from every corner of its group's rectangle is not one of its legs (0: off)",
        live=True,
    )
    corner_leg_owner: bool = param(
        True,
        help="improved, collisions: points a smaller object of a class without legs shares with legged furniture, all at "
        "one corner of the rectangle of its points, are that furniture's leg, not the smaller object's (flowers seen "
        "behind a desk's corner leg; elsewhere the nested object keeps them: a chair's legs under a table's edge)",
        live=True,
    )
    stray_by_views: bool = param(
        True,
        help="improved: the footprint's stray filter counts the views that added to a voxel, not the points it merged (a "
        "near leg gives several points a frame, a far leg one: counted by points, a near leg seen often made the far "
        "legs' voxels strays)",
        live=True,
    )
    support_whole_boxes: bool = param(
        True,
        help="improved: only a box not cut by the image border tells whether a legged object stands on one central "
        "support (a cut box's centre line is unknown and its wedge holds what stands beside it): a view that cannot "
        "tell (a cut box, one leg off the centre line) counts neither for nor against a pedestal, a pedestal's share "
        "is of the views that told, and a group of legs from such a view joins a pedestal only at its support",
        live=True,
    )
    nested_unconfirmed: bool = param(
        True,
        help="improved, collisions: an object not yet confirmed (presence below presence_threshold) nested in a confirmed "
        "one of another class loses the points they share instead of taking them (a box's first glimpse of a chair "
        "behind a round table does not take the table's pedestal; once confirmed, the nested object takes them)",
        live=True,
    )
    presence_confidence: str = param(
        "best",
        choices=("latest", "mean", "best"),
        help="improved: Y_c of the soft decision: the new box's confidence (the paper), the mean or the best of the object's counted frames",
        live=True,
    )
    hidden_behind_boxes: bool = param(
        True,
        help="improved, ghost decay: an object whose image columns and top one box of the frame covers, the box's object "
        "standing nearer (its bottom edge's range), is hidden from the camera by it: no clear miss (a chair behind another "
        "chair's box, whose legs the LIDAR sees through)",
        live=True,
    )
    box_explains_one: bool = param(
        True,
        help="improved, ghost decay: a box that gave an object in this frame explains no other object in its wedge "
        "(a third chair between two sofas' boxes is missed in clear view)",
        live=True,
    )
    fragment_fits_largest: bool = param(
        True,
        help="improved, collisions: an object seen only through boxes cut by the image border and a same-class "
        "neighbour within the class's length are one when together they fit its largest instance (not only a typical shape)",
        live=True,
    )
    border_fragment_of_other: bool = param(
        True,
        help="improved, collisions: a door (an object in a wall) seen only through boxes cut by the image border whose "
        "points continue a wholly seen free-standing object (within the island gap, together no larger than that class's "
        "largest instance) is a piece of that object, not a door (a door box at the image's edge over a bookcase's side)",
        live=True,
    )
    shared_evidence_fraction: float = param(
        0.5, min=0.0, max=1.0, step=0.05,
        help="improved: objects of different classes collide when this share of the smaller one's points lies on the other's",
        live=True,
    )
    seen_apart_frames: int = param(
        3, min=0, max=50, step=1,
        help="improved: two objects of one class seen side by side through boxes that do not overlap in the image in at "
        "least this many frames (and never through overlapping ones) are two objects however their points mix: each "
        "shared LIDAR point stays with the one that saw it more often (two round tables seen along one line; 0: off)",
        live=True,
    )
    free_space_behind_surface: bool = param(
        True,
        help="improved, corner check: the free-space test (corner_free_space) looks just behind the island's own surface "
        "along the bearings it covers, not just behind its front point (an armchair seen corner first)",
        live=True,
    )
    box_width_cap: float = param(
        1.6, min=0.0, max=5.0, step=0.1,
        help="improved, footprints: across the line of sight an object spans at most this many times the apparent width "
        "of its boxes (and 0.2 m more): points spread wider are partly something else's, such as a table's legs "
        "beside a chair that the class's sofa-sized shapes would otherwise take in (0: off, the class's largest size)",
        live=True,
    )
    base_hidden_makes_none: bool = param(
        True,
        help="improved: a box whose bottom edge is at or above the horizon (its object's base hidden by something "
        "nearer, or the box wrong) makes no object; it may still confirm one",
        live=True,
    )
    islands_apart: bool = param(
        True,
        help="improved: two boxes of one frame, side by side (each reaching beyond the other), of a class that stands "
        "on one island (not legged, not an open frame), whose islands are different clusters of the scan, saw two "
        "objects: not merged in the frame, their objects stay two however their points mix later, and a box over both "
        "explains both (two pots of flowers end to end)",
        live=True,
    )
    union_width_check: bool = param(
        True,
        help="improved: two objects of one class seen side by side through two boxes of one frame, whose LIDAR points "
        "mix, are one object only if together they are no wider across most of their lines of sight than their boxes "
        "showed (box_width_cap): two dining chairs' points fit the chair class's sofa, their boxes do not",
        live=True,
    )
    fragment_width_check: bool = param(
        True,
        help="improved: pieces of one object joined across a gap (a fragment seen only through border-cut boxes and a "
        "neighbour of its class) are one object only if together they are no wider across most of their lines of sight "
        "than their whole boxes showed (box_width_cap): a chair glimpsed at the image's edge 2 m from a chair seen whole "
        "fits the chair class's largest sofa, the whole chair's boxes do not",
        live=True,
    )
    hidden_covered_share: float = param(
        0.5, min=0.0, max=1.0, step=0.05,
        help="improved, ghost decay: an object whose image columns the boxes of nearer objects reaching above its top cover "
        "together by more than this share is hidden from the camera: no clear miss (1: only one box covering it whole)",
        live=True,
    )
    hidden_behind_own_face: bool = param(
        True,
        help="improved, footprints: the part of an object its points do not show lies behind its own face, not behind "
        "a wall or another obstacle the map knows; a footprint extrapolated there is turned the other way (a shelf "
        "against a wall seen from the side) or kept to its points",
        live=True,
    )
    far_face: bool = param(
        True,
        help="improved, footprints: an open frame (a bookcase) seen as one face from one side is completed towards the "
        "robot, not away from it, when its boxes' bottom edges put its base more than half its depth nearer than that "
        "face: the LIDAR saw through its open front to its far side panel (false: always away from the robot)",
        live=True,
    )
    legs_extend: bool = param(
        True,
        help="improved, footprints: an object seen as legs (a table's near legs) is completed away from the robot by "
        "its class's depth even where the map saw the floor free, unless it saw free floor where its far legs would "
        "stand: the LIDAR sees the floor under a table between its legs (false: any free band vetoes the completion, "
        "as for a solid object's far side)",
        live=True,
    )
    legs_seen_free: bool = param(
        True,
        help="improved, footprints: an object that may stand on a pedestal (a table), completed from one leg-sized "
        "support, is centred on that support when the map saw free space where two of its other legs would stand "
        "(a round table's pedestal seen off its boxes' centre lines, not a corner leg of a table behind it)",
        live=True,
    )
    gap_seen_free: bool = param(
        True,
        help="improved, association and merges: two point sets joined across a gap (pieces of one object glimpsed "
        "through border-cut boxes) are one object only if the map has not seen free floor between them over more "
        "than one instance leaves free inside itself (a legged class's leg span, an open frame's width; an armchair "
        "and a sofa face 1.8 m apart are two chairs, not one sofa)",
        live=True,
    )
    wide_box_fraction: float = param(
        0.85, min=0.0, max=1.0, step=0.05,
        help="improved: a box at least this share of the image wide makes no new object, it only sees one made before: "
        "the camera is too close to show the object's extent, and such boxes are the detector's answer to a surface "
        "filling the view (a wall, a shelf's side; 1: off)",
        live=True,
    )
    wide_box_whole_only: bool = param(
        True,
        help="improved: a box at least wide_box_fraction of the image wide confirms only an object seen whole before "
        "(through a box not cut by the image border); a fragment, seen only through cut boxes, it neither makes nor "
        "confirms (a counter glimpsed at the image's edge, then filling the view, is no bookcase)",
        live=True,
    )
    central_support: bool = param(
        True,
        help="improved: one leg-sized island on the centre line of a box much wider than it is, for a class that may "
        "stand on a pedestal (table), that support alone in this view: the other leg-sized islands in the box do not "
        "join it as legs (the stools and chairs round a round table)",
        live=True,
    )
    pedestal_fraction: float = param(
        0.8, min=0.0, max=1.0, step=0.05,
        help="improved: a legged object seen as one small island on its box's centre line in at least this share of its "
        "views stands on a pedestal, and its LIDAR cross-section is that support alone: of a later group of legs only "
        "those at it are its own, and neither another box's island in the same frame nor another object's points join "
        "it (stools round a round table; 0: off)",
        live=True,
    )
