"""`drem train`: behaviour-clone recorded sim runs into a DeepRacer-style ONNX model archive."""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

HELP = "train a behaviour-cloning model from recorded sim runs and package it as a .tar.gz model archive"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--runs", nargs="+", required=True, metavar="RUN",
                        help="run folders (runs/{track}/{date}/{run_id}), folders holding run folders, or s3:// run prefixes")
    parser.add_argument("--out", required=True, type=Path, help="output folder for the archive, ONNX, manifest and loss curve")
    parser.add_argument("--name", default="drem-bc-model", help="archive name without .tar.gz ([A-Za-z0-9_-]+)")
    parser.add_argument("--epochs", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch-size", type=int, default=64)
    parser.add_argument("--learning-rate", type=float, default=1e-3)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads (keep small on shared machines)")
    parser.add_argument("--no-augment", action="store_true", help="train on the frames exactly as recorded")


def run(args: argparse.Namespace) -> int:
    # torch is imported only when training really runs: the rest of the CLI stays fast.
    from drem_sim.learn.dataset import DatasetError, iter_run_dirs
    from drem_sim.learn.package import ArchiveError
    from drem_sim.learn.pipeline import train_to_archive
    from drem_sim.learn.train import TrainConfig

    runs: list[str | Path] = []
    for run in args.runs:
        path = Path(run)
        if not str(run).startswith("s3://") and path.is_dir() and not (path / "controls.jsonl").is_file():
            found = list(iter_run_dirs(path))
            if not found:
                print(f"drem train: no run folders under {path} (record some with `drem sim record` or `drem sim drive`)")
                return 2
            runs.extend(found)
        else:
            runs.append(run)
    config = TrainConfig(epochs=args.epochs, seed=args.seed, batch_size=args.batch_size,
                         learning_rate=args.learning_rate, num_threads=args.threads, augment=not args.no_augment)
    try:
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
