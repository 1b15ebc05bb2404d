"""How fast `drem up` is ready, and what the write-ahead journal costs per write.

Measured in one run, side by side:
- cold `drem up` (fresh state dir) until /healthz first answers 200,
- `drem up` again on the state it left (snapshot load + bootstrap finding everything in place),
- PutItem latency (median / p95 over 300) through the durable server (journal + SigV4 verification) vs a plain
  `moto_server` subprocess.
Goal: up <= 5 s, restart <= 5 s, durable/plain PutItem median ratio <= 1.4 (journal + SigV4 verification; issue 12).
"""
from __future__ import annotations

import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import boto3
from botocore.config import Config

from drem_local.stack import REGION, StackConfig, free_port, http_get, read_stack_file
from drem_local.storage_keys import StorageKeys
from drem_local.storage_keys import generate as generate_keys
from drem_local.storage_keys import load as load_keys

PUTS = 300
WARMUP = 30
GOALS = {"up": 5.0, "restart": 5.0, "ratio": 1.4}


def time_drem_up(state_dir: Path, app_port: int, storage_port: int) -> tuple[float, subprocess.Popen]:
    config = StackConfig(state_dir=state_dir, app_port=app_port, storage_port=storage_port)
    started = time.perf_counter()
    process = subprocess.Popen([sys.executable, "-m", "drem_local.cli", "up", "--state-dir", str(state_dir),
                                "--port", str(app_port), "--storage-port", str(storage_port)],
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT)
    deadline = started + 60
    while time.perf_counter() < deadline:
        answer = http_get(config.app_url + "/healthz", timeout=1.0)
        if answer is not None and answer[0] == 200:
            return time.perf_counter() - started, process
        if process.poll() is not None:
            sys.exit(f"drem up exited early:\n{process.stdout.read().decode(errors='replace')}")
        time.sleep(0.01)
    process.kill()
    sys.exit("drem up did not answer /healthz within 60 s")


def stop_drem_up(process: subprocess.Popen) -> str:
    process.send_signal(signal.SIGINT)
    output, _ = process.communicate(timeout=60)
    return output.decode(errors="replace")


def dynamodb(url: str, keys: StorageKeys):
    """Signed with `keys`: the durable server verifies every signature (plain moto accepts any)."""
    return boto3.client("dynamodb", endpoint_url=url, region_name=REGION,
                        config=Config(account_id_endpoint_mode="disabled"), **keys.boto_kwargs())


def put_latencies_ms(client, table: str, count: int, offset: int) -> list[float]:
    latencies = []
    for n in range(offset, offset + count):
        item = {"pk": {"S": f"racer-{n}"}, "sk": {"S": "lap"}, "ms": {"N": str(10_000 + n)},
                "track": {"S": "reInvent2019_track"}}
        started = time.perf_counter()
        client.put_item(TableName=table, Item=item)
        latencies.append((time.perf_counter() - started) * 1000)
    return latencies


def create_table(client, table: str) -> None:
    client.create_table(TableName=table, BillingMode="PAY_PER_REQUEST",
                        KeySchema=[{"AttributeName": "pk", "KeyType": "HASH"},
                                   {"AttributeName": "sk", "KeyType": "RANGE"}],
                        AttributeDefinitions=[{"AttributeName": "pk", "AttributeType": "S"},
                                              {"AttributeName": "sk", "AttributeType": "S"}])


def start_plain_moto(port: int) -> subprocess.Popen:
    process = subprocess.Popen([sys.executable, "-m", "moto.server", "-H", "127.0.0.1", "-p", str(port)],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.perf_counter() + 30
    while time.perf_counter() < deadline:
        if http_get(f"http://127.0.0.1:{port}/moto-api/", timeout=1.0) is not None:
            return process
        time.sleep(0.05)
    process.kill()
    sys.exit("plain moto_server did not start")


def p95(values: list[float]) -> float:
    return statistics.quantiles(values, n=20)[-1]


def main() -> int:
    base = Path(tempfile.mkdtemp(prefix="drem-bench-startup-"))
    state_dir = base / "state"
    app_port, storage_port, plain_port = free_port(), free_port(), free_port()
    plain = start_plain_moto(plain_port)
    try:
        up_s, process = time_drem_up(state_dir, app_port, storage_port)
        print(f"cold drem up -> first 200 on /healthz: {up_s:.2f}s")

        durable_client = dynamodb(f"http://127.0.0.1:{storage_port}", load_keys(state_dir))
        plain_client = dynamodb(f"http://127.0.0.1:{plain_port}", generate_keys())
        create_table(durable_client, "bench-laps")
        create_table(plain_client, "bench-laps")
        put_latencies_ms(durable_client, "bench-laps", WARMUP, 0)
        put_latencies_ms(plain_client, "bench-laps", WARMUP, 0)
        durable_ms: list[float] = []
        plain_ms: list[float] = []
        for block in range(3):  # alternate blocks so machine noise hits both sides alike
            offset = WARMUP + block * (PUTS // 3)
            durable_ms += put_latencies_ms(durable_client, "bench-laps", PUTS // 3, offset)
            plain_ms += put_latencies_ms(plain_client, "bench-laps", PUTS // 3, offset)
        ratio = statistics.median(durable_ms) / statistics.median(plain_ms)
        print(f"PutItem durable (journal + fdatasync): median {statistics.median(durable_ms):.2f} ms, "
              f"p95 {p95(durable_ms):.2f} ms over {len(durable_ms)}")
        print(f"PutItem plain moto_server:             median {statistics.median(plain_ms):.2f} ms, "
              f"p95 {p95(plain_ms):.2f} ms over {len(plain_ms)}")

        info = read_stack_file(state_dir) or {}
        output = stop_drem_up(process)
        print(f"stop: {'stopped cleanly' if 'stopped cleanly' in output else 'NOT clean: ' + output[-500:]}")

        restart_s, process = time_drem_up(state_dir, app_port, storage_port)
        items = durable_client.scan(TableName="bench-laps", Select="COUNT")["Count"]
        print(f"restart with state ({items} bench items kept, pids were {info.get('pids')}) "
              f"-> first 200 on /healthz: {restart_s:.2f}s")
        stop_drem_up(process)
        if items != PUTS + WARMUP:
            print(f"state lost across restart: {items} of {PUTS + WARMUP} items")
            return 1
    finally:
        plain.terminate()
        plain.wait(10)
        shutil.rmtree(base, ignore_errors=True)

    met = up_s <= GOALS["up"] and restart_s <= GOALS["restart"] and ratio <= GOALS["ratio"]
    print(f"RESULT startup: up={up_s:.2f}s restart={restart_s:.2f}s putitem_ratio={ratio:.2f}x "
          f"| goal up<=5s restart<=5s ratio<=1.4 | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
