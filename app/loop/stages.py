"""Stage accounting and where the stage jobs run: :class:`StageTimer` (wall-clock time per stage),
:class:`Counters` (frames, detections, skips and errors) and :class:`StageJobs` (the detector and
estimator threads of :class:`app.pipeline.Pipeline`, or inline)."""

from __future__ import annotations

import threading
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

STAGES = ("physics", "lidar", "render", "detector", "slam", "consciousness", "ui")


class StageTimer:
    """Per-stage wall-clock accounting: totals (for benchmarks) and a smoothed recent value (for the UI)."""

    def __init__(self, stages: tuple[str, ...] = STAGES) -> None:
        self.total_s = {s: 0.0 for s in stages}
        self.calls = {s: 0 for s in stages}
        self.recent_ms = {s: 0.0 for s in stages}
        self._lock = threading.Lock()  # stages are timed on the loop, detector and estimator threads

    def add(self, stage: str, seconds: float) -> None:
        with self._lock:
            self.total_s[stage] = self.total_s.get(stage, 0.0) + seconds
            self.calls[stage] = self.calls.get(stage, 0) + 1
            prev = self.recent_ms.get(stage, 0.0)
            self.recent_ms[stage] = 0.9 * prev + 0.1 * seconds * 1e3 if prev else seconds * 1e3

    def charge(self, stage: str, seconds: float) -> None:
        """Add ``seconds`` of work done for ``stage`` inside another stage's call (no call of its own: the
        SLAM's map update that the fusion's free-space test triggers), to its total."""
        with self._lock:
            self.total_s[stage] = self.total_s.get(stage, 0.0) + seconds

    def time(self, stage: str):
        timer = self

        class _Ctx:
            def __enter__(self_inner):
                self_inner.t0 = time.perf_counter()

            def __exit__(self_inner, *exc):
                timer.add(stage, time.perf_counter() - self_inner.t0)
                return False

        return _Ctx()

    def per_call_ms(self) -> dict[str, float]:
        return {s: (1e3 * self.total_s[s] / self.calls[s]) if self.calls.get(s) else 0.0 for s in self.total_s}

    def per_sim_second_ms(self, sim_seconds: float) -> dict[str, float]:
        if sim_seconds <= 0:
            return {s: 0.0 for s in self.total_s}
        return {s: 1e3 * v / sim_seconds for s, v in self.total_s.items()}


@dataclass
class Counters:
    scans: int = 0
    images: int = 0
    detections: int = 0
    fused_frames: int = 0
    skipped_frames: dict[str, int] = field(default_factory=dict)
    errors: dict[str, int] = field(default_factory=dict)
    _lock: Any = field(default_factory=threading.Lock, repr=False, compare=False)

    def skip(self, reason: str) -> None:
        with self._lock:
            self.skipped_frames[reason] = self.skipped_frames.get(reason, 0) + 1

    def error(self, reason: str) -> None:
        with self._lock:
            self.errors[reason] = self.errors.get(reason, 0) + 1


class StageJobs:
    """Where the detector and estimator jobs run: on two worker threads (``parallel``) or inline.

    ``detect(fn, ...)`` runs on the detector thread; ``estimate(fn, ...)`` on the estimator thread, in
    submission order. Both return a :class:`Future`; inline, it is already done. Jobs catch their own
    errors (a failed job never stops the loop). :meth:`join` waits for every estimator job submitted.
    """

    def __init__(self, parallel: bool) -> None:
        self.parallel = bool(parallel)
        self._det = ThreadPoolExecutor(1, thread_name_prefix="ocslam-detector") if self.parallel else None
        self._est = ThreadPoolExecutor(1, thread_name_prefix="ocslam-estimators") if self.parallel else None
        self._pending: deque[Future] = deque()
        #: guards ``_pending``: the loop thread and the GUI's threads all wait for the jobs in flight
        self._lock = threading.Lock()
        self._threads: set[int] = set()

    @staticmethod
    def _inline(fn: Callable[..., Any], *args: Any) -> Future:
        f: Future = Future()
        try:
            f.set_result(fn(*args))
        except BaseException as e:  # noqa: BLE001 - handed to whoever reads the future
            f.set_exception(e)
        return f

    def _wrap(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        def run(*args: Any) -> Any:
            self._threads.add(threading.get_ident())
            return fn(*args)

        return run

    def detect(self, fn: Callable[..., Any], *args: Any) -> Future:
        if self._det is None:
            return self._inline(fn, *args)
        return self._det.submit(self._wrap(fn), *args)

    def estimate(self, fn: Callable[..., Any], *args: Any) -> Future:
        if self._est is None:
            return self._inline(fn, *args)
        with self._lock:  # submitted and queued together, so the queue keeps the jobs' order
            f = self._est.submit(self._wrap(fn), *args)
            self._pending.append(f)
        return f

    def in_worker(self) -> bool:
        return threading.get_ident() in self._threads

    def join(self) -> None:
        """Wait for every estimator job submitted so far (a no-op on a worker thread or inline)."""
        if self._est is None or self.in_worker():
            return
        while True:
            with self._lock:
                if not self._pending:
                    return
                f = self._pending[0]
            try:
                f.result()
            except Exception:  # jobs log their own errors
                pass
            with self._lock:  # another waiter may have dropped it already
                if self._pending and self._pending[0] is f:
                    self._pending.popleft()

    def busy(self) -> int:
        """Estimator jobs not finished yet."""
        with self._lock:
            while self._pending and self._pending[0].done():
                self._pending.popleft()
            return sum(not f.done() for f in self._pending)

    def close(self) -> None:
        self.join()
        for ex in (self._det, self._est):
            if ex is not None:
                ex.shutdown(wait=True)
        self._det = self._est = None
