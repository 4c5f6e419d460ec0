"""Chapter 11 — the capstone: cascading failures, monitoring, graceful degradation (part A).

Oracles: the rules the exercises state, applied to generated ground truth — metric streams built
from scripted episodes (11.5), fault scenarios with known alert intervals (11.6), faulty runs with a
known first deviating stage (11.7) — and the lesson's own figures (11.1-11.4).

Modules: `questions` (11.1-11.4), `monitor` (11.5), `degradation` (11.6), `rootcause` (11.7), `hybrid`
(11.8, the hybrid switch), `remount` (11.9, DEBUG the right camera shifted), `sync` (11.10,
DEBUG a loose sync cable), `design` (11.14, the compute
budget; 11.15-11.16, the monitor's thresholds and each alert's action), `frontier` (11.17, a learned model of normal flags an
overconfident learned stage), `demo`
(the notebook's drawings and the widget's runs: a sensor fault, one stage faulted in isolation), `autorun` (the
widget's drive with scheduled faults through the pipeline, the monitor and the degradation machine), `pipeline` (part B: the course's own stages from graders.oracles, or the
learner's, run on `corridor.rig_sequence`'s faulted stereo sequence, with per-stage metrics and the fault x
stage table). `lens` (11.11, DEBUG a dirty lens), `sky` (11.12, DEBUG the sky saturates), `exposure` (11.13, DEBUG a firmware exposure change), `proof` (11.9-11.13's fix applied to the pipeline: clean / faulty /
fixed stage metrics against the table's line). Importing the package registers the chapter; the names
below are the API of the notebook and the tests.
"""
from __future__ import annotations

from . import design, questions  # noqa: F401 (registers 11.1-11.4, 11.14-11.16)
from .frontier import confidence_run, gt_confidence_flags, scipy_confidence_flags
from .lens import gt_smudge, smudge_error, smudge_problem
from .sky import FAST_RADIUS, cv_sky_rows, sky_problem
from .exposure import cv_exposure_change, exposure_error, exposure_problem
from .hybrid import chain as chain_motions
from .hybrid import gt_hybrid_choice, gt_hybrid_odometry, hybrid_run
from .remount import gt_fix_right_mount, remount_problem, repaired_rows
from .sync import depth_error, gt_sync_offset, sync_problem
from .degradation import COMPONENT_OF, MODES, fault_scenario, gt_degradation_modes
from .demo import (PIPELINE, STAGE_FAULTS, alert_states, cascade_curves, cascade_run, draw_cascade, draw_cascade_run,
                   draw_stage_run, severity_params, stage_run)
from .autorun import DRIVE_FRAMES, MONITORED, SCHEDULES, draw_drive_run, drive_run, mode_changes
from .monitor import MONITOR_TABLE, gt_health_monitor, metric_streams
from .pipeline import (FAULTS, METRICS, STANDINS, WINDOW, fault_sequence, fault_table, format_fault_table,
                       run_pipeline)
from .proof import NOT_RESTORED, debug_inputs, format_proof, prove_fix
from .rootcause import STAGE_METRICS, STAGES, fault_run, gt_first_faulty_stage

__all__ = [
    "confidence_run", "gt_confidence_flags", "scipy_confidence_flags", "gt_smudge", "smudge_error", "smudge_problem",
    "FAST_RADIUS", "cv_sky_rows", "sky_problem", "cv_exposure_change", "exposure_error", "exposure_problem",
    "chain_motions", "gt_hybrid_choice", "gt_hybrid_odometry", "hybrid_run", "gt_fix_right_mount", "remount_problem",
    "repaired_rows", "depth_error", "gt_sync_offset", "sync_problem",
    "FAULTS", "METRICS", "STANDINS", "WINDOW", "fault_sequence", "fault_table", "format_fault_table", "run_pipeline",
    "COMPONENT_OF", "MODES", "MONITOR_TABLE", "PIPELINE", "STAGES", "STAGE_METRICS", "alert_states",
    "cascade_curves", "cascade_run", "draw_cascade", "draw_cascade_run", "severity_params", "fault_run", "fault_scenario", "gt_degradation_modes", "gt_first_faulty_stage",
    "gt_health_monitor", "metric_streams", "NOT_RESTORED", "debug_inputs", "format_proof", "prove_fix",
]
