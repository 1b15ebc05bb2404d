"""DAgger: the model drives, the demonstrator says what it should have done, the data grows each round.

Behaviour cloning only sees the states the demonstrator visits; a model that drifts a little wide meets
frames it never learned from and drifts further. DAgger (Ross, Gordon & Bagnell 2011) closes that gap:

    round 0   the demonstrator laps every training track and direction (with steering noise) → runs;
              with `drift_deg`, recovery laps too (below); train model 0 on them
    round r   model r-1 drives every training track and direction (with probability beta_r per decision
              the demonstrator's action is executed instead, beta_r = beta · 0.5^(r-1)); every frame is
              labelled with the demonstrator's action for the state the *model* reached → more runs;
              train model r on all runs so far, starting from model r-1's weights
    each round the model is evaluated on the held-out tracks (never trained on), so the rounds show
    whether it generalises, not only whether it fits.

Recovery laps (`drift_deg` > 0): noise of a few degrees a frame averages out, so the demonstrator's runs hardly
ever show the car well off the line and pointing the wrong way, which is exactly where a model that misjudged a
hairpin finds itself. In a recovery lap the demonstrator drives, but now and then, for a fraction of a second, its
steering is pushed `drift_deg` to one side (the car's heading and line drift off), then it steers back; every
frame is labelled with the demonstrator's own action for the state the car is in, so the drifts teach the
corrections. A push is likelier where the track bends, and there it is outwards (that is where a model's mistakes
put the car: wide, facing the outer border).

A DAgger (or recovery) run folder is an ordinary run folder (driver `dagger-round-<r>` or `recovery`): its
`steering_angle`/`speed` are the demonstrator's labels and `offtrack` is false (the label did not leave the track,
the executed action may have: `executed_steering_angle`, `executed_speed` and `model_offtrack` keep what really
happened).
"""
from __future__ import annotations

import json
import sys
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from drem_sim.learn.dataset import load_snapshot
from drem_sim.learn.evaluate import EvalMetrics
from drem_sim.learn.track_sets import TrackDirection

SECONDS_PER_LAP_LIMIT = 60.0  # a collection lap slower than this is a stuck model: stop collecting there


@dataclass(frozen=True)
class DaggerConfig:
    train_tracks: Sequence[TrackDirection]
    eval_tracks: Sequence[TrackDirection] = ()
    rounds: int = 2
    demo_laps: int = 2  # demonstrator laps per training track and direction (round 0)
    demo_noise_deg: float = 6.0
    dagger_laps: int = 1  # laps the model drives per training track and direction in each DAgger round
    beta: float = 0.5  # chance that the demonstrator's action is executed in round 1 (halved every round)
    first_epochs: int = 10
    round_epochs: int = 4
    eval_laps: int = 2
    seed: int = 0
    drift_deg: float = 0.0  # > 0: round 0 also records `drift_laps` recovery laps per track and direction
    drift_laps: int = 1


@dataclass
class RoundReport:
    round: int
    archive: Path
    runs: int
    frames: int
    train_seconds: float
    final_train_loss: float
    final_validation_loss: float | None
    evaluation: list[EvalMetrics] = field(default_factory=list)

    def as_dict(self) -> dict[str, Any]:
        return {"round": self.round, "archive": str(self.archive), "runs": self.runs, "frames": self.frames,
                "train_seconds": round(self.train_seconds, 2), "final_train_loss": round(self.final_train_loss, 6),
                "final_validation_loss": (round(self.final_validation_loss, 6)
                                          if self.final_validation_loss is not None else None),
                "evaluation": [{"track": m.track, "laps_completed": m.laps_completed, "attempts": m.attempts,
                                "laps_completed_pct": m.laps_completed_pct, "completion_pct": m.completion_pct,
                                "offtrack_count": m.offtrack_count, "mean_lap_time_s": m.mean_lap_time_s}
                               for m in self.evaluation]}


def record_demonstrations(directions: Sequence[TrackDirection], root: Path, laps: int, noise_deg: float,
                          seed: int, progress: TextIO | None = None) -> list[Path]:
    """The demonstrator laps each track and direction once per `laps` (one run per lap, its own noise seed)."""
    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import RaceEnv
    from drem_sim.runs import Policy, record_run

    def _teacher_policy(teacher: Demonstrator) -> Policy:
        """The demonstrator as a run policy: it steers from the track parameters and ignores the frame."""
        return lambda _obs, params: teacher.act(params)

    runs = []
    for number, direction in enumerate(directions):
        _bar(progress, "round 0 recording", number, len(directions), direction.label)
        track = direction.load()
        for lap in range(laps):
            run_seed = seed * 1000 + number * 50 + lap + 1
            teacher = Demonstrator(track, DemonstratorConfig(steering_noise_deg=noise_deg),
                                   rng=np.random.default_rng(run_seed))
            runs.append(record_run(RaceEnv(track), _teacher_policy(teacher), root, laps=1,
                                   driver="demonstrator", seed=run_seed))
    _bar(progress, "round 0 recording", len(directions), len(directions), "done")
    return runs


DRIFT_SECONDS = (0.2, 0.7)  # how long one push lasts (uniform)
DRIFT_GAP_SECONDS = (0.6, 2.5)  # driving clean between pushes on a straight (uniform); a quarter of it in a bend


def record_recovery_laps(directions: Sequence[TrackDirection], root: Path, laps: int, drift_deg: float,
                         seed: int, progress: TextIO | None = None) -> list[Path]:
    """One recovery run of `laps` laps per track and direction: the demonstrator drives with pushes of
    `drift_deg` on its steering now and then, every frame labelled with its unpushed action (the correction)."""
    from drem_sim.demonstrator import Demonstrator
    from drem_sim.env import RaceEnv
    from drem_sim.runs import RunRecorder, whole_lap_figures

    runs = []
    for number, direction in enumerate(directions):
        _bar(progress, "round 0 recovery laps", number, len(directions), direction.label)
        track = direction.load()
        env = RaceEnv(track)
        teacher = Demonstrator(track)
        bend = teacher.curvature() > 1.0  # tighter than 1 m radius: where pushes come four times as often
        run_seed = seed * 1000 + 700 + number
        rng = np.random.default_rng(run_seed)
        recorder = RunRecorder(root, track.track_id, direction="reverse" if track.is_reversed else "forward",
                               driver="recovery", seed=run_seed, camera=env.camera.config if env.camera else None,
                               extra={"track_direction": track.direction, "decision_hz": env.config.decision_hz,
                                      "recovery": {"drift_deg": drift_deg}})
        obs, info = env.reset(seed=run_seed)
        params = info["params"]
        step = 1.0 / env.config.decision_hz
        push, push_left, gap_left = 0.0, 0.0, float(rng.uniform(*DRIFT_GAP_SECONDS))
        for _ in range(int(laps * SECONDS_PER_LAP_LIMIT * env.config.decision_hz)):
            assert obs is not None  # the env observes (its camera makes the frames)
            label = teacher.act(params)
            if push_left > 0:
                push_left -= step
            else:
                in_bend = bool(bend[int(params["closest_waypoints"][0]) % len(bend)])
                gap_left -= step * (4.0 if in_bend else 1.0)
                if gap_left <= 0:
                    # In a bend the push is outwards (against the demonstrator's steering): a car gone wide, facing
                    # the outer border with the exit out of the camera's view, is the state a model must recover
                    # from; an inward push would mostly be lost to the steering limit anyway.
                    outward = -1.0 if label["steering_angle"] > 0 else 1.0
                    push = drift_deg * (outward if in_bend else (1.0 if rng.random() < 0.5 else -1.0))
                    push_left, gap_left = float(rng.uniform(*DRIFT_SECONDS)), float(rng.uniform(*DRIFT_GAP_SECONDS))
            executed = dict(label)
            if push_left > 0:
                limit = teacher.car.max_steering_deg
                executed["steering_angle"] = max(-limit, min(limit, label["steering_angle"] + push))
            obs, params, done = _step_and_record(env, recorder, obs, params, label, executed)
            if done or env.laps >= laps:
                break
        runs.append(recorder.close(**whole_lap_figures(env)))
    _bar(progress, "round 0 recovery laps", len(directions), len(directions), "done")
    return runs


def collect_dagger_run(archive: Path, direction: TrackDirection, root: Path, laps: int, beta: float,
                       seed: int, round_number: int) -> Path:
    """The model drives (the demonstrator's action is executed with probability `beta`); frames get the
    demonstrator's labels. Off-tracks put the car back and driving goes on, so recovery states are recorded."""
    from drem_sim.demonstrator import Demonstrator
    from drem_sim.env import RaceEnv
    from drem_sim.learn.pilot import OnnxPilot
    from drem_sim.runs import RunRecorder, whole_lap_figures

    track = direction.load()
    env = RaceEnv(track)
    pilot = OnnxPilot.from_archive(archive)
    teacher = Demonstrator(track)
    rng = np.random.default_rng(seed)
    recorder = RunRecorder(root, track.track_id, direction="reverse" if track.is_reversed else "forward",
                           driver=f"dagger-round-{round_number}", seed=seed,
                           camera=env.camera.config if env.camera else None,
                           extra={"track_direction": track.direction, "decision_hz": env.config.decision_hz,
                                  "dagger": {"round": round_number, "beta": beta, "model": archive.name}})
    obs, info = env.reset(seed=seed)
    params = info["params"]
    limit = int(laps * SECONDS_PER_LAP_LIMIT * env.config.decision_hz)
    for _ in range(limit):
        assert obs is not None  # the env observes (its camera makes the frames the pilot reads)
        label = teacher.act(params)
        executed = label if rng.random() < beta else pilot.act(obs)
        obs, params, done = _step_and_record(env, recorder, obs, params, label, executed)
        if done or env.laps >= laps:
            break
    return recorder.close(**whole_lap_figures(env))


def _step_and_record(env: Any, recorder: Any, obs: Any, params: dict[str, Any], label: dict[str, float],
                     executed: dict[str, float]) -> tuple[Any, dict[str, Any], bool]:
    """Drive one step with `executed`, record the frame labelled with the demonstrator's `label`; the next
    observation and params, and whether the episode ended."""
    t_ms, lap = round(env.sim_time * 1000), env.laps
    next_obs, next_params, terminated, truncated, _info = env.step(executed)
    recorder.add_labelled(obs, label, executed, params, t_ms=t_ms, lap=lap,
                          executed_offtrack=bool(next_params["is_offtrack"]))
    return next_obs, next_params, bool(terminated or truncated)


def run_dagger(config: DaggerConfig, out_dir: Path, name: str, train_config: Any,
               seed_runs: Sequence[str | Path] = (), progress: TextIO | None = sys.stderr) -> list[RoundReport]:
    """Round 0 (demonstrations, or `seed_runs`) and `config.rounds` DAgger rounds; `out_dir/round-<r>/` holds each
    round's archive, `out_dir/<name>.tar.gz` is the last one, `out_dir/rounds.json` and `rounds.png` the story."""
    from drem_sim.learn.pipeline import train_to_archive
    from drem_sim.learn.suite import evaluate_archive

    out_dir = Path(out_dir)
    runs_root = out_dir / "runs"
    runs: list[str | Path] = list(seed_runs)
    if config.demo_laps > 0:
        _say(progress, f"round 0: demonstrator, {config.demo_laps} lap(s) on each of {len(config.train_tracks)} "
                       f"track direction(s)")
        runs += record_demonstrations(config.train_tracks, runs_root / "round-0", config.demo_laps,
                                      config.demo_noise_deg, config.seed, progress)
    if config.drift_deg > 0 and config.drift_laps > 0:
        _say(progress, f"round 0: recovery laps, {config.drift_laps} lap(s) with {config.drift_deg:g} degree pushes "
                       f"on each of {len(config.train_tracks)} track direction(s)")
        runs += record_recovery_laps(config.train_tracks, runs_root / "round-0-recovery", config.drift_laps,
                                     config.drift_deg, config.seed, progress)
    scale = load_snapshot(runs).scale  # fixed from round 0 on: later rounds' targets keep their meaning
    reports: list[RoundReport] = []
    state = None
    for round_number in range(config.rounds + 1):
        if round_number > 0:
            beta = config.beta * 0.5 ** (round_number - 1)
            _say(progress, f"round {round_number}: model drives, demonstrator labels (beta {beta:.2f})")
            previous = reports[-1].archive
            for number, direction in enumerate(config.train_tracks):
                _bar(progress, f"round {round_number} driving", number, len(config.train_tracks), direction.label)
                runs.append(collect_dagger_run(previous, direction, runs_root / f"round-{round_number}",
                                               config.dagger_laps, beta,
                                               config.seed * 1000 + round_number * 100 + number, round_number))
            _bar(progress, f"round {round_number} driving", len(config.train_tracks), len(config.train_tracks), "done")
        epochs = config.first_epochs if round_number == 0 else config.round_epochs
        lineage = {"dagger": {"round": round_number, "rounds": config.rounds,
                              "train_tracks": [d.label for d in config.train_tracks],
                              "held_out_tracks": [d.label for d in config.eval_tracks],
                              "demo_laps_per_track": config.demo_laps, "demo_noise_deg": config.demo_noise_deg,
                              "dagger_laps_per_track": config.dagger_laps, "beta": config.beta,
                              "recovery": ({"drift_deg": config.drift_deg, "laps_per_track": config.drift_laps}
                                           if config.drift_deg > 0 else None),
                              "previous_rounds": [r.as_dict() for r in reports]}}
        trained = train_to_archive(runs, out_dir / f"round-{round_number}", name,
                                   replace(train_config, epochs=epochs, seed=config.seed + round_number),
                                   progress=progress, initial_state=state, extra_lineage=lineage, scale=scale)
        state = {key: value.detach().clone() for key, value in trained.result.model.state_dict().items()}
        evaluation = evaluate_archive(trained.archive, config.eval_tracks, config.eval_laps, config.seed) \
            if config.eval_tracks and config.eval_laps > 0 else []
        report = RoundReport(round_number, trained.archive, len(runs), len(trained.snapshot),
                             trained.result.seconds, trained.result.train_losses[-1],
                             trained.result.final_validation_loss, evaluation)
        reports.append(report)
        held = ", ".join(f"{m.track} {m.laps_completed}/{m.attempts}" for m in evaluation) or "-"
        _say(progress, f"round {round_number}: {report.frames} frames, {report.train_seconds:.0f}s training; "
                       f"held out: {held}")
    final = reports[-1].archive
    (out_dir / f"{name}.tar.gz").write_bytes(final.read_bytes())
    (out_dir / "rounds.json").write_text(json.dumps([r.as_dict() for r in reports], indent=2) + "\n")
    plot_rounds(reports, out_dir / "rounds.png")
    return reports


def _bar(stream: TextIO | None, label: str, done: int, total: int, current: str) -> None:
    """One redrawn line per track: collection is minutes on a big track set, so show where it is."""
    if stream is None:
        return
    filled = int(20 * done / max(total, 1))
    end = "\n" if done >= total else ""
    stream.write(f"\r{label} [{'#' * filled}{'.' * (20 - filled)}] {done}/{total} {current:<32}{end}")
    stream.flush()


def _say(stream: TextIO | None, text: str) -> None:
    if stream is not None:
        stream.write(text + "\n")
        stream.flush()


def plot_rounds(reports: Sequence[RoundReport], path: Path, width: int = 640, height: int = 360) -> Path:
    """Held-out laps completed % per round (one line per track) and the final training loss, with OpenCV."""
    import cv2

    canvas = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 50, width - 170, 30, height - 40
    cv2.rectangle(canvas, (left, top), (right, bottom), (0, 0, 0), 1)
    count = max(len(reports), 2)

    def x_of(i: int) -> int:
        return int(left + (right - left) * i / (count - 1))

    tracks = sorted({m.track for r in reports for m in r.evaluation})
    palette = [(200, 80, 0), (0, 120, 230), (0, 160, 0), (160, 0, 160), (0, 0, 200), (120, 120, 0), (90, 90, 90)]
    for n, track in enumerate(tracks):
        colour = palette[n % len(palette)]
        points = [(x_of(i), int(bottom - (bottom - top) * m.laps_completed_pct / 100.0))
                  for i, r in enumerate(reports) for m in r.evaluation if m.track == track]
        for a, b in zip(points, points[1:], strict=False):
            cv2.line(canvas, a, b, colour, 2, cv2.LINE_AA)
        for point in points:
            cv2.circle(canvas, point, 3, colour, -1)
        cv2.putText(canvas, track[:22], (right + 8, top + 14 + 16 * n), cv2.FONT_HERSHEY_SIMPLEX, 0.4, colour, 1)
    losses = [r.final_train_loss for r in reports]
    if losses:
        peak = max(losses) * 1.05 or 1.0
        points = [(x_of(i), int(bottom - (bottom - top) * v / peak)) for i, v in enumerate(losses)]
        for a, b in zip(points, points[1:], strict=False):
            cv2.line(canvas, a, b, (0, 0, 0), 1, cv2.LINE_AA)
        cv2.putText(canvas, f"train loss (peak {peak:.3f})", (right + 8, bottom), cv2.FONT_HERSHEY_SIMPLEX, 0.4,
                    (0, 0, 0), 1)
    cv2.putText(canvas, "held-out laps completed % per DAgger round", (left, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5,
                (0, 0, 0), 1)
    cv2.putText(canvas, "100", (15, top + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    cv2.putText(canvas, "0", (30, bottom), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    for i in range(len(reports)):
        cv2.putText(canvas, str(i), (x_of(i) - 4, bottom + 16), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
    if not cv2.imwrite(str(path), canvas):
        raise OSError(f"could not write {path}")
    return path
