"""`drem sim`: list tracks, watch the demonstrator lap, record runs, evaluate a model.

Heavy imports (numpy, cv2, pymunk) happen inside the commands: `drem --help` stays fast.
"""
from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

HELP = "simulator: list tracks, demonstrator laps, drive by hand, record training runs, evaluate a model archive"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    sub = parser.add_subparsers(dest="sim_command", metavar="SIM_COMMAND")
    sub.add_parser("tracks", help="list the tracks with length, width and direction")

    demo = sub.add_parser("demo", help="the demonstrator drives laps; prints lap times")
    _track_arguments(demo)
    demo.add_argument("--laps", type=int, default=1)
    demo.add_argument("--png", type=Path, help="write a top-down map with the driven path")
    demo.add_argument("--mp4", type=Path, help="write a video of the car's camera")

    record = sub.add_parser("record", help="record demonstrator laps as a run folder for training")
    _track_arguments(record)
    record.add_argument("--laps", type=int, default=2)
    record.add_argument("--out", type=Path, default=Path("runs"), help="runs root (default ./runs)")
    record.add_argument("--noise", type=float, default=0.0, help="steering noise in degrees (varied examples)")
    record.add_argument("--upload", action="store_true",
                        help="also upload to the runs bucket of the local stack (needs AWS_ENDPOINT_URL)")

    drive = sub.add_parser("drive", help="drive the car yourself from a browser page (keyboard or gamepad) and record")
    _track_arguments(drive)
    drive.add_argument("--port", type=int, default=8765, help="port on 127.0.0.1 (default 8765)")
    drive.add_argument("--out", type=Path, default=Path("runs"), help="runs root for recordings (default ./runs)")
    drive.add_argument("--upload", action="store_true",
                       help="upload each recording to the runs bucket of the local stack when it stops "
                            "(needs AWS_ENDPOINT_URL)")

    evaluate = sub.add_parser("eval", help="drive a model archive round a track and write metrics")
    evaluate.add_argument("--model", required=True, type=Path, help="model archive (.tar.gz) or folder")
    evaluate.add_argument("--track", required=True, action="append",
                          help="track name, NAME:reverse for the other way round, or all (closed tracks); "
                               "repeat or comma-separate for a per-track report")
    evaluate.add_argument("--both-directions", action="store_true", help="drive every track both ways round")
    evaluate.add_argument("--laps", type=int, default=3)
    evaluate.add_argument("--seed", type=int, default=0)
    evaluate.add_argument("--out", type=Path, help="metrics file (*.json) or folder to write metrics.json into; "
                                                    "several tracks: a folder with metrics-<track>.json and suite.json")


def _track_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--track", default=None, help="track name or file (see `drem sim tracks`; default "
                                                      "reinvent_base when its route file is found, else drem_oval)")
    parser.add_argument("--reverse", action="store_true", help="race the track the other way round")
    parser.add_argument("--seed", type=int, default=0)


def run(args: argparse.Namespace) -> int:
    from drem_sim.tracks import TrackError

    commands = {"tracks": _tracks, "demo": _demo, "drive": _drive, "record": _record, "eval": _eval}
    command = commands.get(getattr(args, "sim_command", None) or "")
    if command is None:
        print("drem sim: choose one of " + ", ".join(commands), file=sys.stderr)
        return 2
    try:
        return command(args)
    except TrackError as error:
        print(f"drem sim: {error}", file=sys.stderr)
        return 2


def _tracks(_args: argparse.Namespace) -> int:
    from drem_sim.tracks import available_tracks, load_track

    print(f"{'track':28} {'length m':>8} {'width m':>7} {'direction':>9}")
    for name in sorted(available_tracks()):
        track = load_track(name)
        print(f"{name:28} {track.length:8.2f} {track.width:7.3f} {track.direction:>9}")
    return 0


def _demo(args: argparse.Namespace) -> int:
    from drem_sim.demonstrator import Demonstrator
    from drem_sim.env import EnvConfig, RaceEnv
    from drem_sim.tracks import default_track_name, load_track

    track = load_track(args.track or default_track_name(), reverse=args.reverse)
    env = RaceEnv(track, EnvConfig(observe=args.mp4 is not None, max_laps=args.laps,
                                   max_steps=int(args.laps * 120 * 15)))
    driver = Demonstrator(track)
    if args.mp4 is not None:
        import tempfile

        from drem_sim.render import run_video
        from drem_sim.runs import record_run

        with tempfile.TemporaryDirectory() as tmp:
            run_dir = record_run(env, lambda _obs, params: driver.act(params), Path(tmp), laps=args.laps,
                                 driver="demonstrator", seed=args.seed)
            run_video(run_dir, args.mp4)
            path = _path_of(run_dir)
        print(f"video        {args.mp4}")
    else:
        _, info = env.reset(seed=args.seed)
        params, path, done = info["params"], [], False
        while not done:
            _, params, terminated, truncated, info = env.step(driver.act(params))
            path.append((params["x"], params["y"]))
            done = terminated or truncated
    _print_laps(track.track_id, env)
    if args.png is not None:
        from drem_sim.render import save_track_png

        save_track_png(track, args.png, path)
        print(f"map          {args.png}")
    return 0 if env.whole_laps.laps_completed >= args.laps else 1  # a lap finished after a put-back is no lap


def _path_of(run_dir: Path) -> list[tuple[float, float]]:
    from drem_sim.render import run_rows

    return [(row["x"], row["y"]) for row in run_rows(run_dir)]


def _print_laps(track_id: str, env) -> None:  # noqa: ANN001 - RaceEnv, imported lazily
    """The laps that count (drem_leaderboard.laps: whole, from the line, no off-track), and what else came round."""
    whole = env.whole_laps
    times = ", ".join(f"{t:.3f}s" for t in whole.lap_times_s) or "none"
    after_put_back = env.laps - whole.laps_completed
    more = f" ({after_put_back} more finished after a put-back: not laps)" if after_put_back > 0 else ""
    print(f"{track_id}: {whole.laps_completed} lap(s), resets {env.resets}, lap times {times}{more}")


def _record(args: argparse.Namespace) -> int:
    import numpy as np

    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import RaceEnv
    from drem_sim.runs import record_run, runs_bucket_name, upload_run
    from drem_sim.tracks import default_track_name, load_track

    if args.upload and not os.environ.get("AWS_ENDPOINT_URL"):
        print("drem sim record: --upload needs AWS_ENDPOINT_URL (start the local stack with `drem up`)",
              file=sys.stderr)
        return 2
    track = load_track(args.track or default_track_name(), reverse=args.reverse)
    env = RaceEnv(track)
    driver = Demonstrator(track, DemonstratorConfig(steering_noise_deg=args.noise),
                          rng=np.random.default_rng(args.seed))
    run_dir = record_run(env, lambda _obs, params: driver.act(params), args.out, laps=args.laps,
                         driver="demonstrator", seed=args.seed)
    _print_laps(track.track_id, env)
    print(f"run          {run_dir}")
    if args.upload:
        from drem_sim.runs import default_s3_client

        print(f"uploaded     {upload_run(default_s3_client(), runs_bucket_name(), run_dir)}")
    return 0


def _drive(args: argparse.Namespace) -> int:
    from drem_sim import drive_server
    from drem_sim.runs import default_s3_client, runs_bucket_name, upload_run
    from drem_sim.tracks import default_track_name, load_track

    if args.upload and not os.environ.get("AWS_ENDPOINT_URL"):
        print("drem sim drive: --upload needs AWS_ENDPOINT_URL (start the local stack with `drem up`)", file=sys.stderr)
        return 2
    track = load_track(args.track or default_track_name(), reverse=args.reverse)
    uploader = None
    if args.upload:
        bucket = runs_bucket_name()
        uploader = lambda run_dir: upload_run(default_s3_client(), bucket, run_dir)  # noqa: E731
    try:
        server, threads = drive_server.start(track, args.out, port=args.port, uploader=uploader, seed=args.seed)
    except OSError as error:
        print(f"drem sim drive: cannot listen on 127.0.0.1:{args.port} ({error})", file=sys.stderr)
        return 2
    print(f"driving {track.track_id} at {server.url}  (Ctrl-C to stop; recordings go to {args.out})", flush=True)
    try:
        threads[1].join()
    except KeyboardInterrupt:
        pass
    finally:
        drive_server.stop(server, threads)
    last = server.session.last_run
    if last:
        print(f"last run     {last['run_dir']} ({last['frames']} frames)")
    return 0


def _eval(args: argparse.Namespace) -> int:
    try:
        from drem_sim.learn.evaluate import main_eval
    except ImportError as error:
        print(f"drem sim eval: model evaluation is not available in this build ({error})", file=sys.stderr)
        return 2
    from drem_sim.learn.track_sets import GENERATED_RANGE, split_specs

    specs = split_specs(args.track)
    one_track = specs[0] != "all" and not specs[0].endswith(":reverse") and not GENERATED_RANGE.fullmatch(specs[0])
    if len(specs) == 1 and one_track and not args.both_directions:
        args.track = specs[0]
        return int(main_eval(args) or 0)
    from drem_sim.learn.suite import main_suite

    return main_suite(args)
