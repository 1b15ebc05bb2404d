"""Verified league entries: how long from a racer's push (model upload + logs) to the entry ranked "verified by
drem", for a console model and a drem model, and does the public board stay fast meanwhile?

Starts a durable moto server and the real app server (bench/_stack.py) and the scrutineering worker exactly as
`drem up` runs it (niced, SCHED_IDLE, each drive in a bounded child). Each sample, as `drem league push LOGS
MODEL.tar.gz` does: upload the model through the API's presigned POST, push the packed logs naming the model, then
poll the racer's entry until it reads "verified" (the worker first scrutineers the new model on the upcoming
event's track type, then re-drives it on the board's track, 3 laps). Console model: the shallow PPO .pb of
../shared/deepracer-models (driven through drem's ONNX conversion; a bench input, never read by the product); drem
model: the shipped sample (its ONNX graph re-tagged per sample so each upload is its own model). Meanwhile a
reader GETs the public board (/api/league/{track}) back to back, in a process of its own (the bench's own work
cannot slow it through the GIL); the same reader process runs alone first (idle). The logs uploads are packed before
the clock runs. Besides the RESULT line it prints the board's latency per step of a push (model upload, logs push,
until verified) and once more after the worker stopped (the same board and entries, nothing verifying), to tell what
slows the board from what the entries cost.

Goal (issue #32): p95 of push -> ranked verified <= 60 s, and the board's GET p95 while verifying within 1.2x of
idle.

    .venv/bin/python bench/league.py [--samples 3]
"""
from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "functions"))

from bench import _stack  # noqa: E402
from bench.scrutineer_load import retagged_samples, upload  # noqa: E402

CONSOLE_ARCHIVE = _stack.ROOT.parent / "shared" / "deepracer-models" / "console-discrete-shallow-ppo" / \
    "console-discrete-shallow-ppo.tar.gz"
TRACK = "reinvent_base"
GOAL_S, GOAL_RATIO = 60.0, 1.2
DEADLINE_S = 300.0


def board_get_ms(url: str) -> float:
    started = time.perf_counter()
    status, _ = _get(url + f"/api/league/{TRACK}")
    if status != 200:
        raise SystemExit(f"the public board answered {status}")
    return (time.perf_counter() - started) * 1000


def timed_board_get(url: str) -> tuple[float, float]:
    """(when it was sent, on the machine's monotonic clock that every process shares; its latency in ms)."""
    return time.monotonic(), board_get_ms(url)


def _get(url: str) -> tuple[int, str]:
    from bench.scrutineer_load import get

    return get(url, {"Accept": "application/json"})


def logs_upload(index: int) -> bytes:
    """A console logs download (no model_metadata.json: the model brings it), its laps unfinished so the logs claim
    nothing the re-drive must match; distinct per sample (each is its own evaluation)."""
    from chalicelib.formats.league_export import pack_exports, read_export
    from tests.unit.league_helpers import console_old_export

    with tempfile.TemporaryDirectory() as folder:
        logs = console_old_export(Path(folder) / f"bench-logs-{index}", world=TRACK,
                                  laps=[(20_000 + index, 55), (21_000 + index, 60)])
        (logs / "model/model_metadata.json").unlink()
        return pack_exports([read_export(logs)])


def push(url: str, bearer: str, upload_bytes: bytes, model_id: str, name: str) -> None:
    import requests

    reply = requests.post(f"{url}/api/league/{TRACK}/submissions", data=upload_bytes, timeout=60,
                          params={"model_id": model_id, "model_name": name},
                          headers={"Authorization": bearer, "Content-Type": "application/gzip"})
    if reply.status_code != 201:
        raise SystemExit(f"push refused: {reply.status_code} {reply.text[:300]}")


def wait_verified(url: str, name: str) -> str:
    """The racer's latest submission's verification once it is no longer pending (the board then shows it)."""
    import json

    deadline = time.monotonic() + DEADLINE_S
    while time.monotonic() < deadline:
        status, body = _get(url + f"/api/league/{TRACK}/racers/admin")
        submission = json.loads(body)["submission"] if status == 200 else {}
        if submission.get("model_name") == name and submission.get("verification") != "pending":
            return str(submission["verification"])
        time.sleep(0.25)
    return "timeout"


class BoardReader:
    """The public board's reader: its own process, so what the bench itself does meanwhile (packing an upload,
    polling for the verdict) cannot hold it up through the bench's GIL. The same process reads in both phases."""

    def __init__(self, url: str) -> None:
        import multiprocessing

        context = multiprocessing.get_context("spawn")
        self._commands, theirs = context.Pipe()
        self._process = context.Process(target=_read_board, args=(url, theirs), daemon=True)
        self._process.start()

    def read(self, count: int) -> list[float]:
        """`count` GETs back to back (the idle phase)."""
        self._commands.send(count)
        return list(self._commands.recv())

    def start(self) -> None:
        """GETs back to back until `stop`."""
        self._commands.send("until stopped")

    def stop(self) -> list[tuple[float, float]]:
        """Each GET since `start`: (when it was sent, its latency in ms)."""
        self._commands.send("stop")
        return list(self._commands.recv())

    def close(self) -> None:
        self._commands.send("quit")
        self._process.join(30)


def _read_board(url: str, commands: Any) -> None:
    while (command := commands.recv()) != "quit":
        if isinstance(command, int):
            commands.send([board_get_ms(url) for _ in range(command)])
            continue
        samples = []
        while not commands.poll():
            samples.append(timed_board_get(url))
        commands.recv()  # "stop"
        commands.send(samples)


def console_archives(count: int) -> list[bytes]:
    """The console archive, `count` times (the same graph: each sample deletes the previous upload first, since the
    server refuses a racer's second copy of a model they already have)."""
    return [CONSOLE_ARCHIVE.read_bytes()] * count


def main(argv: list[str] | None = None) -> int:
    import subprocess

    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--samples", type=int, default=3, help="verified entries per model kind")
    args = parser.parse_args(argv)
    if not CONSOLE_ARCHIVE.is_file():
        raise SystemExit(f"{CONSOLE_ARCHIVE} is missing: the console model this bench drives")
    load_before = _stack.machine_load()
    timings: dict[str, list[float]] = {"console": [], "drem": []}
    outcomes: list[str] = []
    steps: list[tuple[str, float, float]] = []  # (step of a push, began, ended): the board's latency per step
    with _stack.bench_stack() as stack:
        bearer = "Bearer " + _stack.call(stack.url, "POST", "/api/auth/token", {
            "username": stack.admin_username, "password": stack.admin_password})["access_token"]
        reader = BoardReader(stack.url)
        reader.read(20)  # warm up
        idle = reader.read(200)
        worker = subprocess.Popen([sys.executable, "-m", "drem_local.workers.scrutineer", "--poll-s", "0.5"],
                                  env=stack.env, stdout=subprocess.DEVNULL,
                                  stderr=open(stack.tmp / "scrutineer.log", "wb"))  # noqa: SIM115
        try:
            models = {"console": console_archives(args.samples), "drem": retagged_samples(args.samples, 0)}
            logs = [logs_upload(index) for index in range(1, 2 * args.samples + 1)]  # packed before the clock runs
            reader.start()
            try:
                index = 0
                for sample in range(args.samples):
                    for kind in ("console", "drem"):
                        index += 1
                        name = f"bench-{kind}-{sample}"
                        started = time.monotonic()
                        model_id = upload(stack.url, stack.storage_url, bearer, f"{name}.tar.gz",
                                          models[kind][sample])
                        uploaded = time.monotonic()
                        push(stack.url, bearer, logs[index - 1], model_id, name)
                        pushed = time.monotonic()
                        outcome = wait_verified(stack.url, name)
                        steps += [(f"{kind} model upload", started, uploaded), (f"{kind} logs push", uploaded, pushed),
                                  (f"{kind} until verified", pushed, time.monotonic())]
                        timings[kind].append(time.monotonic() - started)
                        outcomes.append(outcome)
                        print(f"  {name}: {outcome} after {timings[kind][-1]:.1f} s", flush=True)
                        if kind == "console":
                            _stack.call(stack.url, "DELETE", f"/api/models/{model_id}", authorization=bearer)
            finally:
                busy_timed = reader.stop()
        finally:
            worker.terminate()
            worker.wait(30)
            # The same board, its entries shown, nothing verifying: what the entries alone cost a reader.
            quiet_again = reader.read(2000)
            reader.close()
    busy = [ms for _, ms in busy_timed]
    every = timings["console"] + timings["drem"]
    verified = sum(outcome == "verified" for outcome in outcomes)
    idle_p95, busy_p95 = _stack.percentile(idle, 95), _stack.percentile(busy, 95)
    ratio = busy_p95 / max(idle_p95, 0.001)
    print(f"\nmachine load before: {load_before}; after: {_stack.machine_load()}")
    for kind, values in timings.items():
        print(f"{kind:8s} push -> verified: p50 {_stack.percentile(values, 50):6.1f} s  "
              f"p95 {_stack.percentile(values, 95):6.1f} s  ({len(values)} samples)")
    print(f"board GET: idle p95 {idle_p95:.1f} ms ({len(idle)}), while verifying p95 {busy_p95:.1f} ms "
          f"({len(busy)}), ratio {ratio:.2f}x")
    print(f"board GET with the entries shown and nothing verifying: p50 {_stack.percentile(quiet_again, 50):.1f} ms "
          f"p95 {_stack.percentile(quiet_again, 95):.1f} ms ({len(quiet_again)})")
    print(f"board GET per step of a push (idle p50 {_stack.percentile(idle, 50):.1f} ms):")
    for step in dict.fromkeys(name for name, _, _ in steps):
        during = [ms for sent, ms in busy_timed
                  if any(name == step and began <= sent < ended for name, began, ended in steps)]
        seconds = sum(ended - began for name, began, ended in steps if name == step)
        if during:
            print(f"  {step:26s} {seconds:6.1f} s  p50 {_stack.percentile(during, 50):6.1f} ms  "
                  f"p95 {_stack.percentile(during, 95):6.1f} ms  ({len(during)} GETs)")
    met = verified == len(outcomes) and _stack.percentile(every, 95) <= GOAL_S and ratio <= GOAL_RATIO
    console_p95, drem_p95 = _stack.percentile(timings["console"], 95), _stack.percentile(timings["drem"], 95)
    print(f"RESULT league: verified={verified}/{len(outcomes)} console_p95={console_p95:.1f}s drem_p95={drem_p95:.1f}s "
          f"board_idle_p95={idle_p95:.1f}ms board_busy_p95={busy_p95:.1f}ms ratio={ratio:.2f}x "
          f"load={_stack.machine_load()} | goal every entry verified, p95 push->verified <= {GOAL_S:.0f}s, board p95 "
          f"<= {GOAL_RATIO}x idle | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
