"""A sweep's outputs from its ``results.jsonl``: the per-trial table, the best configuration, the plots.

- ``results.csv``: one row per trial: its parameters, each world's F1 (and strict precision / recall),
  the means, the objective, the worlds it scored (ASHA stops some trials early), the trial's seconds;
  ``results.md``: the same as a Markdown table, best first (trials stopped early last).
- The best trial and the plots use the trials scored on every world only.
- ``best.yaml``: the base config with the best trial's parameters, as :meth:`app.config.Config.save`
  writes it (``ocslam run --config OUT/best.yaml`` loads it).
- ``plots/f1_vs_<param>.png`` (mean F1 against each parameter, the best trial marked, the defaults'
  value dashed) and ``plots/precision_recall.png`` (every trial, the Pareto front joined).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Any

from app.sweep.spec import Spec


def complete(row: dict[str, Any]) -> bool:
    """True if the trial scored every world (an ASHA sweep stops some early; older files: every trial)."""
    return bool(row.get("complete", True))


def best_row(rows: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The trial with the best objective among those scored on every world."""
    ok = [r for r in rows if complete(r) and r.get("objective") is not None and math.isfinite(float(r["objective"]))]
    return max(ok, key=lambda r: (float(r["objective"]), float(r.get("mean_f1") or 0.0))) if ok else None


def _fmt(v: Any) -> str:
    if isinstance(v, float):
        return f"{v:.4g}" if abs(v) >= 1e-3 or v == 0 else f"{v:.2e}"
    return str(v)


def write_table(spec: Spec, rows: list[dict[str, Any]], out: Path) -> tuple[Path, Path]:
    """``results.csv`` (trial order) and ``results.md`` (best first)."""
    names = [p.path for p in spec.params]
    worlds = sorted({w for r in rows for w in r.get("per_world", {})})
    head = ["trial_id", *names, *[f"f1[{w}]" for w in worlds], *[f"P[{w}]" for w in worlds],
            *[f"R[{w}]" for w in worlds], "mean_precision_strict", "mean_recall", "mean_f1", "mean_pos_err_mean_m",
            "objective", "worlds_done", "complete", "trial_s", "trial_cpu_s"]
    csv_path = Path(out) / "results.csv"
    with open(csv_path, "w", newline="", encoding="utf-8") as f:
        wr = csv.writer(f)
        wr.writerow(head)
        for r in rows:
            pw = r.get("per_world", {})
            wr.writerow([r["trial_id"], *[r["params"].get(n) for n in names],
                         *[pw.get(w, {}).get("f1") for w in worlds], *[pw.get(w, {}).get("precision_strict") for w in worlds],
                         *[pw.get(w, {}).get("recall") for w in worlds],
                         *[r.get(k) for k in ("mean_precision_strict", "mean_recall", "mean_f1", "mean_pos_err_mean_m",
                                              "objective")],
                         r.get("worlds_done", len(pw)), complete(r), r.get("trial_s"), r.get("trial_cpu_s")])
    md_head = ["#", *[n.split(".")[1] for n in names], "P", "R", "F1", "objective", *worlds]
    lines = ["| " + " | ".join(md_head) + " |", "|" + "---|" * len(md_head)]
    # the trials scored on every world first (best first), then those ASHA stopped early (their figures
    # are over the worlds they reached: not comparable with the others')
    ranked = sorted(rows, key=lambda r: (not complete(r), -float(r.get("objective") if r.get("objective") is not None else -1e9)))
    for i, r in enumerate(ranked, 1):
        pw = r.get("per_world", {})
        tag = str(i) if complete(r) else f"{i} (stopped, {len(pw)} worlds)"
        lines.append("| " + " | ".join([tag, *[_fmt(r["params"].get(n)) for n in names],
                                        *[_fmt(r.get(k)) for k in ("mean_precision_strict", "mean_recall", "mean_f1", "objective")],
                                        *[_fmt(pw.get(w, {}).get("f1")) for w in worlds]]) + " |")
    md_path = Path(out) / "results.md"
    n_full = sum(complete(r) for r in rows)
    stopped = f" ({len(rows) - n_full} stopped early by ASHA)" if n_full < len(rows) else ""
    md_path.write_text(f"Sweep {spec.name}: {len(rows)} trials{stopped}, objective {spec.objective.describe()} "
                       f"(per-world columns: F1)\n\n" + "\n".join(lines) + "\n", encoding="utf-8")
    return csv_path, md_path


def write_best(spec: Spec, rows: list[dict[str, Any]], out: Path) -> Path | None:
    """``best.yaml``: the base config with the best trial's parameters."""
    b = best_row(rows)
    if b is None:
        return None
    from app.sweep.trial import clean

    cfg = spec.base_config()
    for k, v in clean(b["params"]).items():
        cfg.set(k, v)
    return cfg.save(Path(out) / "best.yaml")


def write_plots(spec: Spec, rows: list[dict[str, Any]], out: Path) -> list[Path]:
    """F1 against each parameter and the precision/recall front (PNG, matplotlib's Agg backend)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return []
    import numpy as np

    ok = [r for r in rows if complete(r) and r.get("mean_f1") is not None and math.isfinite(float(r["mean_f1"]))]
    if not ok:
        return []
    pdir = Path(out) / "plots"
    pdir.mkdir(parents=True, exist_ok=True)
    b = best_row(ok)
    base = spec.base_config()
    f1 = np.array([float(r["mean_f1"]) for r in ok])
    paths = []
    for p in spec.params:
        vals = [r["params"].get(p.path) for r in ok]
        fig, ax = plt.subplots(figsize=(5, 3.6), dpi=110)
        numeric = all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in vals)
        x = np.array(vals, dtype=float) if numeric else np.array([sorted(map(str, set(vals))).index(str(v)) for v in vals])
        ax.scatter(x, f1, s=14, alpha=0.6, label="trials")
        if b is not None:
            bx = float(b["params"][p.path]) if numeric else sorted(map(str, set(vals))).index(str(b["params"][p.path]))
            ax.scatter([bx], [float(b["mean_f1"])], s=60, marker="*", color="C3", label="best", zorder=3)
        dv = base.get(p.path)
        if numeric and isinstance(dv, (int, float)):
            ax.axvline(float(dv), color="0.4", ls="--", lw=1, label=f"default {dv:g}")
        if not numeric:
            labels = sorted(map(str, set(vals)))
            ax.set_xticks(range(len(labels)), labels)
        ax.set_xlabel(p.path)
        ax.set_ylabel("mean F1")
        ax.set_title(f"{spec.name}: F1 vs {p.path.split('.')[1]}", fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
        fig.tight_layout()
        path = pdir / f"f1_vs_{p.path.replace('.', '_')}.png"
        fig.savefig(path)
        plt.close(fig)
        paths.append(path)
    P = np.array([float(r["mean_precision_strict"]) for r in ok])
    R = np.array([float(r["mean_recall"]) for r in ok])
    order = np.argsort(-R, kind="stable")
    front, best_p = [], -1.0
    for i in order:  # Pareto front: no other trial has both higher recall and higher precision
        if P[i] > best_p:
            front.append(i)
            best_p = P[i]
    fig, ax = plt.subplots(figsize=(5, 4), dpi=110)
    ax.scatter(R, P, s=14, alpha=0.6, label="trials")
    fr = sorted(front, key=lambda i: R[i])
    ax.plot(R[fr], P[fr], "-o", color="C1", ms=4, lw=1.2, label="front")
    if b is not None:
        ax.scatter([float(b["mean_recall"])], [float(b["mean_precision_strict"])], s=80, marker="*", color="C3",
                   label="best", zorder=3)
    if spec.objective.metric == "precision_at_recall":
        ax.axvline(spec.objective.recall_floor, color="0.4", ls="--", lw=1, label="recall floor")
    ax.set_xlabel("mean recall")
    ax.set_ylabel("mean strict precision")
    ax.set_title(f"{spec.name}: precision / recall ({len(ok)} trials)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    path = pdir / "precision_recall.png"
    fig.savefig(path)
    plt.close(fig)
    paths.append(path)
    return paths
