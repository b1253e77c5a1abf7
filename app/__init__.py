"""OCSLAM: Object-Conscious SLAM with YOLO and a 2D LIDAR, in a pybullet apartment, live in viser."""

import os as _os

__version__ = "0.1.0"

# No outbound traffic (docs/security.md): onnxruntime >= 1.32 sends 1DS telemetry to
# mobile.events.data.microsoft.com (DNS after ~10 s) and keeps an offline store in
# ~/.cache/Microsoft/DeveloperTools/.onnxruntime/ unless this is set *before* onnxruntime is
# imported; onnxruntime.disable_telemetry_events() stops neither. Every `app` import comes first.
_os.environ["ORT_DISABLE_TELEMETRY"] = "1"

# One glibc malloc arena (app/memory.py): the loop's stage threads end with their pipeline, and the
# arenas glibc gives them keep a large world's working set resident for good. Before any thread starts.
from app.memory import limit_malloc_arenas as _limit_malloc_arenas  # noqa: E402

_limit_malloc_arenas(1)
