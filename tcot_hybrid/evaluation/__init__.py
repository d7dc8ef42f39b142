"""``tcot eval``: tasks × planners × modes × perturbations × (robots × controllers × IK) × sweep values
× seeds, in parallel worker processes (or on a Ray cluster), resumable.

Every finished episode is appended to ``DIR/episodes.jsonl`` at once, so an interrupted evaluation
resumes where it stopped (jobs are keyed by their full config hash, the hash of the task code and the hash of
the checkpoint their planner loads, so a retrained or replaced checkpoint, or a changed oracle script, is never
credited with the old episodes). ``DIR/eval.json`` holds one cell
per task × planner × mode × perturbation × robot × controller × IK × sweep value with success rate and
standard error, plus failure-detector metrics; ``DIR/eval.md`` has the paper's tables (Table 1: per
suite success ± s.e.; Table 4: ablation of the planning modes).
"""
from tcot_hybrid.evaluation.aggregation import aggregate, auroc, detector_metrics
from tcot_hybrid.evaluation.jobs import (CELL_KEYS, Job, checkpoint_digest, make_jobs, parse_sweep, task_code_digest,
                                         with_field)
from tcot_hybrid.evaluation.reports import markdown
from tcot_hybrid.evaluation.running import DETECTOR_STEPS_AFTER_SUCCESS, evaluate, longest_first, run_job

__all__ = ["CELL_KEYS", "DETECTOR_STEPS_AFTER_SUCCESS", "Job", "aggregate", "auroc", "checkpoint_digest",
           "detector_metrics", "evaluate", "longest_first", "make_jobs", "markdown", "parse_sweep", "run_job",
           "task_code_digest", "with_field"]
