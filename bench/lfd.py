"""Learning from demonstration, end to end: 10 demonstrator laps → behaviour cloning → 20-lap evaluations.

Records 10 laps of the pure-pursuit demonstrator (5 runs of 2 laps, steering noise so the data holds
recoveries) on the training track, trains the behaviour-cloning CNN, exports and packages it, then drives the
archive through onnxruntime for 20 lap attempts on the training track and 20 on a track it never saw.
The noiseless demonstrator's own laps on both tracks are measured in the same run for the lap-time ratio.
Goals: >= 95 % of laps completed on the training track, >= 80 % on the other track, mean lap time <= 1.15x
the demonstrator's on the training track. Two CPU threads (torch.set_num_threads(2)).

    .venv/bin/python bench/lfd.py [--track reinvent_base] [--other-track reInvent2019_track] [--epochs 15]
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "2")  # before numpy/torch/onnxruntime load their thread pools

import argparse  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

GOAL_TRAIN_PCT, GOAL_OTHER_PCT, GOAL_RATIO = 95.0, 80.0, 1.15
RUNS, LAPS_PER_RUN, NOISE_DEG = 5, 2, 6.0  # 6 deg noise: enough recoveries to generalise (3 deg: 50 % on the other track)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--track", default="reinvent_base")
    parser.add_argument("--other-track", default="reInvent2019_track")
    parser.add_argument("--epochs", type=int, default=15)
    parser.add_argument("--eval-laps", type=int, default=20)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise", type=float, default=NOISE_DEG, help="demonstrator steering noise, degrees")
    parser.add_argument("--keep", type=Path, help="keep runs and model in this folder (default: a temporary one)")
    args = parser.parse_args()

    import numpy as np
    import torch

    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import EnvConfig, RaceEnv
    from drem_sim.learn.evaluate import drive, evaluate_model
    from drem_sim.learn.pipeline import train_to_archive
    from drem_sim.learn.train import TrainConfig
    from drem_sim.runs import record_run
    from drem_sim.tracks import load_track

    torch.set_num_threads(2)
    started = time.monotonic()
    work = args.keep or Path(tempfile.mkdtemp(prefix="drem-lfd-"))
    track = load_track(args.track)

    run_dirs = []
    for number in range(RUNS):
        seed = args.seed + number + 1
        teacher = Demonstrator(track, DemonstratorConfig(steering_noise_deg=args.noise), rng=np.random.default_rng(seed))
        run_dirs.append(record_run(RaceEnv(track), lambda _obs, params, t=teacher: t.act(params), work / "runs",
                                   laps=LAPS_PER_RUN, driver="demonstrator", seed=seed))
    recorded = time.monotonic()

    config = TrainConfig(epochs=args.epochs, seed=args.seed, num_threads=2)
    trained = train_to_archive(run_dirs, work / "model", "lfd-bench", config, progress=None)
    train_seconds = time.monotonic() - recorded

    def demonstrator_laps(name: str):  # noqa: ANN202 - EvalMetrics
        demo_track = load_track(name)
        teacher = Demonstrator(demo_track)
        return drive(RaceEnv(demo_track, EnvConfig(observe=False)), lambda _obs, params: teacher.act(params),
                     5, args.seed, "demonstrator", name)

    rows = []
    for name in (args.track, args.other_track):
        model = evaluate_model(trained.archive, name, args.eval_laps, args.seed)
        rows.append((name, model, demonstrator_laps(name)))
    total = time.monotonic() - started

    frames = len(trained.snapshot)
    print(f"demonstration: {RUNS * LAPS_PER_RUN} laps on {args.track} ({frames} on-track frames, noise {args.noise} deg), "
          f"recorded in {recorded - started:.1f}s")
    print(f"training:      {trained.result.epochs_run} epochs, {train_seconds:.1f}s on 2 threads, final train loss "
          f"{trained.result.train_losses[-1]:.4f}, validation {trained.result.final_validation_loss or 0:.4f}, "
          f"archive {trained.archive.stat().st_size / 1e6:.2f} MB")
    print(f"{'track':24} {'driver':14} {'laps':>7} {'completed':>9} {'completion':>10} {'off-track':>9} {'mean lap':>9}")
    for name, model, demo in rows:
        for label, metrics in (("model", model), ("demonstrator", demo)):
            mean = f"{metrics.mean_lap_time_s:.2f}s" if metrics.mean_lap_time_s is not None else "-"
            print(f"{name:24} {label:14} {metrics.laps_completed:>3}/{metrics.attempts:<3} "
                  f"{metrics.laps_completed_pct:>8.0f}% {metrics.completion_pct:>9.1f}% {metrics.offtrack_count:>9} {mean:>9}")
    train_model, train_demo = rows[0][1], rows[0][2]
    other_model = rows[1][1]
    ratio = (train_model.mean_lap_time_s / train_demo.mean_lap_time_s
             if train_model.mean_lap_time_s and train_demo.mean_lap_time_s else float("inf"))
    print(f"total {total:.1f}s")
    met = (train_model.laps_completed_pct >= GOAL_TRAIN_PCT and other_model.laps_completed_pct >= GOAL_OTHER_PCT
           and ratio <= GOAL_RATIO)
    print(f"RESULT lfd: train_track={train_model.laps_completed_pct:.0f}% other_track={other_model.laps_completed_pct:.0f}% "
          f"laptime_ratio={ratio:.2f}x | goal >=95% >=80% <=1.15x | {'met' if met else 'not met'}")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
