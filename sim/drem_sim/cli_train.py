"""`drem train`: behaviour-clone recorded sim runs (and, with --dagger-rounds, DAgger rounds on chosen tracks)
into a DeepRacer-style ONNX model archive. Training needs the `train` extra (torch, onnx)."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "train a behaviour-cloning model from recorded sim runs and package it as a .tar.gz model archive"
TRAIN_EXTRA_HINT = ("training needs the `train` extra (torch, onnx), which `make up` does not install: "
                    "run `make install-test`, or `pip install -e '.[train]'`")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--runs", nargs="+", metavar="RUN",
                        help="run folders (runs/{track}/{date}/{run_id}), folders holding run folders, "
                             "or s3:// run prefixes")
    parser.add_argument("--out", required=True, type=Path,
                        help="output folder for the archive, ONNX, manifest and loss curve")
    parser.add_argument("--name", default="drem-bc-model", help="archive name without .tar.gz ([A-Za-z0-9_-]+)")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--learning-rate", type=float, default=1e-3)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (keep small on shared machines)")
    parser.add_argument("--no-augment", action="store_true", help="train on the frames exactly as recorded")
    parser.add_argument("--augment", default=None, metavar="LIST",
                        help="comma-separated augmentations: brightness,noise,flip,shift,blur (default "
                             "brightness,noise,flip); 'none' = --no-augment")
    parser.add_argument("--balance-steering", action="store_true",
                        help="draw each epoch's frames evenly over |steering| (3-degree bins), so a long track's "
                             "straights do not drown the few frames of its hairpins")
    parser.add_argument("--balance-cap", type=float, default=8.0, metavar="X",
                        help="with --balance-steering: a frame is drawn at most X times as often as one of the "
                             "commonest bin (default 8)")
    dagger = parser.add_argument_group("demonstrations and DAgger rounds on chosen tracks")
    dagger.add_argument("--tracks", action="append", metavar="SPEC",
                        help="train on these tracks (NAME, NAME:reverse, all, generated-1..10 for generated "
                             "tracks with hairpins; repeat or comma-separate): the demonstrator records "
                             "--demo-laps laps on each, then --dagger-rounds rounds run")
    dagger.add_argument("--both-directions", action="store_true", help="every track both ways round")
    dagger.add_argument("--hold-out", action="append", default=[], metavar="SPEC",
                        help="never train on these (a NAME holds out both directions); they are evaluated each round")
    dagger.add_argument("--dagger-rounds", type=int, default=0, help="rounds where the model drives and the "
                                                                     "demonstrator labels (default 0)")
    dagger.add_argument("--demo-laps", type=int, default=2, help="demonstrator laps per track and direction (max 10)")
    dagger.add_argument("--noise", type=float, default=6.0, help="demonstrator steering noise in degrees")
    dagger.add_argument("--drift", type=float, default=0.0, metavar="DEG",
                        help="also record recovery laps: the demonstrator's steering is pushed DEG degrees to one "
                             "side now and then, every frame labelled with its correction (default 0: none)")
    dagger.add_argument("--drift-laps", type=int, default=1, help="recovery laps per track and direction (--drift)")
    dagger.add_argument("--dagger-laps", type=int, default=1,
                        help="laps the model drives per track and direction per round")
    dagger.add_argument("--round-epochs", type=int, default=4,
                        help="epochs per DAgger round (from the previous weights)")
    dagger.add_argument("--eval-laps", type=int, default=2, help="lap attempts per held-out track after each round")


def run(args: argparse.Namespace) -> int:
    try:  # torch is imported only when training really runs: the rest of the CLI stays fast.
        import onnx  # noqa: F401
        import torch  # noqa: F401
    except ImportError as error:
        print(f"drem train: {TRAIN_EXTRA_HINT} ({error})", file=sys.stderr)
        return 2
    from drem_sim.learn.dataset import Augmentation, DatasetError, iter_run_dirs
    from drem_sim.learn.package import ArchiveError
    from drem_sim.learn.train import TrainConfig

    if not args.runs and not args.tracks:
        print("drem train: give --runs (recorded run folders) or --tracks (the demonstrator records them)",
              file=sys.stderr)
        return 2
    if args.balance_cap < 1.0:
        print("drem train: --balance-cap is at least 1 (a multiple of the commonest steering bin's weight)",
              file=sys.stderr)
        return 2
    if args.drift and not args.tracks:
        print("drem train: --drift records recovery laps on --tracks; give --tracks", file=sys.stderr)
        return 2
    if args.drift < 0 or args.drift > 30 or args.drift_laps < 0:
        print("drem train: --drift is 0..30 degrees and --drift-laps at least 0", file=sys.stderr)
        return 2
    runs: list[str | Path] = []
    for run in args.runs or []:
        path = Path(run)
        if not str(run).startswith("s3://") and path.is_dir() and not (path / "controls.jsonl").is_file():
            found = list(iter_run_dirs(path))
            if not found:
                print(f"drem train: no run folders under {path} "
                      "(record some with `drem sim record` or `drem sim drive`)")
                return 2
            runs.extend(found)
        else:
            runs.append(run)
    try:
        augmentation = Augmentation.from_names(args.augment.split(",")) if args.augment else None
    except DatasetError as error:
        print(f"drem train: {error}", file=sys.stderr)
        return 2
    no_augment = args.no_augment or (args.augment or "").strip() == "none"
    config = TrainConfig(epochs=args.epochs, seed=args.seed, batch_size=args.batch_size,
                         learning_rate=args.learning_rate, num_threads=args.threads, augment=not no_augment,
                         augmentation=augmentation, balance_steering=args.balance_steering,
                         balance_cap=args.balance_cap)
    try:
        if args.tracks:
            return _run_dagger(args, runs, config)
        from drem_sim.learn.pipeline import train_to_archive

        trained = train_to_archive(runs, args.out, args.name, config, progress=sys.stderr)
    except (DatasetError, ArchiveError) as error:
        print(f"drem train: {error}")
        return 2
    print(f"archive      {trained.archive}")
    print(f"frames       {len(trained.snapshot)} from {len(trained.snapshot.manifest['runs'])} run(s)")
    print(f"loss         train {trained.result.train_losses[-1]:.4f}"
          + (f" validation {trained.result.final_validation_loss:.4f}" if trained.result.validation_losses else ""))
    print(f"loss curve   {trained.loss_curve}")
    print(f"onnx check   max |torch - onnxruntime| = {trained.max_export_difference:.1e}")
    return 0


def _run_dagger(args: argparse.Namespace, runs: list, config) -> int:  # noqa: ANN001 - TrainConfig, lazily imported
    from drem_sim.learn.dagger import DaggerConfig, run_dagger
    from drem_sim.learn.suite import table
    from drem_sim.learn.track_sets import TrackSetError, expand, hold_out

    if not 0 <= args.demo_laps <= 10:
        print("drem train: --demo-laps is 0..10 (laps per track and direction)", file=sys.stderr)
        return 2
    try:
        kept, held = hold_out(expand(args.tracks, args.both_directions), args.hold_out, args.both_directions)
    except TrackSetError as error:
        print(f"drem train: {error}", file=sys.stderr)
        return 2
    if not kept:
        print("drem train: --hold-out leaves no track to train on", file=sys.stderr)
        return 2
    dagger = DaggerConfig(train_tracks=kept, eval_tracks=held, rounds=args.dagger_rounds, demo_laps=args.demo_laps,
                          demo_noise_deg=args.noise, dagger_laps=args.dagger_laps, first_epochs=args.epochs,
                          round_epochs=args.round_epochs, eval_laps=args.eval_laps, seed=args.seed,
                          drift_deg=args.drift, drift_laps=args.drift_laps)
    print(f"training on  {', '.join(d.label for d in kept)}")
    print(f"held out     {', '.join(d.label for d in held) or '-'}")
    reports = run_dagger(dagger, args.out, args.name, config, seed_runs=list(runs), progress=sys.stderr)
    for report in reports:
        print(f"round {report.round:<6} {report.frames} frames, train loss {report.final_train_loss:.4f}, "
              f"{report.train_seconds:.0f}s  {report.archive}")
    if reports[-1].evaluation:
        print(table(reports[-1].evaluation))
    print(f"archive      {Path(args.out) / (args.name + '.tar.gz')}")
    print(f"rounds       {Path(args.out) / 'rounds.json'} {Path(args.out) / 'rounds.png'}")
    return 0
