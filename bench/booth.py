"""The learning booth: from "train" pressed to v0001 AVAILABLE and scrutineered, and what training costs live pages.

Starts a durable moto server and the real app server (bench/_stack.py) plus the booth trainer exactly as `drem up`
starts it (`python -m drem_local.workers.trainer`: nice'd, one core, one thread). A visitor's drive is 3 laps of
`reinvent_base` at a visitor's pace (~40 s a lap, so ~1,800 frames): the demonstrator, slowed down and with 3° steering
noise (the driving data a visitor would give, but repeatable). The run goes in through the booth's own artifact API as
the booth's live drive stores it (`PUT /api/runs/{id}/artifacts/frames.tar`, one object for every frame, and
`controls.jsonl`, then `finalise`). Then:

1. idle: a live race on an event with 49 seeded racers, 100 spectators (bench/_crowd.py, keep-alive, each with its
   own version token) polling the leaderboard's live fragment; a probe posts a lap crossing from the race's timer
   and polls the same fragment every 50 ms until the lap is there: that wait is the live latency (no browser, so it
   is the server's share: the poll cycle plus the render);
2. training: the same, while `POST /api/training-jobs` (t0, "train pressed", the booth's 8 epochs) is downloaded,
   trained, exported, submitted, validated and scrutineered by the worker; t1 is the first moment the API shows v0001
   AVAILABLE with a scrutineering result. The job's stages seen on the way are printed (honest progress).

Goal: t1 - t0 <= 60 s for a 1,800-frame drive (on a quiet 2-core machine: say the load with the figure); live-latency
p95 while training <= 1.2x idle at 100 spectators.
Self-contained on purpose (bench/live_latency.py measures in browsers and is being rewritten).

    .venv/bin/python bench/booth.py [--frames 1800] [--epochs 8] [--samples 12] [--spectators 100]
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
PROBE_EVERY_S = 0.05
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


def visitor_run(frames: int, folder: Path) -> Path:
    import numpy as np

    from drem_sim.demonstrator import Demonstrator, DemonstratorConfig
    from drem_sim.env import RaceEnv
    from drem_sim.runs import record_run
    from drem_sim.tracks import load_track

    track = load_track(TRACK)
    teacher = Demonstrator(track, DemonstratorConfig(steering_noise_deg=3.0, **VISITOR_PACE),
                           rng=np.random.default_rng(1))
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
                return (time.perf_counter() - sent) * 1000
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


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=int, default=1800, help="frames of the visitor's drive (15 a second)")
    parser.add_argument("--epochs", type=int, default=8, help="the booth's default")
    parser.add_argument("--samples", type=int, default=12, help="live-latency samples while idle (at least)")
    parser.add_argument("--spectators", type=int, default=100)
    args = parser.parse_args(argv)
    from drem_local import stack as local_stack

    rng = random.Random(11)
    load_before = _stack.machine_load()
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

            started = time.perf_counter()
            run_dir = visitor_run(args.frames, Path(tmp))
            recorded_s = time.perf_counter() - started
            started = time.perf_counter()
            run_id, metrics = upload_run(stack.url, bearer, run_dir)
            upload_s = time.perf_counter() - started
            print(f"driving data: {metrics['laps_completed']} laps of {TRACK}, {metrics['frames']} frames "
                  f"(recorded {recorded_s:.1f}s, uploaded and finalised {upload_s:.1f}s)", flush=True)

            crowd = start_crowd(stack.port, fragment, args.spectators, period_s)
            time.sleep(3.0)
            idle = measure(probe, rng, samples=args.samples)
            idle_crowd = stop_crowd(crowd)
            print(f"idle:     live p50 {_stack.percentile(idle, 50):.0f} ms p95 {_stack.percentile(idle, 95):.0f} ms "
                  f"({len(idle)} laps; spectators' polls p99 {idle_crowd['p99_ms']:.0f} ms)", flush=True)

            crowd = start_crowd(stack.port, fragment, args.spectators, period_s)
            time.sleep(3.0)
            pressed = time.perf_counter()
            job = _stack.call(stack.url, "POST", "/api/training-jobs", {"run_ids": [run_id], "epochs": args.epochs},
                              authorization=bearer)["job"]
            ready: dict[str, Any] = {}
            stages: list[tuple[float, str]] = []

            def v0001_ready() -> bool:
                if "at" in ready:
                    return True
                models = _stack.call(stack.url, "GET", "/api/models?limit=100", authorization=bearer)["models"]
                found = [m for m in models if m["name"] == "v0001"]
                if found and found[0]["status"] == "AVAILABLE" and found[0]["scrutineer_result"]:
                    ready.update(at=time.perf_counter(), model=found[0])
                    return True
                state = _stack.call(stack.url, "GET", f"/api/training-jobs/{job['job_id']}", authorization=bearer)
                shown = state["job"]["stage"] or state["job"]["status"]
                if state["job"]["stage"] == "training":
                    shown = f"training: epoch {state['job']['epoch']}/{state['job']['epochs']}"
                if not stages or stages[-1][1] != shown:
                    stages.append((time.perf_counter() - pressed, shown))
                if state["job"]["status"] == "FAILED":
                    raise SystemExit(f"training failed: {state['job']['reason']}")
                return False

            training = measure(probe, rng, until=v0001_ready)
            while not v0001_ready():
                time.sleep(0.5)
            train_s = ready["at"] - pressed
            busy_crowd = stop_crowd(crowd)
            scrutineer = ready["model"]["scrutineer_result"]
            print(f"training: live p50 {_stack.percentile(training, 50):.0f} ms "
                  f"p95 {_stack.percentile(training, 95):.0f} ms ({len(training)} laps; spectators' polls p99 "
                  f"{busy_crowd['p99_ms']:.0f} ms)", flush=True)
            print("progress shown: " + "; ".join(f"{at:.0f}s {stage}" for at, stage in stages), flush=True)
            print(f"train pressed -> v0001 AVAILABLE and scrutineered: {train_s:.1f}s "
                  f"({args.epochs} epochs; scrutineering {scrutineer['verdict']}: {scrutineer['message']})", flush=True)
        finally:
            trainer.stop(10)
            print(f"trainer log: {trainer.log_tail(6)}", flush=True)
    idle_p95, busy_p95 = _stack.percentile(idle, 95), _stack.percentile(training, 95)
    ratio = busy_p95 / idle_p95 if idle_p95 else float("inf")
    met = train_s <= GOAL_TRAIN_S and ratio <= GOAL_RATIO
    print(f"machine load before {load_before}, after {_stack.machine_load()}")
    print(f"RESULT booth: train_to_v0001={train_s:.0f}s frames={metrics['frames']} "
          f"epochs={args.epochs} live_p95_idle={idle_p95:.0f}ms live_p95_training={busy_p95:.0f}ms "
          f"ratio={ratio:.2f}x spectators={args.spectators} | goal <={GOAL_TRAIN_S:.0f}s, <={GOAL_RATIO}x | "
          f"{'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
