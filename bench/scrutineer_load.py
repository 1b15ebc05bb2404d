"""Do background test drives starve the live pages? Live-page latency with a crowd, idle vs while 10 models are
scrutineered, side by side.

Starts a durable moto server, the live server (drem_live, one process per core as `drem up` runs it) and the real app
server (bench/_stack.py), a live race driven by a real activated timer device and a seeded 50-racer board, and N
spectators on the pages' own event streams (bench/_sse_crowd.py, as bench/live_latency.py: half the leaderboard's
stream, half the overlay's, each decoding its gzip stream and checking that tokens never go backwards). A probe
spectator subscribes to the leaderboard's stream like one more browser; each sample posts one strip crossing (a new
fastest lap) and times POST sent -> the pushed fragment that shows the lap arriving (the browser's swap and paint, a
few ms, are not included: bench/live_latency.py measures those in Chromium).

For each N: an idle round, then a loaded round. The loaded round starts the scrutineering worker
(drem_local.workers.scrutineer, exactly as `drem up` runs it: niced and SCHED_IDLE, each drive in a bounded child),
uploads 10 models through the API (the shipped sample with its ONNX graph re-tagged so each is its own model, as 10
racers' uploads would be) and samples until every one of them has its verdict, so every sample falls while drives run.
Goal: the live pages' goals hold while scrutineering (p95 <= 500 ms at N = 500, <= 1 s at N = 2000, as
bench/live_latency.py), every drive finishes, 0 crowd errors, 0 tokens backwards.

    .venv/bin/python bench/scrutineer_load.py [--spectators 500,2000] [--samples 12] [--models 10] [--workers N]
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
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import _sse_crowd, _stack  # noqa: E402

SAMPLE = _stack.ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
RACER = "lina"
FIRST_LAP_MS = 30_000
LAP_PAUSE_S = (1.0, 1.5)
WARM_UP_S = 3.0
GOALS_MS = {500: 500.0, 2000: 1000.0}  # bench/live_latency.py's goals
SETTLED = ("passed", "failed", "cannot_scrutineer")
_NO_PROXY = urllib.request.build_opener(urllib.request.ProxyHandler({}))
_STREAM = re.compile(r'data-live-stream="([^"]+)"')


def get(url: str, headers: dict[str, str] | None = None) -> tuple[int, str]:
    request = urllib.request.Request(url, headers=headers or {})
    try:
        with _NO_PROXY.open(request, timeout=30) as reply:
            return reply.status, reply.read().decode()
    except urllib.error.HTTPError as error:
        return error.code, ""


def live_streams(url: str, event_id: str) -> list[str]:
    """The event-stream URLs the leaderboard and the overlay pages subscribe to, from their own HTML."""
    streams = []
    for path in (f"/leaderboard/{event_id}", f"/overlay/{event_id}?track=1"):
        _, html = get(url + path)
        match = _STREAM.search(html)
        if not match:
            raise SystemExit(f"{path} names no live stream (data-live-stream): is the live server running?")
        streams.append(match.group(1).replace("&amp;", "&"))
    return streams


class StreamProbe:
    """One more spectator on the board's event stream: a reader thread notes when each pushed fragment arrives."""

    def __init__(self, stream_url: str) -> None:
        import requests

        self._arrivals: list[tuple[float, str]] = []
        self._lock = threading.Lock()
        self._closed = threading.Event()
        self._response = requests.get(stream_url, stream=True, timeout=(5, 120), proxies={"http": "", "https": ""},
                                      headers={"Accept": "text/event-stream", "Accept-Encoding": "identity"})
        if self._response.status_code != 200:
            raise SystemExit(f"{stream_url}: {self._response.status_code} {self._response.text[:200]}")
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        try:
            self._read_messages()
        except Exception:
            if not self._closed.is_set():  # closing the stream at the end ends the read with an error: expected
                raise

    def _read_messages(self) -> None:
        buffer = b""
        for chunk in self._response.iter_content(chunk_size=None):
            buffer += chunk
            while b"\n\n" in buffer:
                raw, buffer = buffer.split(b"\n\n", 1)
                lines = raw.decode().split("\n")
                if "event: fragment" in lines:
                    data = "\n".join(line[6:] for line in lines if line.startswith("data: "))
                    with self._lock:
                        self._arrivals.append((time.time(), data))

    def wait_for(self, text: str, sent_s: float, timeout_s: float = 15.0) -> float:
        while time.time() - sent_s < timeout_s:
            with self._lock:
                self._arrivals = [(at, data) for at, data in self._arrivals if at >= sent_s]
                seen = next((at for at, data in self._arrivals if text in data), None)
            if seen is not None:
                return (seen - sent_s) * 1000
            time.sleep(0.002)
        return timeout_s * 1000

    def close(self) -> None:
        self._closed.set()
        self._response.close()


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


def run_round(probe: StreamProbe, lapper: Lapper, samples: int, rng: random.Random,
              until: Any = None) -> list[float]:
    """At least `samples` laps; with `until`, on until it says the load is over (checked between laps)."""
    latencies: list[float] = []
    while len(latencies) < samples or (until is not None and not until()):
        text, sent = lapper.lap()
        latencies.append(probe.wait_for(text, sent))
        time.sleep(rng.uniform(*LAP_PAUSE_S))
        if len(latencies) >= samples * 6:
            break  # the drives never finished: report what we have, the table says how many settled
    return latencies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--spectators", default="500,2000")
    parser.add_argument("--samples", type=int, default=12, help="laps per round at least")
    parser.add_argument("--models", type=int, default=10, help="models scrutineered during each loaded round")
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1, help="live server processes")
    args = parser.parse_args(argv)
    rng = random.Random(11)
    rows: list[dict[str, Any]] = []
    load_before = _stack.machine_load()
    caps = {"DREM_LIVE_MAX_STREAMS": "100000", "DREM_LIVE_MAX_STREAMS_PER_CLIENT": "100000"}  # one client: the crowd
    with _stack.bench_stack(caps, live_workers=args.workers) as stack:
        race = _stack.start_live_race(stack, RACER)
        _stack.seed_board(stack.env, race.event_id)
        bearer = "Bearer " + _stack.call(stack.url, "POST", "/api/auth/token", {
            "username": stack.admin_username, "password": stack.admin_password})["access_token"]
        lapper = Lapper(stack.url, race)
        streams = live_streams(stack.url, race.event_id)
        probe = StreamProbe(streams[0])
        worker = subprocess.Popen([sys.executable, "-m", "drem_local.workers.scrutineer", "--poll-s", "0.5"],
                                  env=stack.env, stdout=subprocess.DEVNULL,
                                  stderr=open(stack.tmp / "scrutineer.log", "wb"))  # noqa: SIM115
        copies = 0
        try:
            for crowd in [int(n) for n in args.spectators.split(",")]:
                spawn = multiprocessing.get_context("spawn")
                stop, queue = spawn.Event(), spawn.Queue()
                crowd_process = spawn.Process(target=_sse_crowd.run_crowd, args=(streams, crowd, stop, queue),
                                              daemon=True)
                crowd_process.start()
                time.sleep(WARM_UP_S)
                idle = run_round(probe, lapper, args.samples, rng)
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

                busy = run_round(probe, lapper, args.samples, rng, until=settled)
                verdicts = statuses(stack.url, bearer, model_ids)
                stop.set()
                load = queue.get(timeout=60)
                crowd_process.join(30)
                rows.append({"crowd": crowd, "idle": idle, "busy": busy, "load": load, "verdicts": verdicts,
                             "drain_s": drained.get("at"), "machine_load": os.getloadavg()[0]})
                print(f"  N={crowd}: idle p95 {_stack.percentile(idle, 95):.0f} ms, while scrutineering p95 "
                      f"{_stack.percentile(busy, 95):.0f} ms", flush=True)
        finally:
            probe.close()
            worker.terminate()
            worker.wait(30)

    print(f"\nlatency = strip crossing POST sent -> the pushed leaderboard fragment showing the lap arriving at a "
          f"subscriber; live server: {args.workers} process(es); machine load before the bench: {load_before}; "
          f"{args.models} models uploaded at the start of each loaded round, sampled until all had a verdict")
    print(f"{'N':>5s} {'idle p50':>9s} {'idle p95':>9s} {'scrut p50':>10s} {'scrut p95':>10s} {'ratio p95':>9s} "
          f"{'laps':>9s} {'drives in':>10s} {'verdicts':>18s} {'connected':>9s} {'backwards':>9s} {'errors':>6s} "
          f"{'load':>5s}")
    for r in rows:
        idle, busy, load = r["idle"], r["busy"], r["load"]
        verdicts = ",".join(f"{v}:{r['verdicts'].count(v)}" for v in sorted(set(r["verdicts"])))
        drain = f"{r['drain_s']:.0f} s" if r["drain_s"] is not None else "not done"
        print(f"{r['crowd']:5d} {_stack.percentile(idle, 50):7.0f}ms {_stack.percentile(idle, 95):7.0f}ms "
              f"{_stack.percentile(busy, 50):8.0f}ms {_stack.percentile(busy, 95):8.0f}ms "
              f"{_stack.percentile(busy, 95) / max(_stack.percentile(idle, 95), 1):8.2f}x "
              f"{len(idle):4d}/{len(busy):<4d} {drain:>10s} {verdicts:>18s} {load['connected']:9d} "
              f"{load['backwards']:9d} {load['errors']:6d} {r['machine_load']:5.1f}")
        if load["first_error"]:
            print(f"      first crowd error: {load['first_error']}")
    met = {r["crowd"] for r in rows} >= set(GOALS_MS) and all(
        _stack.percentile(r["busy"], 95) <= GOALS_MS.get(r["crowd"], GOALS_MS[max(GOALS_MS)])
        and r["drain_s"] is not None and r["load"]["errors"] == 0 and r["load"]["backwards"] == 0
        and r["load"]["connected"] == r["crowd"] for r in rows)
    figures = " ".join(f"N={r['crowd']}:idle_p95={_stack.percentile(r['idle'], 95):.0f}ms,"
                       f"scrutineering_p95={_stack.percentile(r['busy'], 95):.0f}ms,"
                       f"ratio={_stack.percentile(r['busy'], 95) / max(_stack.percentile(r['idle'], 95), 1):.2f}x,"
                       f"drives={r['drain_s'] or 0:.0f}s,errors={r['load']['errors']},"
                       f"backwards={r['load']['backwards']}" for r in rows)
    print(f"RESULT scrutineer_load: {figures} load={_stack.machine_load()} | goal p95<=500ms at N=500 and <=1000ms "
          f"at N=2000 while {args.models} models are scrutineered, 0 errors, 0 backwards | "
          f"{'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
