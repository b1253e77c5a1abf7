"""viser scene layers. The viser world frame is the SLAM ``map`` frame (z up, REP-103).

Each layer owns its scene nodes under one parent (``/layers/<key>``) so a single checkbox hides it.
Layers only read pipeline state; they run in the loop thread at ``ui.update_hz`` (the map at
``ui.map_hz``) and compute arrays before touching viser handles.
"""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import viser

from app.ocslam.se2 import Pose2
from app.ui.colors import CLASS_COLORS, grid_to_rgb

if TYPE_CHECKING:
    from app.pipeline import Pipeline

log = logging.getLogger(__name__)


def wxyz(yaw: float) -> tuple[float, float, float, float]:
    return (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))


def pose3(T: np.ndarray) -> tuple[tuple[float, float, float, float], tuple[float, float, float]]:
    """(4, 4) → (wxyz, xyz)."""
    q = viser.transforms.SO3.from_matrix(T[:3, :3]).wxyz
    return tuple(float(v) for v in q), tuple(float(v) for v in T[:3, 3])  # type: ignore[return-value]


def polyline_segments(points_xy: np.ndarray, z: float = 0.0, closed: bool = False) -> np.ndarray:
    """``(N, 2)`` polyline → ``(M, 2, 3)`` segments at height ``z``."""
    p = np.asarray(points_xy, dtype=np.float64).reshape(-1, 2)
    if closed and len(p) > 2:
        p = np.vstack([p, p[:1]])
    if len(p) < 2:
        return np.zeros((0, 2, 3))
    a = np.column_stack([p[:-1], np.full(len(p) - 1, z)])
    b = np.column_stack([p[1:], np.full(len(p) - 1, z)])
    return np.stack([a, b], axis=1)


def _segments_or_empty(seg: np.ndarray) -> np.ndarray:
    # viser needs at least one segment: a zero-length one at the origin is invisible
    return seg if len(seg) else np.zeros((1, 2, 3))


#: (key, label, visible by default)
LAYERS: tuple[tuple[str, str, bool], ...] = (
    ("world", "World (simulator)", True),
    ("robot", "Robot model", True),
    ("tf", "TF axes", False),
    ("lidar", "LIDAR points", True),
    ("camera_bound", "Camera view bound", True),
    ("areas", "Bounding areas", True),
    ("grid", "Occupancy grid", True),
    ("traj_slam", "SLAM trajectory", True),
    ("traj_odom", "Odometry trajectory", True),
    ("graph", "Pose graph", False),
    ("objects", "Objects", True),
    ("nav", "Navigation path", True),
    ("truth", "Ground truth overlay", False),
)


@dataclass
class _ObjectNodes:
    footprint: Any
    label: Any
    last_text: str = ""


class SceneLayers:
    """All scene layers of one viser server (shared by every client)."""

    def __init__(self, server: viser.ViserServer, pipeline: Pipeline) -> None:
        self.server = server
        self.scene = server.scene
        self.pipeline = pipeline
        self.roots: dict[str, Any] = {}
        for key, _, visible in LAYERS:
            self.roots[key] = self.scene.add_frame(f"/layers/{key}", show_axes=False, visible=visible)
        self._objects: dict[int, _ObjectNodes] = {}
        self._truth_built = False
        self._grid_stamp = -1.0
        self._graph_sig: tuple[int, int, int] = (-1, -1, -1)
        self._last_fusion = -1.0
        self.urdf = None
        self._build_static()

    # ------------------------------------------------------------------------------------------
    def set_visible(self, key: str, visible: bool) -> None:
        self.roots[key].visible = visible

    def is_visible(self, key: str) -> bool:
        return bool(self.roots[key].visible)

    # ------------------------------------------------------------------------------------------
    def _build_static(self) -> None:
        p = self.pipeline
        s = self.scene
        s.set_up_direction("+z")
        # the world, re-expressed in the map frame
        self.world_root = s.add_frame("/layers/world/T_map_world", show_axes=False)
        self._set_pose(self.world_root, p.T_map_world)
        self._build_world_meshes()
        # robot: base_footprint at T_map_base, URDF below it
        self.robot_root = s.add_frame("/layers/robot/base_footprint", show_axes=False)
        try:
            from viser.extras import ViserUrdf

            self.urdf = ViserUrdf(self.server, p.robot_model.urdf_path, root_node_name="/layers/robot/base_footprint")
            self.urdf.update_cfg(np.zeros(len(self.urdf.get_actuated_joint_names())))
        except Exception as e:  # the scene still works without the robot model
            log.error("robot model not shown: %s", e)
        # LIDAR points in the base_scan frame, under a frame that follows the robot
        self.lidar_root = s.add_frame("/layers/lidar/base_footprint", show_axes=False)
        q, t = pose3(p.robot_model.T_base_scan)
        self.lidar_scan_frame = s.add_frame("/layers/lidar/base_footprint/base_scan", show_axes=False, wxyz=q, position=t)
        self.lidar_points = s.add_point_cloud(
            "/layers/lidar/base_footprint/base_scan/points",
            points=np.zeros((1, 3), dtype=np.float32),
            colors=(255, 40, 40),
            point_size=0.035,
            point_shape="circle",
        )
        # TF axes
        self.tf_nodes = {
            name: s.add_frame(f"/layers/tf/{name}", show_axes=True, axes_length=0.25, axes_radius=0.008)
            for name in ("map", "odom", "base_footprint", "base_scan", "camera_optical_frame")
        }
        self.tf_labels = {
            name: s.add_label(f"/layers/tf/{name}/label", name, font_screen_scale=0.6, anchor="bottom-left")
            for name in self.tf_nodes
        }
        # camera bound and bounding areas: polygons in the map frame, drawn slightly above the floor
        self.camera_bound = s.add_line_segments(
            "/layers/camera_bound/outline", np.zeros((1, 2, 3)), colors=(70, 70, 220), thickness=0.012
        )
        self.areas = s.add_line_segments("/layers/areas/outlines", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.02)
        self.bisectors = s.add_line_segments(
            "/layers/areas/bisectors", np.zeros((1, 2, 3)), colors=(0, 0, 0), thickness=0.006
        )
        self.area_points = s.add_point_cloud(
            "/layers/areas/points", np.zeros((1, 3), dtype=np.float32), colors=(0, 0, 0), point_size=0.05,
            precision="float32",
        )
        # occupancy grid
        self.grid_image = s.add_image(
            "/layers/grid/map", np.full((2, 2, 3), 205, np.uint8), 0.1, 0.1, format="png", position=(0, 0, 0.007),
            cast_shadow=False, receive_shadow=False,
        )
        # trajectories and graph
        self.traj_slam = s.add_line_segments("/layers/traj_slam/path", np.zeros((1, 2, 3)), colors=(0, 150, 255), thickness=0.02)
        self.traj_odom = s.add_line_segments("/layers/traj_odom/path", np.zeros((1, 2, 3)), colors=(255, 140, 0), thickness=0.015)
        self.graph_nodes = s.add_point_cloud(
            "/layers/graph/nodes", np.zeros((1, 3), dtype=np.float32), colors=(30, 30, 160), point_size=0.05,
            precision="float32",
        )
        self.graph_edges = s.add_line_segments("/layers/graph/edges", np.zeros((1, 2, 3)), colors=(120, 120, 200), thickness=0.008)
        self.graph_loops = s.add_line_segments("/layers/graph/loops", np.zeros((1, 2, 3)), colors=(255, 0, 200), thickness=0.02)
        # loop closures the SLAM found but rejected (verification / post-optimisation residual): red, thin
        self.graph_rejected = s.add_line_segments("/layers/graph/rejected", np.zeros((1, 2, 3)), colors=(230, 40, 40), thickness=0.008)
        # navigation path
        self.nav_path = s.add_line_segments("/layers/nav/path", np.zeros((1, 2, 3)), colors=(0, 200, 80), thickness=0.025)
        # ground truth robot ghost
        self.truth_robot = s.add_frame("/layers/truth/robot", show_axes=True, axes_length=0.2, axes_radius=0.01)

    def _set_pose(self, handle: Any, T: Pose2, z: float = 0.0) -> None:
        handle.position = (T.x, T.y, z)
        handle.wxyz = wxyz(T.yaw)

    def _build_world_meshes(self) -> None:
        """The simulator's walls and objects (in the world frame, under T_map_world)."""
        try:
            from app.world.models.meshes import world_visual_meshes

            meshes = world_visual_meshes(self.pipeline.world)
        except Exception as e:
            log.error("world meshes not shown: %s", e)
            return
        cut = self.pipeline.cfg.ui.wall_height_m
        for i, (name, mesh) in enumerate(meshes):
            if name.startswith("wall") and cut > 0:  # cut-away walls, so the rooms can be seen from above
                zmax = float(mesh.bounds[1, 2])
                if zmax > cut:
                    mesh = mesh.copy()
                    mesh.apply_scale([1.0, 1.0, cut / zmax])
            safe = "".join(c if c.isalnum() or c in "_-" else "_" for c in name) or f"m{i}"
            self.scene.add_mesh_trimesh(f"/layers/world/T_map_world/{i:03d}_{safe}", mesh)

    def rebuild_world(self) -> None:
        """After loading another world."""
        self.scene.remove_by_name("/layers/world/T_map_world") if hasattr(self.scene, "remove_by_name") else None
        self.world_root.remove()
        self.world_root = self.scene.add_frame("/layers/world/T_map_world", show_axes=False)
        self._set_pose(self.world_root, self.pipeline.T_map_world)
        self._build_world_meshes()
        self._truth_built = False
        for nodes in self._objects.values():
            nodes.footprint.remove()
        self._objects.clear()
        self._grid_stamp = -1.0

    # ------------------------------------------------------------------------------------------
    def update(self, *, with_map: bool) -> None:
        """Push the current state (robot, scan, fusion, objects; the map when ``with_map``)."""
        p = self.pipeline
        T_map_base = p.T_map_base
        self._set_pose(self.robot_root, T_map_base)
        self._set_pose(self.lidar_root, T_map_base)
        if self.urdf is not None:
            enc = getattr(p.sim, "wheel_angles", None)
            if enc is not None:
                try:
                    self.urdf.update_cfg(np.asarray(enc, dtype=np.float64))
                except Exception:
                    pass
        if self.is_visible("lidar") and p.last_scan is not None:
            pts = p.last_scan.points()
            if len(pts):
                self.lidar_points.points = np.column_stack([pts, np.zeros(len(pts))]).astype(np.float32)
        if self.is_visible("tf"):
            self._update_tf(T_map_base)
        if p.fusion.stamp != self._last_fusion:
            self._last_fusion = p.fusion.stamp
            self._update_fusion()
        if self.is_visible("objects"):
            self._update_objects()
        if self.is_visible("nav"):
            path = p._nav_path_map
            self.nav_path.points = _segments_or_empty(polyline_segments(path, 0.03) if path is not None else np.zeros((0, 2, 3)))
        if self.is_visible("truth"):
            self._update_truth()
        if with_map:
            self._update_map()

    def _update_tf(self, T_map_base: Pose2) -> None:
        p = self.pipeline
        self._set_pose(self.tf_nodes["map"], Pose2())
        self._set_pose(self.tf_nodes["odom"], p.T_map_odom)
        self._set_pose(self.tf_nodes["base_footprint"], T_map_base)
        T_map_base_4 = np.eye(4)
        T_map_base_4[:3, :3] = viser.transforms.SO3.from_z_radians(T_map_base.yaw).as_matrix()
        T_map_base_4[:2, 3] = (T_map_base.x, T_map_base.y)
        for name, T_base in (("base_scan", p.robot_model.T_base_scan), ("camera_optical_frame", p.robot_model.T_base_camera_optical)):
            q, t = pose3(T_map_base_4 @ T_base)
            self.tf_nodes[name].wxyz = q
            self.tf_nodes[name].position = t

    def _update_fusion(self) -> None:
        """Camera view bound, bounding areas, bisectors and the points each area received (map frame)."""
        p = self.pipeline
        rep = p.fusion.report
        T = p.fusion.T_frame_base
        if rep is None or T is None:
            return
        T_frame_scan = getattr(rep, "T_frame_scan", None) or (T @ p.T_base_scan)
        # seed mode keeps objects in odom: show them in the map frame
        if p.cfg.consciousness.mode == "seed":
            T_frame_scan = p.T_map_odom @ T_frame_scan
        z = 0.02
        bound = getattr(rep, "camera_bound", None)
        if bound is not None and not bound.is_empty:
            xy = T_frame_scan.transform_points(np.asarray(bound.exterior.coords)[:, :2])
            self.camera_bound.points = _segments_or_empty(polyline_segments(xy, z))
        segs, cols, bis, bcols, pts, pcols = [], [], [], [], [], []
        for area in getattr(rep, "areas", []) or []:
            color = CLASS_COLORS.get(area.detection.label, (0, 0, 0))
            poly = area.polygon
            if poly is None or poly.is_empty:
                continue
            geoms = getattr(poly, "geoms", [poly])
            for g in geoms:
                xy = T_frame_scan.transform_points(np.asarray(g.exterior.coords)[:, :2])
                s = polyline_segments(xy, z + 0.005)
                segs.append(s)
                cols.append(np.broadcast_to(np.array(color, np.uint8), s.shape).copy())
            b = getattr(area, "bisector", None)
            if b is not None:
                s = polyline_segments(T_frame_scan.transform_points(np.asarray(b)[:, :2]), z + 0.005)
                bis.append(s)
                bcols.append(np.broadcast_to(np.array(color, np.uint8), s.shape).copy())
            ap = getattr(area, "points", None)
            if ap is not None and len(ap):
                q = T_frame_scan.transform_points(np.asarray(ap)[:, :2])
                pts.append(np.column_stack([q, np.full(len(q), 0.04)]))
                pcols.append(np.broadcast_to(np.array(color, np.uint8), (len(q), 3)))
        if segs:
            self.areas.points = np.concatenate(segs)
            self.areas.colors = np.concatenate(cols)
        else:
            self.areas.points = np.zeros((1, 2, 3))
        self.bisectors.points = np.concatenate(bis) if bis else np.zeros((1, 2, 3))
        if bis:
            self.bisectors.colors = np.concatenate(bcols)
        if pts:
            self.area_points.points = np.concatenate(pts).astype(np.float32)
            self.area_points.colors = np.concatenate(pcols)
        else:
            self.area_points.points = np.zeros((1, 3), np.float32)

    def _object_pose_map(self, o) -> Pose2:
        p = self.pipeline
        if o.frame_id == "odom":
            return p.T_map_odom @ o.pose
        return o.pose

    def _update_objects(self) -> None:
        """Class-coloured footprints with a ``label p%`` label, opacity = presence; hidden below the threshold."""
        p = self.pipeline
        thr = p.cfg.consciousness.presence_threshold
        seen = set()
        for o in p.consciousness.objects:
            seen.add(o.id)
            nodes = self._objects.get(o.id)
            color = CLASS_COLORS.get(o.label, (128, 128, 128))
            if nodes is None:
                fp = self.scene.add_box(
                    f"/layers/objects/o{o.id}", color=color, dimensions=(max(o.size_x, 0.05), max(o.size_y, 0.05), 0.3),
                    opacity=0.5, cast_shadow=False, receive_shadow=False,
                )
                lb = self.scene.add_label(f"/layers/objects/o{o.id}/label", "", position=(0, 0, 0.45), anchor="bottom-center",
                                          font_screen_scale=0.8)
                nodes = self._objects[o.id] = _ObjectNodes(fp, lb)
            T = self._object_pose_map(o)
            h = 0.3 if o.size_z <= 0 else min(max(o.size_z, 0.05), 2.0)
            nodes.footprint.position = (T.x, T.y, h / 2)
            nodes.footprint.wxyz = wxyz(T.yaw)
            nodes.footprint.dimensions = (max(o.size_x, 0.05), max(o.size_y, 0.05), h)
            nodes.footprint.opacity = float(np.clip(o.presence, 0.05, 1.0)) * 0.85
            nodes.footprint.visible = o.presence >= thr
            nodes.label.position = (0.0, 0.0, h / 2 + 0.12)
            text = f"{o.label} {o.presence * 100:.0f}%" + (" (ground)" if o.source == "ground_plane" else "")
            if text != nodes.last_text:
                nodes.label.text = text
                nodes.last_text = text
        for oid in list(self._objects):
            if oid not in seen:
                self._objects.pop(oid).footprint.remove()  # its label is a child node: removed with it

    def _update_truth(self) -> None:
        p = self.pipeline
        self._set_pose(self.truth_robot, p.true_pose_map(), 0.01)
        if self._truth_built:
            return
        self._truth_built = True
        segs, cols = [], []
        for o in p.truth_objects_map():
            s = polyline_segments(o.footprint, 0.01, closed=True)
            segs.append(s)
            cols.append(np.broadcast_to(np.array(CLASS_COLORS.get(o.label, (0, 0, 0)), np.uint8), s.shape).copy())
            c = o.footprint.mean(axis=0)
            self.scene.add_label(f"/layers/truth/labels/{o.id}", f"true {o.label}", position=(c[0], c[1], 0.05),
                                 font_screen_scale=0.6, anchor="top-center")
        for ob in p.truth_obstacles_map():
            s = polyline_segments(ob.footprint, 0.01, closed=True)
            segs.append(s)
            cols.append(np.broadcast_to(np.array((90, 90, 90), np.uint8), s.shape).copy())
        if segs:
            self.scene.add_line_segments("/layers/truth/outlines", np.concatenate(segs), colors=np.concatenate(cols), thickness=0.015)

    def _update_map(self) -> None:
        p = self.pipeline
        if not p.cfg.slam.enabled:
            return
        if self.is_visible("grid"):
            grid = p.slam.occupancy_grid()
            if grid.width and grid.height:
                rgb = grid_to_rgb(grid.data)
                w, h = grid.width * grid.resolution, grid.height * grid.resolution
                o = grid.origin
                c = o.transform_points(np.array([[w / 2, h / 2]]))[0]
                self.grid_image.image = rgb
                self.grid_image.render_width = w
                self.grid_image.render_height = h
                self.grid_image.position = (float(c[0]), float(c[1]), 0.007)
                self.grid_image.wxyz = wxyz(o.yaw)
        if self.is_visible("traj_slam"):
            _, traj = p.slam.trajectory()
            if len(traj) > 1:
                self.traj_slam.points = polyline_segments(traj[:: max(1, len(traj) // 2000), :2], 0.015)
        if self.is_visible("traj_odom") and p.truth_log:
            odom = np.array([o.as_array()[:2] for _, _, o in p.truth_log[:: max(1, len(p.truth_log) // 2000)]])
            if len(odom) > 1:
                self.traj_odom.points = polyline_segments(odom, 0.012)
        if self.is_visible("graph"):
            g = p.slam.pose_graph()
            rejected = np.asarray(getattr(g, "rejected", np.zeros((0, 2))), dtype=np.int64).reshape(-1, 2)
            sig = (len(g.nodes), len(g.edges), p.slam.correction_count, len(rejected))
            if sig != self._graph_sig and len(g.nodes):
                self._graph_sig = sig
                nodes3 = np.column_stack([g.nodes[:, :2], np.full(len(g.nodes), 0.02)])
                self.graph_nodes.points = nodes3.astype(np.float32)
                e = np.asarray(g.edges, dtype=np.int64).reshape(-1, 2)
                loop = np.asarray(g.is_loop, dtype=bool)
                if len(e):
                    segs = np.stack([nodes3[e[:, 0]], nodes3[e[:, 1]]], axis=1)
                    self.graph_edges.points = _segments_or_empty(segs[~loop])
                    self.graph_loops.points = _segments_or_empty(segs[loop] + np.array([0, 0, 0.01]))
                rejected = rejected[(rejected >= 0).all(axis=1) & (rejected < len(nodes3)).all(axis=1)]
                self.graph_rejected.points = _segments_or_empty(
                    np.stack([nodes3[rejected[:, 0]], nodes3[rejected[:, 1]]], axis=1) + np.array([0, 0, 0.005])
                )
