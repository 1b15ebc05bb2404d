"""Does the car's camera on the stream cost what matters? One car streaming 15 fps to 500 overlay viewers.

Starts a durable moto server, the live server (drem_live) and the app (bench/_stack.py), an event with a live race
whose car is a sim car activated as a real device, and runs that sim car's drive loop (the camera, pilot, safety and
actuator parts, and the camera tap the relay reads) at 15 Hz for the whole run, in a process of its own
(bench/_car_stand_in.py), with the car's video relay (drem_cars.video_relay: 480×360 JPEG at 15 fps, the sim's rendered
frames, its own child process of the car's, as `drem car run` starts it) running throughout. Two halves, side by side
in one run, alternating in rounds (5 by default; the order swapped every round, each round's laps at the same pauses in
both halves), so a change in the shared machine's load falls on both alike:

- without video: nobody watches the car, so its relay sends nothing; the stream overlay (no car's eye) is open in
  headless Chromium;
- with video: 500 MJPEG viewers watch the racing car (bench/_mjpeg_crowd.py, one asyncio child process, the URL the
  overlay's car's eye reads), so the relay sends to the live server, and the overlay with the car's eye is open in
  Chromium.

Where things run (bench/_placement.py), the same in both halves: at a venue the car and the 500 phones are other
machines than the event laptop, so on this 2-core machine the laptop's processes (storage, live server, app) are
pinned to core 1, the car's (its drive loop and its relay) to core 0, and the viewers' stand-in
runs SCHED_IDLE (only on CPU time neither wants) on the laptop's core, and so does Chromium, the OBS PC's stand-in:
unplaced, the viewers' reading and the browser's decoding of the car's eye ran on the car's core between the drive
loop's ticks, a cost no venue has (the car, the phones and the OBS PC are separate machines); on the laptop's core
they make the laptop's share of lap-to-screen heavier than a venue's. This process (the timer, the browser driver)
is not placed. Other engineers' work on
the shared machine is not placed either: say the load.

In each half: lap-to-screen (a timer's strip crossing → the lap painted in the overlay; bench/live_latency.py's
observer and clock calibration), with the part of it until the lap was in the overlay's DOM (the rest is the page's
paint) and how long the app took to answer the crossing (the lap stored and the boards published), and the car loop's
jitter (how late each 15 Hz tick started). With video also:
glass-to-glass in the page (the frame's taken time → painted by car_eye.js, its data-delay-ms, sampled on each painted
frame), the viewers' arrival delay, and stalls (> 1 s without a frame at a viewer; printed beside how long the viewers'
stand-in itself got no CPU, as at SCHED_IDLE on a busy shared machine it may starve).
Goal (issue #35): glass-to-glass p95 ≤ 300 ms, 0 stalls > 1 s, lap-to-screen p95 and loop jitter p99 within 1.1× of
the run without video.

    .venv/bin/python bench/car_video.py [--samples 15] [--rounds 5] [--viewers 500]
"""
from __future__ import annotations

import argparse
import contextlib
import multiprocessing
import os
import random
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import _car_stand_in, _mjpeg_crowd, _placement, _stack  # noqa: E402
from bench.live_latency import CHROMIUM, CHROMIUM_ARGS, OBSERVER_JS, Lapper, clock_offset_ms, sample_round  # noqa: E402

CAR = "bench-car"
DELAYS_JS = """() => {
  window.__delays = [];
  const eye = document.querySelector('[data-car-eye]');
  new MutationObserver(() => { window.__delays.push(Number(eye.dataset.delayMs)); })
    .observe(eye, {attributes: true, attributeFilter: ['data-frames']});
}"""


def racing_car(stack: _stack.BenchStack) -> tuple[_stack.LiveRace, str]:
    """A live race (bench/_stack.py) and a car device, activated like any car, named as the race's car."""
    race = _stack.start_live_race(stack)
    bearer = "Bearer " + _stack.call(stack.url, "POST", "/api/auth/token", {
        "username": stack.admin_username, "password": stack.admin_password})["access_token"]
    fleet = _stack.call(stack.url, "POST", "/api/fleets", {"name": "Cars"}, authorization=bearer)
    code = _stack.call(stack.url, "POST", "/api/devices/activation-codes", {
        "fleet_id": fleet["fleet_id"], "hostname": CAR, "device_kind": "car"}, authorization=bearer)["code"]
    credential = _stack.call(stack.url, "POST", "/api/devices/activate", {
        "code": code, "hostname": CAR, "device_kind": "car"})["credential"]
    # The started race of start_live_race names no car: this one is submitted and a second race names the car.
    path = f"/api/events/{race.event_id}/races/{race.race_id}/commands"
    for kind in ("end", "submit"):
        _stack.call(stack.url, "POST", path, {"kind": kind}, authorization=bearer)
    second = _stack.call(stack.url, "POST", f"/api/events/{race.event_id}/races",
                         {"track_id": "1", "racer_username": "lina", "car": CAR}, authorization=bearer)
    _stack.call(stack.url, "POST", f"/api/events/{race.event_id}/races/{second['race_id']}/commands",
                {"kind": "start"}, authorization=bearer)
    return _stack.LiveRace(race.event_id, second["race_id"], race.timer_credential), credential


def overlay(browser: Any, stack: _stack.BenchStack, event_id: str, car_eye: bool) -> tuple[Any, float]:
    page = browser.new_context(viewport={"width": 1920, "height": 1080}).new_page()
    obs_pc_idle()  # the new page's renderer too
    page.goto(f"{stack.url}/overlay/{event_id}?trackId=1{'&carEye=true' if car_eye else ''}")
    page.locator("[data-testid=lower-third]").wait_for()
    page.evaluate(OBSERVER_JS)
    return page, clock_offset_ms(page)[0]


def obs_pc_idle() -> None:
    """Chromium (the OBS PC's stand-in) and every process it started, SCHED_IDLE and off the car's core
    (bench/_placement.py)."""
    if _placement.two_cores():
        for pid in _placement.processes_running(Path(CHROMIUM).name, os.getpid()):
            _placement.idle(pid)
            _placement.pin(pid, _placement.STAND_IN_CORES)


def place(stack: _stack.BenchStack, car_pid: int) -> str:
    """The laptop's processes on one core, the car's on the other (bench/_placement.py); the same for both halves."""
    if not _placement.two_cores():
        return "no placement (fewer than 2 cores): everything competes"
    for pid in (stack.storage_pid, stack.live_pid, stack.app_pid):
        _placement.pin(pid, _placement.LAPTOP_CORES)
    _placement.pin(car_pid, _placement.CAR_CORES)
    return _placement.describe()


def _stop_car(process: Any) -> None:
    """Whatever happened, the car's stand-in and its relay end with the bench (its relay ends with it by itself)."""
    if process.is_alive():
        process.terminate()
    process.join(10)


def ask(car: Any, *command: Any) -> Any:
    car.send(command)
    return car.recv()


class Half:
    """What one half (with or without video) measured over all its rounds."""

    def __init__(self, name: str) -> None:
        self.name, self.laps, self.jitter, self.painted = name, [], [], []  # type: ignore[var-annotated]
        # sample_round's breakdown: "overlay" (crossing -> in its DOM), "acknowledged" (crossing -> the app's answer)
        self.breakdown: dict[str, list[float]] = {}
        self.sent, self.skipped, self.seconds = 0, 0, 0.0
        self.crowd: dict[str, Any] = {"connected": [], "frames": 0, "stalls": 0, "max_gap_s": 0.0, "delays_ms": [],
                                      "errors": [], "starved_s": 0.0}

    def add_crowd(self, stats: dict[str, Any]) -> None:
        crowd = self.crowd
        crowd["connected"].append(stats["connected"])
        for key in ("frames", "stalls", "delays_ms", "errors"):
            crowd[key] += stats[key]
        for key in ("max_gap_s", "starved_s"):
            crowd[key] = max(crowd[key], stats[key])

    def row(self) -> str:
        in_dom, acked = self.breakdown.get("overlay", []), self.breakdown.get("acknowledged", [])
        return (f"{self.name:>14}: lap-to-screen p50 {_stack.percentile(self.laps, 50):.0f} ms p95 "
                f"{_stack.percentile(self.laps, 95):.0f} ms over {len(self.laps)} laps (the app's answer: p50 "
                f"{_stack.percentile(acked, 50):.0f} ms p95 {_stack.percentile(acked, 95):.0f} ms; in the page's DOM: "
                f"p50 {_stack.percentile(in_dom, 50):.0f} ms p95 {_stack.percentile(in_dom, 95):.0f} ms); "
                f"car loop jitter p99 {_stack.percentile(self.jitter, 99):.1f} ms over {len(self.jitter)} ticks")


class Bench:
    def __init__(self, stack: _stack.BenchStack, browser: Any, car: Any, race: _stack.LiveRace, viewers: int) -> None:
        self.stack, self.browser, self.car, self.race, self.viewers = stack, browser, car, race, viewers
        self.lapper = Lapper(stack.url, race)
        self.spawn = multiprocessing.get_context("spawn")

    def without_video(self, half: Half, laps: int, seed: int) -> None:
        """No viewer watches the car, so its relay (running, as on any car) sends nothing; the overlay has no car's
        eye."""
        page, offset = overlay(self.browser, self.stack, self.race.event_id, car_eye=False)
        try:
            self._laps(half, page, offset, laps, seed)
        finally:
            page.context.close()

    def with_video(self, half: Half, laps: int, seed: int) -> None:
        """The crowd of viewers and the overlay's car's eye watch the racing car: its relay sends at 15 fps."""
        stop, queue, connected = self.spawn.Event(), self.spawn.Queue(), self.spawn.Value("i", 0)
        crowd = self.spawn.Process(target=_mjpeg_crowd.run_crowd, daemon=True, args=(
            f"{self.stack.live_url}/live/video/{self.race.event_id}?track=1", self.viewers, stop, queue, connected))
        crowd.start()
        page, offset = overlay(self.browser, self.stack, self.race.event_id, car_eye=True)
        try:
            page.wait_for_function("() => Number(document.querySelector('[data-car-eye]').dataset.frames) >= 15",
                                   timeout=60_000)
            deadline = time.monotonic() + 60
            while connected.value < self.viewers and time.monotonic() < deadline:  # the crowd's spread-out arrival
                time.sleep(0.1)
            page.evaluate(DELAYS_JS)
            sent_before, skipped_before = ask(self.car, "sent")
            started = time.monotonic()
            self._laps(half, page, offset, laps, seed)
            sent, skipped = ask(self.car, "sent")
            half.sent, half.skipped = half.sent + sent - sent_before, half.skipped + skipped - skipped_before
            half.seconds += time.monotonic() - started
            half.painted += [d for d in page.evaluate("() => window.__delays") if d == d]
        finally:
            stop.set()
            half.add_crowd(queue.get(timeout=60))
            crowd.join(10)
            page.context.close()

    def _laps(self, half: Half, page: Any, offset: float, laps: int, seed: int) -> None:
        first_tick = ask(self.car, "mark")
        half.laps += sample_round({"overlay": page}, {"overlay": offset}, self.lapper, laps,
                                  random.Random(seed), half.breakdown)["overlay"]
        half.jitter += ask(self.car, "jitter", first_tick)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--samples", type=int, default=40, help="laps timed in each half")
    parser.add_argument("--rounds", type=int, default=5, help="rounds the halves alternate in")
    parser.add_argument("--viewers", type=int, default=500)
    args = parser.parse_args(argv)
    from playwright.sync_api import sync_playwright

    spawn = multiprocessing.get_context("spawn")
    without, with_video = Half("without video"), Half("with video")
    with _stack.bench_stack() as stack, sync_playwright() as playwright, contextlib.ExitStack() as stops:
        race, credential = racing_car(stack)
        car, car_end = spawn.Pipe()
        # Not a daemon: the car starts its relay as a child of its own, as `drem car run` does (stopped below).
        car_process = spawn.Process(target=_car_stand_in.run_car, args=(car_end, CAR))
        car_process.start()
        stops.callback(_stop_car, car_process)
        if not car.poll(120) or car.recv() != "driving":
            raise SystemExit("the car's stand-in did not start driving")
        ask(car, "relay", stack.live_url, credential)  # a child of the car's: it inherits the car's core
        placement = place(stack, car_process.pid)
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
        obs_pc_idle()
        bench = Bench(stack, browser, car, race, args.viewers)
        print(f"machine load before: {_stack.machine_load()}; placement: {placement}", flush=True)
        per_round = [args.samples // args.rounds + (index < args.samples % args.rounds) for index in range(args.rounds)]
        for index, laps in enumerate(per_round):
            # Alternating halves, each round's laps at the same pauses in both, the order swapped every round: a
            # change in the shared machine's load during the run falls on both halves alike.
            halves = [(bench.without_video, without), (bench.with_video, with_video)]
            for run, half in halves if index % 2 == 0 else halves[::-1]:
                run(half, laps, 35 + index)
            print(f"round {index + 1}/{args.rounds}: load {_stack.machine_load()}", flush=True)
        load = _stack.machine_load()
        ask(car, "stop")
        car_process.join(10)
        browser.close()

    stats, painted = with_video.crowd, with_video.painted
    glass_p95 = _stack.percentile(painted, 95) if painted else float("inf")
    arrive_p95 = _stack.percentile(stats["delays_ms"], 95) if stats["delays_ms"] else float("inf")
    connected = min(stats["connected"])
    for half in (without, with_video):
        print(half.row())
    print(f"video: relay sent {with_video.sent / max(1e-9, with_video.seconds):.1f} fps ({with_video.skipped} frames "
          f"skipped, latest-frame-wins); {connected}/{args.viewers} viewers (fewest in a round), {stats['frames']} "
          f"frames received, arrival p95 {arrive_p95:.0f} ms, longest gap {stats['max_gap_s']:.2f} s, "
          f"{stats['stalls']} stalls > 1 s (the viewers' stand-in itself got no CPU for up to "
          f"{stats['starved_s']:.2f} s), {len(stats['errors'])} errors {stats['errors'][:3]}; glass-to-glass painted "
          f"in the overlay: p50 {_stack.percentile(painted, 50) if painted else float('nan'):.0f} ms p95 "
          f"{glass_p95:.0f} ms ({len(painted)} frames)")
    lap_p95 = [_stack.percentile(half.laps, 95) for half in (with_video, without)]
    jitter_p99 = [_stack.percentile(half.jitter, 99) for half in (with_video, without)]
    lap_ratio = lap_p95[0] / max(1.0, lap_p95[1])
    jitter_ratio = jitter_p99[0] / max(1.0, jitter_p99[1])
    met = (glass_p95 <= 300 and stats["stalls"] == 0 and not stats["errors"] and lap_ratio <= 1.1
           and jitter_ratio <= 1.1 and connected == args.viewers)
    print(f"RESULT car_video: glass-to-glass p95 {glass_p95:.0f} ms, {stats['stalls']} stalls > 1 s, "
          f"lap-to-screen p95 {lap_p95[0]:.0f} vs {lap_p95[1]:.0f} ms ({lap_ratio:.2f}x), "
          f"loop jitter p99 {jitter_p99[0]:.1f} vs {jitter_p99[1]:.1f} ms ({jitter_ratio:.2f}x), "
          f"{args.viewers} viewers, {args.rounds} alternating rounds, load {load}, {placement} | goal glass-to-glass "
          f"p95 <= 300 ms, 0 stalls, lap-to-screen p95 and jitter p99 <= 1.1x without video | "
          f"{'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
