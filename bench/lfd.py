"""Learning that generalises: demonstrations on many tracks + DAgger rounds → clean laps on held-out tracks.

The demonstrator records `--demo-laps` laps (steering noise) on every training track and direction (all closed
tracks both ways round, minus the held-out ones), `--dagger-rounds` DAgger rounds follow (the model drives, the
demonstrator labels), exactly as `drem train --tracks ... --dagger-rounds ...` does. The final archive is then
driven through onnxruntime for `--eval-laps` lap attempts on every held-out track and direction (never trained
on); a lap with an off-track is not a completed lap. The noiseless demonstrator's laps on the same tracks, timed
in the same run, give the lap-time ratio.

Goals (issue 17): on EVERY held-out track and direction >= 80 % of laps completed (no resets) and mean lap time
<= 1.15x the demonstrator's; <= 10 demonstrator laps per track plus the DAgger rounds; the whole learning
pipeline (recording, DAgger driving, training) <= 600 s on a 2-core machine (torch on 2 threads).

    .venv/bin/python bench/lfd.py                 # the goal's configuration (about 10 minutes on a quiet machine)
    .venv/bin/python bench/lfd.py --reduced       # a 2-3 minute smoke version; it can never report the goal met
    .venv/bin/python bench/lfd.py --hold-out 2024_reinvent_champ_ccw,reInvent2019_track --dagger-rounds 3
"""
from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "2")  # before numpy/torch/onnxruntime load their thread pools

import argparse  # noqa: E402
import io  # noqa: E402
import sys  # noqa: E402
import tempfile  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

GOAL_PCT, GOAL_RATIO, GOAL_SECONDS, MAX_DEMO_LAPS = 80.0, 1.15, 600.0, 10
# Held out, both directions: reInvent2019_track (23 m, wide, gentle bends), 2024_reinvent_champ_ccw (25.1 m: the
# longest of the shipped loops but for 2022_summit_speedway's 25.2 m, and narrow, 0.76 m) and drem_chicane (the
# tightest bend shipped, 0.54 m radius, narrow). Every other closed track trains.
DEFAULT_HOLD_OUT = "reInvent2019_track,2024_reinvent_champ_ccw,drem_chicane"
REDUCED = {"train_tracks": "reinvent_base,drem_chicane", "hold_out": "reInvent2019_track", "demo_laps": 1,
           "dagger_rounds": 1, "epochs": 3, "round_epochs": 1, "eval_laps": 3}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--train-tracks", default="all", help="track specs to train on (default: all closed tracks)")
    parser.add_argument("--hold-out", default=DEFAULT_HOLD_OUT, help="held-out track specs (evaluated, never trained)")
    parser.add_argument("--one-direction", action="store_true", help="only each track's own direction")
    parser.add_argument("--demo-laps", type=int, default=2)
    parser.add_argument("--noise", type=float, default=6.0, help="demonstrator steering noise, degrees")
    parser.add_argument("--dagger-rounds", type=int, default=2)
    parser.add_argument("--dagger-laps", type=int, default=1)
    parser.add_argument("--epochs", type=int, default=8)
    parser.add_argument("--round-epochs", type=int, default=3)
    parser.add_argument("--eval-laps", type=int, default=10)
    parser.add_argument("--augment", default="brightness,noise,flip,shift,blur")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--reduced", action="store_true", help="small smoke configuration; never reports the goal met")
    parser.add_argument("--keep", type=Path, help="keep runs and models in this folder (default: a temporary one)")
    args = parser.parse_args()
    if args.reduced:
        for key, value in REDUCED.items():
            setattr(args, key, value)

    import torch

    from drem_sim.demonstrator import Demonstrator
    from drem_sim.env import EnvConfig, RaceEnv
    from drem_sim.learn.dagger import DaggerConfig, run_dagger
    from drem_sim.learn.dataset import Augmentation
    from drem_sim.learn.evaluate import drive
    from drem_sim.learn.suite import evaluate_archive
    from drem_sim.learn.track_sets import expand, hold_out
    from drem_sim.learn.train import TrainConfig

    torch.set_num_threads(2)
    both = not args.one_direction
    kept, held = hold_out(expand([args.train_tracks], both), [args.hold_out], both)
    work = args.keep or Path(tempfile.mkdtemp(prefix="drem-lfd-"))
    print(f"train on     {len(kept)} track directions: {', '.join(d.label for d in kept)}")
    print(f"held out     {', '.join(d.label for d in held)}")
    print(f"data         {args.demo_laps} demonstrator laps per track direction (noise {args.noise} deg), "
          f"{args.dagger_rounds} DAgger round(s) of {args.dagger_laps} lap(s); "
          f"epochs {args.epochs}+{args.round_epochs}/round; "
          f"augment {args.augment}", flush=True)

    print(f"load         {_load()} (1, 5, 15 min) at the start", flush=True)
    started, cpu_started = time.monotonic(), time.process_time()
    config = DaggerConfig(train_tracks=kept, eval_tracks=(), rounds=args.dagger_rounds, demo_laps=args.demo_laps,
                          demo_noise_deg=args.noise, dagger_laps=args.dagger_laps, first_epochs=args.epochs,
                          round_epochs=args.round_epochs, eval_laps=0, seed=args.seed)
    train = TrainConfig(seed=args.seed, num_threads=2, augmentation=Augmentation.from_names(args.augment.split(",")))
    reports = run_dagger(config, work, "lfd-bench", train, progress=io.StringIO())
    pipeline_seconds = time.monotonic() - started
    # CPU seconds of all this process's threads: on a loaded shared machine the wall time mostly measures the
    # others; CPU / 2 is what two quiet cores could at best bring the pipeline down to (torch runs 2 threads).
    pipeline_cpu = time.process_time() - cpu_started
    train_seconds = sum(r.train_seconds for r in reports)
    for r in reports:
        print(f"round {r.round}: {r.frames} frames, train loss {r.final_train_loss:.4f}, "
              f"{r.train_seconds:.0f}s training")
    print(f"pipeline     {pipeline_seconds:.0f}s (training {train_seconds:.0f}s, recording and DAgger driving "
          f"{pipeline_seconds - train_seconds:.0f}s); load {_load()} at its end; CPU {pipeline_cpu:.0f}s "
          f"(>= {pipeline_cpu / 2:.0f}s wall on 2 quiet cores)", flush=True)

    models = evaluate_archive(work / "lfd-bench.tar.gz", held, args.eval_laps, args.seed)
    print(f"{'held-out track':<30} {'model laps':>10} {'done %':>7} {'progress':>9} {'off':>4} {'model lap':>10} "
          f"{'demo lap':>9} {'ratio':>6}")
    worst_pct, worst_ratio = 100.0, 0.0
    for direction, model in zip(held, models, strict=True):
        teacher = Demonstrator(direction.load())
        # As many attempts as the model's, so both means hold the same share of standing-start laps.
        demo = drive(RaceEnv(direction.load(), EnvConfig(observe=False)), lambda _o, p, t=teacher: t.act(p),
                     args.eval_laps, args.seed, "demonstrator", direction.label)
        ratio = (model.mean_lap_time_s / demo.mean_lap_time_s
                 if model.mean_lap_time_s and demo.mean_lap_time_s else float("inf"))
        worst_pct, worst_ratio = min(worst_pct, model.laps_completed_pct), max(worst_ratio, ratio)
        model_lap = f"{model.mean_lap_time_s:.2f}s" if model.mean_lap_time_s else "-"
        demo_lap = f"{demo.mean_lap_time_s:.2f}s" if demo.mean_lap_time_s else "-"
        print(f"{direction.label:<30} {model.laps_completed:>4}/{model.attempts:<5} {model.laps_completed_pct:>6.0f}% "
              f"{model.completion_pct:>8.1f}% {model.offtrack_count:>4} {model_lap:>10} {demo_lap:>9} {ratio:>5.2f}x")
    print(f"total        {time.monotonic() - started:.0f}s")
    goal_config = (not args.reduced and args.demo_laps <= MAX_DEMO_LAPS and args.eval_laps >= 10
                   and args.train_tracks == "all" and both
                   and {d.name for d in held} >= set(DEFAULT_HOLD_OUT.split(",")))  # the long and the tight one
    met = (goal_config and worst_pct >= GOAL_PCT and worst_ratio <= GOAL_RATIO
           and pipeline_seconds <= GOAL_SECONDS)
    label = "lfd" if goal_config else "lfd (reduced configuration: cannot meet the goal)"
    print(f"RESULT {label}: worst_heldout_completed={worst_pct:.0f}% worst_laptime_ratio={worst_ratio:.2f}x "
          f"pipeline={pipeline_seconds:.0f}s pipeline_cpu={pipeline_cpu:.0f}s held_out={len(held)} load={_load()} "
          f"| goal >=80% each, <=1.15x, <=600s | {'met' if met else 'not met'}")
    return 0 if met else 1


def _load() -> str:
    """The machine's load averages: a shared machine's training time means little without them."""
    return "/".join(f"{value:.1f}" for value in os.getloadavg())


if __name__ == "__main__":
    sys.exit(main())
