"""Do background test drives starve the live pages? Live-page latency with a crowd, idle vs while 10 models are
scrutineered, side by side.

Starts a durable moto server and the real app server (bench/_stack.py), a live race driven by a real activated timer
device and a seeded 50-racer board, and N spectators (bench/_crowd.py: N keep-alive connections polling the
leaderboard's and the overlay's live fragments with their own version tokens, as browsers do). A probe spectator polls
the leaderboard fragment at the page's own period (read from its `hx-trigger`), like one more browser; each sample
posts one strip crossing (a new fastest lap) and times POST sent -> the first poll answer that shows the lap (what a
spectator's htmx swaps in; the browser's paint, a few ms, is not included: bench/live_latency.py measures that).

For each N: an idle round, then a loaded round. The loaded round starts the scrutineering worker
(drem_local.workers.scrutineer, exactly as `drem up` runs it: niced, each drive in a bounded child), uploads 10 models
through the API (the shipped sample with its ONNX graph re-tagged so each is its own model, as 10 racers' uploads
would be) and samples until every one of them has its verdict, so every sample falls while drives run.
Goal: the live pages' goal (p95 <= 1000 ms) holds while scrutineering, at every N.

    .venv/bin/python bench/scrutineer_load.py [--spectators 100,500] [--samples 12] [--models 10]
"""
from __future__ import annotations

import argparse
import io
import multiprocessing
import os
import random
import re
import subprocess
import sys
import tarfile
import time
import urllib.request
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import _crowd, _stack  # noqa: E402

SAMPLE = _stack.ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
RACER = "lina"
FIRST_LAP_MS = 30_000
LAP_PAUSE_S = (1.0, 1.5)
WARM_UP_S = 3.0
GOAL_MS = 1000.0
SETTLED = ("passed", "failed", "cannot_scrutineer")
_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))
_LIVE = re.compile(r'<section id="(board-live|overlay-live)"[^>]*?data-version="([^"]*)"[^>]*?hx-get="([^"]+)"'
                   r'[^>]*?hx-trigger="every (\d+)(ms|s)"', re.S)


def get(url: str, headers: dict[str, str] | None = None) -> tuple[int, str]:
    request = urllib.request.Request(url, headers=headers or {})
    try:
        with _NO_PROXY.open(request, timeout=30) as reply:
            return reply.status, reply.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, ""


def live_regions(url: str, event_id: str) -> dict[str, tuple[str, str, float]]:
    """{region id: (poll path without `&v=`, version token, period s)} from the pages' own HTML."""
    found = {}
    for path in (f"/leaderboard/{event_id}", f"/overlay/{event_id}?track=1"):
        _, html = get(url + path)
        match = _LIVE.search(html)
        if not match:
            raise SystemExit(f"{path} has no polled live region (hx-get + hx-trigger every N): this bench measures "
                             "the polling pages; see bench/live_latency.py for the pages' current transport")
        region, token, poll, amount, unit = match.groups()
        base = poll.replace("&amp;", "&").rpartition("&v=")[0] or poll.replace("&amp;", "&")
        found[region] = (base, token, int(amount) / (1000 if unit == "ms" else 1))
    return found


class Probe:
    """One more spectator: polls the board's fragment at the page's period, holding its own version token."""

    def __init__(self, url: str, path: str, token: str, period_s: float) -> None:
        self.url, self.path, self.token, self.period_s = url, path, token, period_s

    def poll(self) -> str:
        status, body = get(f"{self.url}{self.path}&v={self.token}", {"HX-Request": "true"})
        if status == 200 and (found := re.search(r'data-version="([^"]+)"', body)):
            self.token = found.group(1)
        return body if status == 200 else ""

    def wait_for(self, text: str, sent_s: float, rng: random.Random, timeout_s: float = 15.0) -> float:
        time.sleep(rng.uniform(0, self.period_s))  # the crossing falls at a random point of this browser's cycle
        while time.time() - sent_s < timeout_s:
            if text in self.poll():
                return (time.time() - sent_s) * 1000
            time.sleep(self.period_s)
        return timeout_s * 1000


class Lapper:
    """Strip crossings of a timer device, each one a lap 10 ms faster than the last (a new fastest lap)."""

    def __init__(self, url: str, race: _stack.LiveRace) -> None:
        self.url, self.race = url, race
        self.device_ms, self.next_lap_ms, self.count = int(time.time() * 1000), FIRST_LAP_MS, 0
        self.post()

    def post(self) -> None:
        self.count += 1
        _stack.strip_event(self.url, self.race, self.device_ms, f"crossing-{self.count}")

    def lap(self) -> tuple[str, float]:
        lap_ms = self.next_lap_ms
        self.next_lap_ms -= 10
        self.device_ms += lap_ms
        sent = time.time()
        self.post()
        return f"{lap_ms // 60_000}:{(lap_ms % 60_000) / 1000:06.3f}", sent


def retagged_samples(count: int, start: int) -> list[bytes]:
    """`count` copies of the sample archive, each with its ONNX graph's doc string changed (a distinct model file,
    the same driving), so the duplicate check keeps every one."""
    import onnx

    with tarfile.open(SAMPLE) as tar:
        members = {m.name: tar.extractfile(m).read() for m in tar.getmembers() if m.isfile()}  # type: ignore[union-attr]
    onnx_name = next(name for name in members if name.endswith("model.onnx"))
    archives = []
    for index in range(start, start + count):
        graph = onnx.load_from_string(members[onnx_name])
        graph.doc_string = f"scrutineer load copy {index}"
        files = {**members, onnx_name: graph.SerializeToString()}
        out = io.BytesIO()
        with tarfile.open(fileobj=out, mode="w:gz") as tar:
            for name, data in files.items():
                info = tarfile.TarInfo(name)
                info.size = len(data)
                tar.addfile(info, io.BytesIO(data))
        archives.append(out.getvalue())
    return archives


def upload(url: str, storage_url: str, bearer: str, name: str, archive: bytes) -> str:
    import requests

    ticket = _stack.call(url, "POST", "/api/models", {"filename": name}, authorization=bearer)
    # The bench's app server has no /_storage gateway (drem up's has): post straight to the storage server.
    target = ticket["upload"]["url"].replace(url + "/_storage", storage_url)
    posted = requests.post(target, data=ticket["upload"]["fields"], files={"file": (name, archive)}, timeout=60)
    posted.raise_for_status()
    model_id = ticket["model"]["model_id"]
    _stack.call(url, "POST", f"/api/models/{model_id}/complete", authorization=bearer)
    return model_id


def statuses(url: str, bearer: str, model_ids: list[str]) -> list[str]:
    """The models' scrutineering states in one listing call (the bench's own requests stay few beside the crowd's)."""
    listed = _stack.call(url, "GET", "/api/models?limit=100", authorization=bearer)["models"]
    state = {m["model_id"]: m["scrutineer_status"] for m in listed}
    return [state.get(model_id, "missing") for model_id in model_ids]


def run_round(stack: _stack.BenchStack, probe: Probe, lapper: Lapper, samples: int, rng: random.Random,
              until: Any = None) -> list[float]:
    """At least `samples` laps; with `until`, on until it says the load is over (checked between laps)."""
    latencies: list[float] = []
    while len(latencies) < samples or (until is not None and not until()):
        text, sent = lapper.lap()
        latencies.append(probe.wait_for(text, sent, rng))
        time.sleep(rng.uniform(*LAP_PAUSE_S))
        if len(latencies) >= samples * 6:
            break  # the drives never finished: report what we have, the table says how many settled
    return latencies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--spectators", default="100,500")
    parser.add_argument("--samples", type=int, default=12, help="laps per round at least")
    parser.add_argument("--models", type=int, default=10, help="models scrutineered during each loaded round")
    args = parser.parse_args(argv)
    rng = random.Random(11)
    rows: list[dict[str, Any]] = []
    load_before = _stack.machine_load()
    with _stack.bench_stack() as stack:
        race = _stack.start_live_race(stack, RACER)
        _stack.seed_board(stack.env, race.event_id)
        bearer = "Bearer " + _stack.call(stack.url, "POST", "/api/auth/token", {
            "username": stack.admin_username, "password": stack.admin_password})["access_token"]
        lapper = Lapper(stack.url, race)
        regions = live_regions(stack.url, race.event_id)
        board_path, board_token, period_s = regions["board-live"]
        probe = Probe(stack.url, board_path, board_token, period_s)
        fragments = [(path, token) for path, token, _ in regions.values()]
        worker = subprocess.Popen([sys.executable, "-m", "drem_local.workers.scrutineer", "--poll-s", "0.5"],
                                  env=stack.env, stdout=subprocess.DEVNULL,
                                  stderr=open(stack.tmp / "scrutineer.log", "wb"))  # noqa: SIM115
        copies = 0
        try:
            for crowd in [int(n) for n in args.spectators.split(",")]:
                spawn = multiprocessing.get_context("spawn")
                stop, queue = spawn.Event(), spawn.Queue()
                crowd_process = spawn.Process(target=_crowd.run_crowd, args=(
                    "127.0.0.1", stack.port, fragments, crowd, period_s, stop, queue), daemon=True)
                crowd_process.start()
                time.sleep(WARM_UP_S)
                idle = run_round(stack, probe, lapper, args.samples, rng)
                archives = retagged_samples(args.models, copies)
                copies += args.models
                started = time.monotonic()
                model_ids = [upload(stack.url, stack.storage_url, bearer, f"load-{copies}-{i}.tar.gz", archive)
                             for i, archive in enumerate(archives)]
                drained: dict[str, float] = {}

                def settled(ids: list[str] = model_ids, mark: dict[str, float] = drained,
                            t0: float = started) -> bool:
                    done = all(s in SETTLED for s in statuses(stack.url, bearer, ids))
                    if done and "at" not in mark:
                        mark["at"] = time.monotonic() - t0
                    return done

                busy = run_round(stack, probe, lapper, args.samples, rng, until=settled)
                verdicts = statuses(stack.url, bearer, model_ids)
                stop.set()
                load = queue.get(timeout=60)
                crowd_process.join(30)
                rows.append({"crowd": crowd, "idle": idle, "busy": busy, "load": load, "verdicts": verdicts,
                             "drain_s": drained.get("at"), "machine_load": os.getloadavg()[0]})
                print(f"  N={crowd}: idle p95 {_stack.percentile(idle, 95):.0f} ms, while scrutineering p95 "
                      f"{_stack.percentile(busy, 95):.0f} ms", flush=True)
        finally:
            worker.terminate()
            worker.wait(30)

    print(f"\nlatency = strip crossing POST sent -> first answer of a spectator's poll (every "
          f"{period_s * 1000:.0f} ms, random phase) showing the lap; machine load before the bench: {load_before}; "
          f"{args.models} models uploaded at the start of each loaded round, sampled until all had a verdict")
    print(f"{'N':>4s} {'idle p50':>9s} {'idle p95':>9s} {'scrut p50':>10s} {'scrut p95':>10s} {'ratio p95':>9s} "
          f"{'laps':>9s} {'10 drives in':>12s} {'verdicts':>18s} {'crowd p99':>10s} {'errors':>6s} {'load':>5s}")
    for r in rows:
        idle, busy = r["idle"], r["busy"]
        verdicts = ",".join(f"{v}:{r['verdicts'].count(v)}" for v in sorted(set(r["verdicts"])))
        drain = f"{r['drain_s']:.0f} s" if r["drain_s"] is not None else "not done"
        print(f"{r['crowd']:4d} {_stack.percentile(idle, 50):7.0f}ms {_stack.percentile(idle, 95):7.0f}ms "
              f"{_stack.percentile(busy, 50):8.0f}ms {_stack.percentile(busy, 95):8.0f}ms "
              f"{_stack.percentile(busy, 95) / max(_stack.percentile(idle, 95), 1):8.2f}x "
              f"{len(idle):4d}/{len(busy):<4d} {drain:>12s} {verdicts:>18s} {r['load']['p99_ms']:8.1f}ms "
              f"{r['load']['errors'] + r['load']['other']:6d} {r['machine_load']:5.1f}")
    met = all(_stack.percentile(r["busy"], 95) <= GOAL_MS and r["drain_s"] is not None for r in rows)
    figures = " ".join(f"N={r['crowd']}:idle_p95={_stack.percentile(r['idle'], 95):.0f}ms,"
                       f"scrutineering_p95={_stack.percentile(r['busy'], 95):.0f}ms,"
                       f"ratio={_stack.percentile(r['busy'], 95) / max(_stack.percentile(r['idle'], 95), 1):.2f}x"
                       for r in rows)
    print(f"RESULT scrutineer_load: {figures} | goal p95<={GOAL_MS:.0f}ms while {args.models} models are "
          f"scrutineered | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
