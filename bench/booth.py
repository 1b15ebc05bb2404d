"""The learning booth: from "train" pressed to the new version AVAILABLE and scrutineered, and what training costs
live pages.

Starts a durable moto server and the real app server (bench/_stack.py) plus the booth trainer exactly as `drem up`
starts it (`python -m drem_local.workers.trainer`: the lowest priority on one core, one thread). A visitor's drive is
3 laps of `reinvent_base` at a visitor's pace (~40 s a lap, so ~1,800 frames): the demonstrator, slowed down and with
3° steering noise (the driving data a visitor would give, but repeatable). The run goes in through the booth's own
artifact API as the booth's live drive stores it (`PUT /api/runs/{id}/artifacts/frames.tar`, one object for every
frame, and `controls.jsonl`, then `finalise`).

A live race on an event with 49 seeded racers and 100 spectators (bench/_crowd.py, keep-alive, each with its own
version token) polling the leaderboard's live fragment throughout; a probe posts a lap crossing from the race's timer
and polls the same fragment every 10 ms until the lap is there: that wait is the live latency (no browser, so it is
the server's share: the poll cycle plus the render). Rounds (4 by default), each:

1. a new visitor's drive (its own noise seed) is recorded and uploaded;
2. idle: `--samples` laps timed, nothing training;
3. training: laps timed while `POST /api/training-jobs` (t0, "train pressed", the booth's 8 epochs) is downloaded,
   trained, exported, submitted, validated and scrutineered by the worker; t1 is the first moment the API shows the
   new version (v0001, v0002 …) AVAILABLE with a scrutineering result. The job's stages seen on the way are printed
   (honest progress).

Training takes ~10 s on a quiet machine, so one round times only 5-6 laps while training: a p95 of those is their
slowest lap, which one noisy lap decides (three runs of one round on the same code gave 0.82x, 1.10x and 1.25x). The
rounds alternate the two phases, so both p95s come from 20-30 laps and a change in the machine's load falls on both.

Goal: t1 - t0 <= 60 s for a 1,800-frame drive, every round (on a quiet 2-core machine: say the load with the figure);
live-latency p95 while training <= 1.2x idle at 100 spectators.
Self-contained on purpose (bench/live_latency.py measures in browsers and is being rewritten).

    .venv/bin/python bench/booth.py [--frames 1800] [--epochs 8] [--rounds 4] [--samples 6] [--spectators 100]
"""
from __future__ import annotations

import argparse
import multiprocessing
import random
import re
import sys
import tempfile
import time
import urllib.request
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
from bench import _crowd, _stack  # noqa: E402

TRACK = "reinvent_base"
RACER = "lina"
GOAL_TRAIN_S = 60.0
VISITOR_PACE = {"max_speed": 0.55, "min_speed": 0.35}  # m/s: a keyboard visitor's ~40 s laps
GOAL_RATIO = 1.2
PROBE_EVERY_S = 0.01  # finer than the tolerance: at 50 ms one poll more or less was 0.5x of the idle p95
LAP_PAUSE_S = (1.5, 2.5)
_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))


def put(url: str, path: str, data: bytes, bearer: str) -> None:
    request = urllib.request.Request(url + path, method="PUT", data=data, headers={
        "Authorization": bearer, "Content-Type": "application/octet-stream", "Accept": "application/json"})
    with _NO_PROXY.open(request, timeout=30) as reply:
        reply.read()


def get_text(url: str) -> str:
    request = urllib.request.Request(url, headers={"HX-Request": "true", "Accept": "text/html"})
    with _NO_PROXY.open(request, timeout=30) as reply:
        return reply.read().decode()


def visitor_run(frames: int, folder: Path, seed: int = 1) -> Path:
    import numpy as np

    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import RaceEnv
    from drem_sim.runs import record_run
    from drem_sim.tracks import load_track

    track = load_track(TRACK)
    teacher = Demonstrator(track, DemonstratorConfig(steering_noise_deg=3.0, **VISITOR_PACE),
                           rng=np.random.default_rng(seed))
    return record_run(RaceEnv(track), lambda _obs, params: teacher.act(params), folder, laps=100, driver="bench",
                      max_steps=frames)


def upload_run(url: str, bearer: str, run_dir: Path) -> tuple[str, dict[str, Any]]:
    """The run through the booth's API as the live drive stores it: create, PUT the frames (one tar) and the controls,
    finalise."""
    from drem_sim.runs import pack_frames

    run = _stack.call(url, "POST", "/api/runs", {"track_id": TRACK, "mode": "manual"}, authorization=bearer)["run"]
    put(url, f"/api/runs/{run['run_id']}/artifacts/frames.tar", pack_frames(run_dir), bearer)
    put(url, f"/api/runs/{run['run_id']}/artifacts/controls.jsonl", (run_dir / "controls.jsonl").read_bytes(), bearer)
    final = _stack.call(url, "POST", f"/api/runs/{run['run_id']}/finalise", authorization=bearer)["run"]
    return run["run_id"], final["metrics"]


class Probe:
    """Posts a new fastest lap and times until the leaderboard's live fragment shows it."""

    def __init__(self, url: str, race: _stack.LiveRace, fragment: str) -> None:
        self.url, self.race, self.fragment = url, race, fragment
        self.device_ms = int(time.time() * 1000)
        self.next_lap_ms = 30_000
        self.count = 0
        self.log: list[tuple[float, float]] = []  # (when the crossing was sent, its latency in ms)
        self._post()  # the first crossing seeds the lap clock

    def _post(self) -> dict[str, Any]:
        self.count += 1
        return _stack.strip_event(self.url, self.race, self.device_ms, f"booth-crossing-{self.count}")

    def sample(self) -> float:
        lap_ms = self.next_lap_ms
        self.next_lap_ms -= 10
        self.device_ms += lap_ms
        sent = time.perf_counter()
        reply = self._post()
        if reply.get("lap", {}).get("time_ms") != lap_ms:
            raise SystemExit(f"the crossing did not give a {lap_ms} ms lap: {reply}")
        wanted = f'data-time="{lap_ms}"'
        deadline = sent + 15
        while time.perf_counter() < deadline:
            if wanted in get_text(self.url + self.fragment):
                self.log.append((sent, (time.perf_counter() - sent) * 1000))
                return self.log[-1][1]
            time.sleep(PROBE_EVERY_S)
        raise SystemExit(f"lap {lap_ms} never showed on the leaderboard fragment")


def measure(probe: Probe, rng: random.Random, *, samples: int = 0, until: Any = None) -> list[float]:
    """`samples` laps, or (with `until`) laps until it says so, at least three."""
    latencies: list[float] = []
    while len(latencies) < max(samples, 3 if until else 0) or (until is not None and not until()):
        time.sleep(rng.uniform(*LAP_PAUSE_S))
        latencies.append(probe.sample())
    return latencies


def start_crowd(port: int, fragment: str, size: int, period_s: float) -> tuple[Any, Any, Any]:
    base, _, token = fragment.rpartition("&v=")
    spawn = multiprocessing.get_context("spawn")
    stop, queue = spawn.Event(), spawn.Queue()
    process = spawn.Process(target=_crowd.run_crowd, args=("127.0.0.1", port, [(base, token)], size, period_s,
                                                           stop, queue), daemon=True)
    process.start()
    return process, stop, queue


def stop_crowd(crowd: tuple[Any, Any, Any]) -> dict[str, Any]:
    process, stop, queue = crowd
    stop.set()
    figures = queue.get(timeout=60)
    process.join(30)
    return figures


def press_train(url: str, bearer: str, run_id: str, epochs: int, version: str) -> tuple[float, dict[str, Any], Any]:
    """POST the job (t0, "train pressed"); returns t0, what the API showed when `version` was AVAILABLE with a
    scrutineering result, and a `ready()` check that also records the job's stages as the page would show them."""
    pressed = time.perf_counter()
    job = _stack.call(url, "POST", "/api/training-jobs", {"run_ids": [run_id], "epochs": epochs},
                      authorization=bearer)["job"]
    ready: dict[str, Any] = {"stages": []}

    def check() -> bool:
        if "at" in ready:
            return True
        models = _stack.call(url, "GET", "/api/models?limit=100", authorization=bearer)["models"]
        found = [m for m in models if m["name"] == version]
        if found and found[0]["status"] == "AVAILABLE" and found[0]["scrutineer_result"]:
            ready.update(at=time.perf_counter(), model=found[0])
            return True
        state = _stack.call(url, "GET", f"/api/training-jobs/{job['job_id']}", authorization=bearer)
        shown = state["job"]["stage"] or state["job"]["status"]
        if state["job"]["stage"] == "training":
            shown = f"training: epoch {state['job']['epoch']}/{state['job']['epochs']}"
        stages = ready["stages"]
        if not stages or stages[-1][1] != shown:
            stages.append((time.perf_counter() - pressed, shown))
        if state["job"]["status"] == "FAILED":
            raise SystemExit(f"training failed: {state['job']['reason']}")
        return False

    return pressed, ready, check


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=1800, help="frames of the visitor's drive (15 a second)")
    parser.add_argument("--epochs", type=int, default=8, help="the booth's default")
    parser.add_argument("--rounds", type=int, default=4, help="idle and training phases, alternating")
    parser.add_argument("--samples", type=int, default=6, help="live-latency samples in each idle phase")
    parser.add_argument("--spectators", type=int, default=100)
    args = parser.parse_args(argv)
    from drem_local import stack as local_stack

    rng = random.Random(11)
    load_before = _stack.machine_load()
    idle: list[float] = []
    training: list[float] = []
    train_times: list[float] = []
    with _stack.bench_stack() as stack, tempfile.TemporaryDirectory(prefix="drem-booth-") as tmp:
        trainer = local_stack.spawn("booth trainer", [sys.executable, "-m", "drem_local.workers.trainer"],
                                    stack.tmp / "trainer.log", env=stack.env)
        try:
            bearer = "Bearer " + _stack.call(stack.url, "POST", "/api/auth/token", {
                "username": stack.admin_username, "password": stack.admin_password})["access_token"]
            race = _stack.start_live_race(stack, RACER)
            _stack.seed_board(stack.env, race.event_id)
            page = get_text(f"{stack.url}/leaderboard/{race.event_id}")
            tag = re.search(r'<section id="board-live"[^>]*>', page)
            if tag is None:
                raise SystemExit("the leaderboard has no live region")
            fragment = re.search(r'hx-get="([^"]+)"', tag.group(0)).group(1).replace("&amp;", "&")  # type: ignore[union-attr]
            trigger = re.search(r'hx-trigger="every (\d+)(ms|s)"', tag.group(0))
            period_s = int(trigger.group(1)) / (1000 if trigger.group(2) == "ms" else 1) if trigger else 0.5
            probe = Probe(stack.url, race, fragment.rpartition("&v=")[0] + "&v=none")
            crowd = start_crowd(stack.port, fragment, args.spectators, period_s)
            time.sleep(3.0)
            for index in range(args.rounds):
                # Each round a new visitor's drive (its own seed: Train is refused for an unchanged set of drives),
                # uploaded before the round's idle phase, so neither phase pays for it.
                started = time.perf_counter()
                run_dir = visitor_run(args.frames, Path(tmp) / f"drive-{index}", seed=index + 1)
                run_id, metrics = upload_run(stack.url, bearer, run_dir)
                print(f"round {index + 1}/{args.rounds}: the visitor's drive, {metrics['laps_completed']} laps of "
                      f"{TRACK}, {metrics['frames']} frames (recorded and uploaded in "
                      f"{time.perf_counter() - started:.1f}s)", flush=True)
                idle += measure(probe, rng, samples=args.samples)
                version = f"v{index + 1:04d}"
                pressed, ready, check = press_train(stack.url, bearer, run_id, args.epochs, version)
                training += measure(probe, rng, until=check)
                while not check():
                    time.sleep(0.5)
                train_times.append(ready["at"] - pressed)
                print("  laps while training (s after pressed: ms): " + ", ".join(
                    f"{at - pressed:.1f}: {ms:.0f}" for at, ms in probe.log if at >= pressed), flush=True)
                scrutineer = ready["model"]["scrutineer_result"]
                print(f"  train pressed -> {version} AVAILABLE and scrutineered: {train_times[-1]:.1f}s "
                      f"(scrutineering {scrutineer['verdict']}: {scrutineer['message']}); progress shown: "
                      + "; ".join(f"{at:.0f}s {stage}" for at, stage in ready["stages"]), flush=True)
                print(f"  load {_stack.machine_load()}", flush=True)
            crowd_figures = stop_crowd(crowd)
        finally:
            trainer.stop(10)
            print(f"trainer log: {trainer.log_tail(6)}", flush=True)
    idle_p95, busy_p95 = _stack.percentile(idle, 95), _stack.percentile(training, 95)
    print(f"idle:     live p50 {_stack.percentile(idle, 50):.0f} ms p95 {idle_p95:.0f} ms ({len(idle)} laps)")
    print(f"training: live p50 {_stack.percentile(training, 50):.0f} ms p95 {busy_p95:.0f} ms ({len(training)} laps; "
          f"spectators' polls p99 {crowd_figures['p99_ms']:.0f} ms over the whole run)")
    ratio = busy_p95 / idle_p95 if idle_p95 else float("inf")
    slowest = max(train_times)
    met = slowest <= GOAL_TRAIN_S and ratio <= GOAL_RATIO
    print(f"machine load before {load_before}, after {_stack.machine_load()}")
    print(f"RESULT booth: train_to_version={'/'.join(f'{t:.0f}' for t in train_times)}s frames={args.frames} "
          f"epochs={args.epochs} live_p95_idle={idle_p95:.0f}ms live_p95_training={busy_p95:.0f}ms "
          f"ratio={ratio:.2f}x rounds={args.rounds} spectators={args.spectators} | goal <={GOAL_TRAIN_S:.0f}s each, "
          f"<={GOAL_RATIO}x | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
