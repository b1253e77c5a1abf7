"""Navigation core: cost maps, A* planning, frontiers, exploration and path following.

Pure numpy/scipy/OpenCV; every point and pose is in the SLAM ``map`` frame.

    blocked = inflate(grid, 0.105)                                   # (H, W) bool
    path = plan_path(grid, start_xy, goal_xy, 0.105)                 # (N, 2) or None
    frontiers = find_frontiers(grid)                                 # list[Frontier]
    explorer = FrontierExplorer(0.105); explorer.next_goal(grid, T_map_base)
    follower = PathFollower(RobotConfig()); follower.set_path(path)
    cmd_vel = follower.compute(T_map_base, scan, T_base_scan)
    controller = ExplorationController(RobotConfig()); controller.start()
    cmd_vel = controller.compute(grid, T_map_base, scan, T_base_scan, now)
    goto = GoToController(RobotConfig(), clicked_xy)                  # click-to-go
    cmd_vel = goto.compute(grid, T_map_base, scan, T_base_scan, now)  # goto.status: following/arrived/failed
"""

from app.ocslam.navigation.astar import astar, cost_to_go, plan_path
from app.ocslam.navigation.costmap import CostMap, build_costmap, inflate
from app.ocslam.navigation.explorer import ExplorationController, FrontierExplorer
from app.ocslam.navigation.follower import PathFollower, RouteFollower, StuckDetector
from app.ocslam.navigation.frontiers import Frontier, find_frontiers
from app.ocslam.navigation.goto import GoToController

__all__ = [
    "CostMap",
    "ExplorationController",
    "Frontier",
    "FrontierExplorer",
    "GoToController",
    "PathFollower",
    "RouteFollower",
    "StuckDetector",
    "astar",
    "build_costmap",
    "cost_to_go",
    "find_frontiers",
    "inflate",
    "plan_path",
]
