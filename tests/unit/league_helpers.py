"""Model exports in each real layout, built from the documented formats (deepracer-formats.md §5), for the league
tests (unit and browser). No binary fixtures: every file is written here."""
from __future__ import annotations

import io
import json
import tarfile
from pathlib import Path
from typing import Any

from chalicelib.domain.league_tracks import DREM_TRACK_LENGTHS_M

# Like deepracer-utils' sample-drfc-1-logs/model/model_metadata.json: each steering angle at 1.0 and 2.0 m/s.
DISCRETE_METADATA = {
    "action_space": [{"steering_angle": s, "speed": v, "index": 2 * i + j}
                     for i, s in enumerate((-30, -15, 0, 15, 30)) for j, v in enumerate((1.0, 2.0))],
    "sensor": ["FRONT_FACING_CAMERA"], "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    "training_algorithm": "clipped_ppo", "action_space_type": "discrete", "version": "5",
}
CONTINUOUS_SAC_METADATA = {
    "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 1.0, "high": 2.0}},
    "sensor": ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"], "neural_network": "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
    "training_algorithm": "sac", "action_space_type": "continuous", "version": "5",
}
HYPERPARAMETERS = {"batch_size": 64, "beta_entropy": 0.01, "discount_factor": 0.95, "e_greedy_value": 0.05,
                   "epsilon_steps": 10000, "exploration_type": "categorical", "loss_type": "huber", "lr": 0.0003,
                   "num_episodes_between_training": 20, "num_epochs": 10, "stack_size": 1,
                   "term_cond_avg_score": 350.0, "term_cond_max_episodes": 1000}
SIMTRACE_HEADER = ("episode,steps,X,Y,yaw,steer,throttle,action,reward,done,all_wheels_on_track,progress,"
                   "closest_waypoint,track_len,tstamp,episode_status,pause_duration\n")


def simtrace(world: str, laps: list[tuple[int, int]], *, track_len: float | None = None) -> str:
    """An evaluation sim-trace as the simapp writes it (deepracer-utils sample-drfc-1-logs/evaluation-20220709200242/
    evaluation-simtrace/0-iteration.csv): one row per step, `track_len` the track's centre-line length, `tstamp` sim
    seconds; here the first and last step of each trial, the trial lasting its `elapsed_time_in_milliseconds`."""
    length = track_len if track_len is not None else DREM_TRACK_LENGTHS_M.get(world, 30.0)
    rows, start = [], 6.978
    for episode, (ms, completion) in enumerate(laps):
        status = "lap_complete" if completion == 100 else "off_track"
        rows.append(f"{episode},1.0,3.2,0.68,0.17,-20.0,1.0,2,0.0,False,True,0.79,1,{length},{start:.3f},prepare,0.0")
        rows.append(f"{episode},200.0,3.1,0.70,0.10,0.0,2.0,5,1.0,True,{completion == 100},{completion},1,{length},"
                    f"{start + ms / 1000:.3f},{status},0.0")
        start += ms / 1000 + 0.1
    return SIMTRACE_HEADER + "\n".join(rows) + "\n"


def training_metrics(completions: list[int], *, version: bool = True) -> dict[str, Any]:
    metrics = [{"reward_score": 10 * c, "metric_time": 1_600_000_000_000 + i, "start_time": 1000 * i,
                "elapsed_time_in_milliseconds": 15000, "episode": i + 1, "trial": i % 20 + 1, "phase": "training",
                "completion_percentage": c, "episode_status": "Lap complete" if c == 100 else "Off track"}
               for i, c in enumerate(completions)]
    metrics.append({**metrics[-1], "phase": "evaluation", "completion_percentage": 100})  # not a training episode
    return {"metrics": metrics, "version": 2.0, "best_model_metric": "progress"} if version else {"metrics": metrics}


def evaluation_metrics(laps: list[tuple[int, int]], off_track: int = 0) -> dict[str, Any]:
    """`laps`: (elapsed ms, completion %) per trial."""
    return {"metrics": [{"completion_percentage": c, "metric_time": 1_600_000_100_000 + i, "start_time": 0,
                         "elapsed_time_in_milliseconds": ms, "episode_status": "Lap complete" if c == 100 else
                         "Off track", "crash_count": 0, "immobilized_count": 0,
                         "off_track_count": off_track if c == 100 else off_track + 1, "reversed_count": 0,
                         "reset_count": 0 if c == 100 else 1, "trial": i + 1} for i, (ms, c) in enumerate(laps)]}


def training_yaml(world: str, job: str = "TRAINING") -> str:
    return (f"JOB_TYPE: {job}\nWORLD_NAME: {world}\nRACE_TYPE: TIME_TRIAL\nREVERSE_DIR: false\n"
            "NUM_WORKERS: 1\nMIN_EVAL_TRIALS: 5\nBEST_MODEL_METRIC: progress\nCAR_NAME: FastCar\n")


def _write(root: Path, files: dict[str, Any]) -> Path:
    for name, content in files.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        if isinstance(content, bytes):
            path.write_bytes(content)
        elif isinstance(content, str):
            path.write_text(content)
        else:
            path.write_text(json.dumps(content, indent=2))
    return root


def console_old_export(root: Path, *, world: str, laps: list[tuple[int, int]],
                       metadata: dict | None = None, training: list[int] | None = None) -> Path:
    job = "20201020123456-AbCdEfGhIjKlMnOpQrStUv"
    return _write(root, {
        f"logs/training/training-{job}-robomaker.log":
            f"INFO: params {{'JOB_TYPE': 'TRAINING', 'WORLD_NAME': '{world}', 'RACE_TYPE': 'TIME_TRIAL'}}\n",
        f"logs/training/training-{job}-sagemaker.log": "sagemaker\n",
        f"metrics/training/training-{job}.json": training_metrics(training or [12, 40, 100, 76]),
        "metrics/evaluation/evaluation-20201021101010-XyXyXyXyXyXyXyXyXyXyXy.json": evaluation_metrics(laps),
        "sim-trace/training/training-simtrace/0-iteration.csv":
            SIMTRACE_HEADER + "1,1,0,0,0,0,0.6,2,1,False,True,1,1,17.7,0.06,in_progress,0\n",
        "sim-trace/evaluation/20201021101010-XyXyXyXyXyXyXyXyXyXyXy/evaluation-simtrace/0-iteration.csv":
            simtrace(world, laps),
        "model/model_metadata.json": metadata or DISCRETE_METADATA,
        "ip/hyperparameters.json": HYPERPARAMETERS,
    })


def console_new_export(root: Path, *, world: str, laps: list[tuple[int, int]],
                       metadata: dict | None = None) -> Path:
    stamp = "2024-05-01T10-11-12-000Z"
    return _write(root, {
        f"logs/training/{stamp}-my-model-simulation.log": f"WORLD_NAME: {world}\nRACE_TYPE: TIME_TRIAL\n",
        f"metrics/training/{stamp}-my-model/training-metrics.json": training_metrics([30, 100, 100]),
        f"metrics/evaluation/{stamp}-my-model-eval/evaluation-metrics.json": evaluation_metrics(laps),
        f"sim-trace/evaluation/{stamp}-my-model-eval/evaluation-simtrace/0-iteration.csv": simtrace(world, laps),
        "model/model_metadata.json": metadata or DISCRETE_METADATA,
        "ip/hyperparameters.json": HYPERPARAMETERS,
    })


def drfc_export(root: Path, *, world: str, laps: list[tuple[int, int]], metadata: dict | None = None,
                eval_world: str | None = None, params: bool = True) -> Path:
    """DRfC's model prefix; `params=False` as in deepracer-utils' sample-drfc-1-logs (no params YAML: the
    evaluation's sim-trace is the only track evidence)."""
    yamls = {"training_params.yaml": training_yaml(world),
             "evaluation_params.yaml": training_yaml(eval_world or world, "EVALUATION")} if params else {}
    return _write(root, {
        **yamls,
        "training-simtrace/0-iteration.csv": SIMTRACE_HEADER,
        "evaluation-20240102030405/evaluation-simtrace/0-iteration.csv": simtrace(eval_world or world, laps),
        "metrics/TrainingMetrics.json": training_metrics([5, 55, 100, 100, 88]),
        "metrics/EvaluationMetrics-20240101010101.json": evaluation_metrics([(99_000, 100)]),  # older, ignored
        "metrics/EvaluationMetrics-20240102030405.json": evaluation_metrics(laps),
        "model/model_metadata.json": metadata or CONTINUOUS_SAC_METADATA,
        "model/deepracer_checkpoints.json": {"best_checkpoint": {"name": "7_Step-1234.ckpt", "avg_eval_metric": 88,
                                                                 "time_stamp": 1.7e9},
                                             "last_checkpoint": {"name": "9_Step-1500.ckpt"}},
        "model/model_7.pb": b"\x08\x01frozen-graph-placeholder",
        "ip/hyperparameters.json": {**HYPERPARAMETERS, "sac_alpha": 0.2},
        "reward_function.py": "def reward_function(params):\n    return 1.0\n",
    })


def drem_sim_export(root: Path, *, track: str, progress: list[float], lap_times: list[float]) -> Path:
    lineage = {"created_epoch_s": 1_700_000_000, "network": "DREM_SMALL_CNN", "parameters": 123456,
               "dataset": {"runs": [{"run": "runs/a", "track_id": track, "rows": 900, "frames_used": 850}]},
               "seed": 7, "epochs_requested": 12, "epochs_run": 10, "batch_size": 32, "learning_rate": 0.001,
               "augment": True, "train_frames": 800, "validation_frames": 50,
               "train_losses": [0.9, 0.5, 0.3], "validation_losses": [1.0, 0.6, 0.4]}
    completed = [p for p in progress if p >= 100]
    metrics = {"model": "bc-1.tar.gz", "track": track, "seed": 0, "laps_requested": len(progress),
               "attempts": len(progress), "laps_completed": len(completed),
               "laps_completed_pct": 100.0 * len(completed) / len(progress),
               "completion_pct": sum(min(p, 100) for p in progress) / len(progress), "attempt_progress": progress,
               "offtrack_count": len(progress) - len(completed), "resets": len(progress) - len(completed),
               "lap_times_s": lap_times, "mean_lap_time_s": sum(lap_times) / len(lap_times) if lap_times else None,
               "best_lap_time_s": min(lap_times) if lap_times else None, "steering_jitter_deg": 1.5,
               "steps": 1000, "sim_seconds": 66.0}
    return _write(root, {"model_metadata.json": {
        "action_space": {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2.0}},
        "action_space_type": "continuous", "sensor": ["FRONT_FACING_CAMERA"], "neural_network": "DREM_SMALL_CNN",
        "training_algorithm": "behaviour_cloning", "version": "1"},
        "model.onnx": b"onnx-bytes-not-read", "training/lineage.json": lineage, "metrics.json": metrics})


def tar_gz_of(folder: Path, destination: Path, *, top: str | None = None) -> Path:
    with tarfile.open(destination, "w:gz") as archive:
        for path in sorted(folder.rglob("*")):
            if path.is_file():
                name = path.relative_to(folder).as_posix()
                archive.add(path, arcname=f"{top}/{name}" if top else name)
    return destination


def raw_tar_gz(destination: Path, members: list[tuple[tarfile.TarInfo, bytes | None]]) -> Path:
    with tarfile.open(destination, "w:gz") as archive:
        for info, data in members:
            archive.addfile(info, io.BytesIO(data) if data is not None else None)
    return destination


def console_log(world: str, metrics_key: str) -> str:
    """A console robomaker log as the simapp writes it: printenv, then the params dict, then roslaunch's summary."""
    return (f"Executing simulation-entrypoint.sh script\nMETRICS_S3_OBJECT_KEY=leaderboard/private/acct-1/metrics/"
            f"{metrics_key}\nNUMBER_OF_TRIALS=3\nWORLD_NAME={world}\n"
            f"{{'JOB_TYPE': 'EVALUATION', 'RACE_TYPE': 'TIME_TRIAL', 'WORLD_NAME': '{world}', "
            f"'NUMBER_OF_TRIALS': '3'}}\n"
            f"SUMMARY\n========\nPARAMETERS\n * /JOB_TYPE: EVALUATION\n * /WORLD_NAME: {world}\n")


def droa_log(world: str, job: str) -> str:
    """A DeepRacer-on-AWS simulation log: SageMaker's toolkit prints hyperparameters in lower case."""
    return (f"2026-03-07 12:54:56,575 sagemaker-training-toolkit INFO     Failed to parse hyperparameter world_name "
            f"value {world} to Json.\nReturning the value itself\nTraining Env:\n{{\n    \"hyperparameters\": {{\n"
            f"        \"kinesis_stream_name\": \"{job}\",\n        \"track_direction_clockwise\": true,\n"
            f"        \"world_name\": \"{world}\"\n    }}\n}}\n")


def droa_export(root: Path, *, world: str, eval_world: str, laps: list[tuple[int, int]]) -> Path:
    """DROA's layout: ISO-8601 timestamped job names, *-simulation.log, no params YAML."""
    training_job, evaluation_job = "deepracerindy-training-ACGVRmRuFNU9NkQ", "deepracerindy-evaluation-9oJ3QbS0SYm7Iag"
    return _write(root, {
        f"logs/training/2026-03-06T20:36:57.936Z-{training_job}-simulation.log": droa_log(world, training_job),
        f"logs/evaluation/2026-03-07T17:59:20.610Z-{evaluation_job}-simulation.log": droa_log(eval_world,
                                                                                           evaluation_job),
        f"metrics/training/2026-03-06T18:33:59.511Z-{training_job}.json": training_metrics([20, 100, 64]),
        f"metrics/evaluation/2026-03-07T17:52:00.898Z-{evaluation_job}.json": evaluation_metrics(laps),
        "model/model_metadata.json": DISCRETE_METADATA,
        "ip/hyperparameters.json": HYPERPARAMETERS,
    })
