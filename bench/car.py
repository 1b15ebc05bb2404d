"""Car agent bench: how long a staff assignment takes to drive the car, the pilot's inference cost, loop jitter.

One run, side by side, on the real local stack (durable moto + app server on free ports in a temp dir):
- assign → loaded: a sim car (`drem car run --sim` as a subprocess: agent + 15 Hz drive loop) gets the sample model
assigned 20 times,
  alternating between two uploads of it so every assignment is a fresh pull (download, md5, unpack, swap, load);
  the time runs from the staff's `PUT /api/cars/{id}/models` answer to the first `GET` that shows `loaded`, as staff
  see it. The agent holds a request open on its assignment, and the staff's write wakes it (a push; storage is
  re-read every 5 s only for writes made elsewhere); rounds start at random phases, as staff clicks do.
- inference: `OnnxPilot.run` of the sample model over 1000 simulator camera frames (1 intra-op thread).
- loop jitter: lateness of each 15 Hz tick of the car's drive loop (sim world + camera + model + safety), measured
  in the car process while the assignments above ran (its agent threads and the model swaps share that process).
- stock car (`--stock-rounds`, 0 skips it): `drem car run --deepracer` (a subprocess) drives the tests' fake device
  console (tests/cars/fake_deepracer_console.py) whose load takes 1.5 s, with two racers' copies of the shared
  real-structure console model (../shared/deepracer-models, 23 MB). Cold: the model is on neither the laptop nor the
  car (download, verify, unpack, upload, load). Pre-uploaded: the car holds it already because it was assigned behind
  the racer before (the agent puts the next racers' models on the car while one drives), so the swap is the load.
  Both from the staff's assignment answer to the first GET that shows it `loaded`. Also each console-model upload
  → AVAILABLE (the conversion to ONNX included), as the racer waits for it.

    .venv/bin/python bench/car.py [--rounds 20] [--stock-rounds 8]
"""
from __future__ import annotations

import argparse
import ast
import os
import re
import signal
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np
import requests

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
GOAL_ASSIGN_P95_S, GOAL_INFER_P99_MS, GOAL_JITTER_P99_MS = 3.0, 1.0, 5.0
GOAL_STOCK_COLD_P95_S, GOAL_STOCK_PRELOADED_P95_S, GOAL_CONSOLE_UPLOAD_P95_S = 3.5, 2.0, 5.0
STOCK_LOAD_S = 1.5


def upload(api, name: str, data: bytes) -> str:  # type: ignore[no-untyped-def]
    ticket = api.post("/api/models", {"filename": f"{name}.tar.gz"})
    posted = requests.post(ticket["upload"]["url"], data=ticket["upload"]["fields"],
                           files={"file": (f"{name}.tar.gz", data)}, timeout=30)
    posted.raise_for_status()
    model = api.post(f"/api/models/{ticket['model']['model_id']}/complete")["model"]
    assert model["status"] == "AVAILABLE", model
    return model["model_id"]


def second_owner(api, running, username: str = "bench-rita"):  # type: ignore[no-untyped-def]
    """A racer registered through the API; its password is set at the Cognito edge (no e-mail locally)."""
    from drem_local.api_client import ApiClient
    from drem_local.bootstrap import generate_password
    from drem_local.storage_keys import load, local_client

    api.post("/api/users", {"username": username, "email": f"{username}@example.test", "country_code": "NL"})
    password = generate_password()
    local_client("cognito-idp", running.config.storage_url, load(running.config.state_dir)).admin_set_user_password(
        UserPoolId=running.outputs.user_pool_id, Username=username, Password=password, Permanent=True)
    racer = ApiClient(running.config.app_url)
    racer.sign_in(username, password)
    return racer


def measure_assignments(rounds: int) -> tuple[list[float], dict]:
    """(assign→loaded seconds per round, the car's drive-loop summary)."""
    from drem_cars.client import activate
    from drem_cars.credentials import CredentialStore
    from drem_local import stack as local_stack
    from drem_local.api_client import ApiClient
    from drem_local.bootstrap import generate_password

    with tempfile.TemporaryDirectory(prefix="drem-bench-car-") as tmp:
        config = local_stack.StackConfig(state_dir=Path(tmp) / "state", app_port=local_stack.free_port(),
                                         storage_port=local_stack.free_port())
        password = generate_password()
        running = local_stack.start_stack(config, "admin", password, timeout=60.0)
        try:
            api = ApiClient(config.app_url)
            api.sign_in("admin", password)
            data = SAMPLE.read_bytes()
            # The same file twice from one owner is refused as a duplicate: the second copy belongs to another racer.
            models = [upload(api, "bench-a", data), upload(second_owner(api, running), "bench-b", data)]
            fleet_id = api.post("/api/fleets", {"name": "bench"})["fleet_id"]
            code = api.post("/api/devices/activation-codes",
                            {"fleet_id": fleet_id, "hostname": "bench-car", "device_kind": "car"})["code"]
            car_dir = Path(tmp) / "car"
            CredentialStore(car_dir).save(activate(config.app_url, code, "bench-car"))
            device_id = CredentialStore(car_dir).load().device_id
            # The car runs as it does on a laptop: its own process (agent + 15 Hz loop), so the bench's polling
            # does not share its interpreter; it prints its loop statistics when stopped with Ctrl-C.
            car = subprocess.Popen([sys.executable, "-m", "drem_local.cli", "car", "--config-dir", str(car_dir),
                                    "run", "--sim", "--track", "reinvent_base"],
                                   stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True,
                                   env={**os.environ, "DREM_CAR_NO_REEXEC": "1", "NO_PROXY": "127.0.0.1"})
            waits = []
            rng = np.random.default_rng(7)
            try:
                for round_no in range(rounds):
                    # Staff do not click in step with the car's 2 s assignment watch: a random phase each round.
                    time.sleep(float(rng.uniform(0.0, 2.0)))
                    model_id = models[round_no % 2]
                    api.put(f"/api/cars/{device_id}/models", {"model_ids": [model_id]})
                    assigned = time.perf_counter()
                    deadline = assigned + 30
                    while time.perf_counter() < deadline:
                        rows = api.get(f"/api/cars/{device_id}/models")["assignment"]["models"]
                        if rows and rows[0]["model_id"] == model_id and (rows[0]["progress"] or {}).get(
                                "status") == "loaded":
                            break
                        time.sleep(0.02)
                    waits.append(time.perf_counter() - assigned)
            finally:
                car.send_signal(signal.SIGINT)
                printed, _ = car.communicate(timeout=30)
            summary = re.search(r"drive loop: (\{.*?\}); sim laps", printed)
            assert summary, f"the car printed no loop statistics:\n{printed}"
            loop = ast.literal_eval(summary.group(1))
            return waits, loop
        finally:
            running.stop()


def wait_loaded(api, device_id: str, model_id: str, since: float, bound_s: float = 60.0) -> float:  # type: ignore[no-untyped-def]
    """Seconds from `since` to the first GET showing `model_id` first in the car's list and `loaded`."""
    while time.perf_counter() < since + bound_s:
        rows = api.get(f"/api/cars/{device_id}/models")["assignment"]["models"]
        if rows and rows[0]["model_id"] == model_id and (rows[0]["progress"] or {}).get("status") == "loaded":
            return time.perf_counter() - since
        time.sleep(0.02)
    raise AssertionError(f"{model_id} was not loaded within {bound_s:.0f} s")


def measure_stock_car(rounds: int) -> tuple[list[float], list[float], list[float]]:
    """(cold assign→loaded s, pre-uploaded assign→loaded s, console upload→AVAILABLE s) on a fake stock car."""
    sys.path.insert(0, str(ROOT))
    from drem_cars.client import activate
    from drem_cars.credentials import CredentialStore
    from drem_local import stack as local_stack
    from drem_local.api_client import ApiClient
    from drem_local.bootstrap import generate_password
    from tests import console_fixture
    from tests.cars.fake_deepracer_console import FakeConsole

    archive = console_fixture.require_fixture().read_bytes()
    with tempfile.TemporaryDirectory(prefix="drem-bench-stock-") as tmp, \
            FakeConsole("car-password", load_seconds=STOCK_LOAD_S) as car_console:
        config = local_stack.StackConfig(state_dir=Path(tmp) / "state", app_port=local_stack.free_port(),
                                         storage_port=local_stack.free_port())
        password = generate_password()
        running = local_stack.start_stack(config, "admin", password, timeout=60.0)
        try:
            api = ApiClient(config.app_url)
            api.sign_in("admin", password)
            uploads, models = [], []
            for owner in (api, second_owner(api, running, "bench-sam")):  # one copy each: a duplicate is refused
                started = time.perf_counter()
                models.append(upload(owner, f"console-{len(models)}", archive))
                uploads.append(time.perf_counter() - started)
            fleet_id = api.post("/api/fleets", {"name": "bench-stock"})["fleet_id"]
            code = api.post("/api/devices/activation-codes",
                            {"fleet_id": fleet_id, "hostname": "bench-deepracer", "device_kind": "car"})["code"]
            car_dir = Path(tmp) / "deepracer"
            CredentialStore(car_dir).save(activate(config.app_url, code, "bench-deepracer"))
            device_id = CredentialStore(car_dir).load().device_id
            folders = {}
            for model_id in models:
                entry = api.get(f"/api/models/{model_id}")
                record = entry.get("model", entry)
                folders[model_id] = f"{record['owner_username']}-{record['name']}"
            agent = subprocess.Popen([sys.executable, "-m", "drem_local.cli", "car", "--config-dir", str(car_dir),
                                      "run", "--deepracer", car_console.url],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                     env={**os.environ, "DREM_CAR_NO_REEXEC": "1", "NO_PROXY": "127.0.0.1",
                                          "DEEPRACER_PASSWORD": "car-password"})
            cold, preloaded = [], []
            rng = np.random.default_rng(11)
            try:
                for round_no in range(rounds):
                    time.sleep(float(rng.uniform(0.0, 2.0)))  # staff clicks at any phase of the agent's work
                    model_id = models[round_no % 2]
                    with car_console.state.lock:  # on neither the car nor (only it assigned) the laptop
                        car_console.state.artifacts.pop(folders[model_id], None)
                    api.put(f"/api/cars/{device_id}/models", {"model_ids": [model_id]})
                    cold.append(wait_loaded(api, device_id, model_id, time.perf_counter()))
                first, second = models
                api.put(f"/api/cars/{device_id}/models", {"model_ids": [first, second]})
                wait_loaded(api, device_id, first, time.perf_counter())
                for round_no in range(rounds):
                    driving, following = (first, second) if round_no % 2 == 0 else (second, first)
                    deadline = time.perf_counter() + 60
                    while folders[following] not in car_console.state.artifacts:  # the next racer's, put on the car
                        assert time.perf_counter() < deadline, "the next racer's model never reached the car"
                        time.sleep(0.05)
                    time.sleep(float(rng.uniform(0.0, 2.0)))
                    api.put(f"/api/cars/{device_id}/models", {"model_ids": [following, driving]})
                    preloaded.append(wait_loaded(api, device_id, following, time.perf_counter()))
            finally:
                agent.send_signal(signal.SIGINT)
                _out, err = agent.communicate(timeout=60)
            assert "Traceback" not in err, err[-3000:]
            return cold, preloaded, uploads
        finally:
            running.stop()


def measure_inference(frames: int) -> list[float]:
    from drem_cars.parts.pilot_onnx import OnnxPilot
    from drem_cars.parts.sim_world import SimWorld

    with tempfile.TemporaryDirectory(prefix="drem-bench-model-") as tmp:
        with tarfile.open(SAMPLE) as archive:
            archive.extractall(tmp, filter="data")
        pilot = OnnxPilot(tmp)
        world = SimWorld("reinvent_base")
        images = []
        for _ in range(100):
            world.command(*pilot.run(world.render())[:2])
            world.advance()
            images.append(world.render())
        for image in images[:20]:  # warm-up
            pilot.run(image)
        timings = []
        for i in range(frames):
            timings.append(pilot.run(images[i % len(images)])[2])
        return timings


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=20)
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--stock-rounds", type=int, default=8, help="stock-car rounds of each kind (0: skip)")
    args = parser.parse_args()

    infer = np.array(measure_inference(args.frames))
    waits, loop = measure_assignments(args.rounds)
    waits_a = np.array(waits)
    assign_p50, assign_p95 = np.percentile(waits_a, [50, 95])
    infer_p50, infer_p99 = np.percentile(infer, [50, 99])
    jitter_p50, jitter_p99, loops = loop["jitter_ms_p50"], loop["jitter_ms_p99"], loop["loops"]
    frame_ms = 1000 / 15
    print(f"assign→loaded  {len(waits)} fresh pulls of {SAMPLE.name} ({SAMPLE.stat().st_size // 1024} KiB): "
          f"p50 {assign_p50:.2f} s  p95 {assign_p95:.2f} s  max {waits_a.max():.2f} s "
          f"(assignment pushed to the waiting agent)")
    print(f"inference      {len(infer)} frames: p50 {infer_p50:.3f} ms  p99 {infer_p99:.3f} ms  "
          f"= {infer_p99 / frame_ms:.1%} of a 15 Hz frame")
    print(f"loop jitter    {loops} ticks at 15 Hz during the pulls: p50 {jitter_p50:.2f} ms  p99 {jitter_p99:.2f} ms  "
          f"= {jitter_p99 / frame_ms:.1%} of a frame ({loop['overruns']} overruns)")
    print(f"machine        load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (shared: p99s include "
          f"other processes' preemption)")
    met = assign_p95 <= GOAL_ASSIGN_P95_S and infer_p99 <= GOAL_INFER_P99_MS and jitter_p99 <= GOAL_JITTER_P99_MS
    print(f"RESULT car: assign_to_loaded_p95={assign_p95:.2f}s infer_p99={infer_p99:.3f}ms "
          f"jitter_p99={jitter_p99:.2f}ms | goal <=3s <=1ms <=5ms | {'met' if met else 'not met'}")
    stock_met = True
    if args.stock_rounds > 0:
        cold, preloaded, uploads = (np.array(v) for v in measure_stock_car(args.stock_rounds))
        cold_p50, cold_p95 = np.percentile(cold, [50, 95])
        pre_p50, pre_p95 = np.percentile(preloaded, [50, 95])
        upload_p95 = float(np.percentile(uploads, 95))
        print(f"stock car      fake console, {STOCK_LOAD_S:.1f} s load: cold {len(cold)}x p50 {cold_p50:.2f} s "
              f"p95 {cold_p95:.2f} s; pre-uploaded {len(preloaded)}x p50 {pre_p50:.2f} s p95 {pre_p95:.2f} s "
              f"(= {pre_p50 / STOCK_LOAD_S:.2f}x the load)")
        print(f"console upload {len(uploads)} uploads → AVAILABLE (conversion by a spare worker started when the "
              "upload was asked for): " + ", ".join(f"{u:.2f} s" for u in uploads))
        print(f"machine        load average {os.getloadavg()[0]:.1f} after the stock-car rounds")
        stock_met = (cold_p95 <= GOAL_STOCK_COLD_P95_S and pre_p95 <= GOAL_STOCK_PRELOADED_P95_S
                     and upload_p95 <= GOAL_CONSOLE_UPLOAD_P95_S)
        print(f"RESULT stock_car: cold_p95={cold_p95:.2f}s preloaded_p95={pre_p95:.2f}s "
              f"console_upload_p95={upload_p95:.2f}s | goal <=3.5s <=2.0s <=5s | {'met' if stock_met else 'not met'}")
    return 0 if met and stock_met else 1


if __name__ == "__main__":
    sys.exit(main())
