"""Aggregating episode records: cells (success rate and interval per configuration) and failure-detector
figures."""
from __future__ import annotations

import math
from collections import defaultdict

from tcot_hybrid.evaluation.jobs import CELL_KEYS
from tcot_hybrid.metrics import auroc


def _mean(xs):
    xs = [x for x in xs if x is not None]
    return round(sum(xs) / len(xs), 4) if xs else None


def aggregate(records: list[dict]) -> list[dict]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for r in records:
        groups[tuple(r.get(k, "-" if k == "sweep" else "none") for k in CELL_KEYS)].append(r)
    cells = []
    for key, recs in groups.items():
        n = len(recs)
        k = sum(bool(r["success"]) for r in recs)
        p = k / n
        cell = dict(zip(CELL_KEYS, key))
        cell.update(episodes=n, successes=k, success_rate=round(p, 4),
                    stderr=round(math.sqrt(p * (1 - p) / n), 4),
                    faults=sum(bool(r.get("fault")) for r in recs),
                    mean_episode_time_s=_mean([r.get("success_time_s") or r.get("sim_time_s") for r in recs]),
                    mean_wall_time_s=_mean([r.get("wall_time_s") for r in recs]),
                    mean_replans=_mean([r.get("replans") for r in recs]),
                    mean_tracking_error_rad=_mean([r.get("max_tracking_error_rad") for r in recs]),
                    max_joint_limit_violation_rad=max(r.get("max_joint_limit_violation_rad", 0.0) for r in recs),
                    max_velocity_ratio=round(max(r.get("max_velocity_ratio", 0.0) for r in recs), 4),
                    failed_seeds=sorted(r["seed"] for r in recs if not r["success"]))
        cells.append(cell)
    return cells


def detector_metrics(records: list[dict], threshold: float = 0.5) -> dict:
    """Failure-detector figures per planner from the logged (p_success, ground truth) pairs.

    auroc: over every detector call (after t_f during the episode, and on the steps after success).
    false_alarm_rate: fraction of successful episodes in which the detector judged the finished task
        not successful (p < threshold) on any post-success step, i.e. would have replanned needlessly.
    detection_latency_steps: planner steps from true success to the detector's first p >= threshold.
    """
    by_planner: dict[str, dict] = defaultdict(lambda: {"scores": [], "labels": [], "alarms": 0,
                                                       "successes": 0, "latency": []})
    for r in records:
        calls = [e for e in r.get("events", []) if e.get("kind") in ("supervisor", "detector") and "p_success" in e]
        if not calls:
            continue
        d = by_planner[r["planner"]]
        for e in calls:
            d["scores"].append(e["p_success"])
            d["labels"].append(bool(e.get("true_success")))
        post = [e for e in calls if e["kind"] == "detector"]
        if r.get("success") and post:
            d["successes"] += 1
            d["alarms"] += any(e["p_success"] < threshold for e in post)
            hits = [i for i, e in enumerate(post) if e["p_success"] >= threshold]
            if hits:
                d["latency"].append(hits[0])
    out = {}
    for planner, d in by_planner.items():
        a = auroc(d["scores"], d["labels"])
        out[planner] = {"calls": len(d["scores"]), "positives": sum(d["labels"]),
                        "auroc": None if a is None else round(a, 4),
                        "false_alarm_rate": round(d["alarms"] / d["successes"], 4) if d["successes"] else None,
                        "successful_episodes_probed": d["successes"],
                        "detection_latency_steps": _mean(d["latency"])}
    return out


