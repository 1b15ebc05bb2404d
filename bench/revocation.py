"""What the revocation check (chalicelib.auth.revocation) costs a request, against a real durable server.

Measured in one run, side by side (median / p95 of 300 each, in-process, the same signed-in admin token):
- token verification alone (RS256 against the pinned installation key),
- verification + revocation check, mark cached (the usual case: one dict look-up),
- verification + revocation check, cache empty (one DynamoDB GetItem over loopback, once per user per 5 s),
- for scale: one plain GetItem on the events table through the same client.
Goal: a cached check adds < 0.1 ms; an uncached one < 5 ms.
"""
from __future__ import annotations

import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "functions"))

RUNS = 300
GOALS = {"hit_ms": 0.1, "miss_ms": 5.0}


def timed(action, runs: int = RUNS, before=None) -> list[float]:
    samples = []
    for _ in range(runs):
        if before is not None:
            before()
        started = time.perf_counter()
        action()
        samples.append((time.perf_counter() - started) * 1000)
    return samples


def summary(samples: list[float]) -> tuple[float, float]:
    ordered = sorted(samples)
    return statistics.median(ordered), ordered[int(len(ordered) * 0.95) - 1]


def main() -> None:
    from drem_local import stack as local_stack
    from drem_local.bootstrap import generate_password
    from drem_local.token_key import key_path

    with tempfile.TemporaryDirectory(prefix="drem-bench-revocation-") as tmp:
        config = local_stack.StackConfig(state_dir=Path(tmp) / "state", storage_port=local_stack.free_port())
        config.state_dir.mkdir(parents=True)
        storage = local_stack.start_storage(config, timeout=60)
        try:
            password = generate_password()
            outputs, admin = local_stack.bootstrap(config, "admin", password)
            os.environ.update(local_stack.app_environment(config, outputs))
            os.environ["DREM_TOKEN_KEY_FILE"] = str(key_path(config.state_dir))
            measure(outputs, admin.username, password)
        finally:
            storage.stop(30)


def measure(outputs, username: str, password: str) -> None:
    from chalicelib import services
    from chalicelib.auth.revocation import REVOKED
    from chalicelib.auth.sessions import current_token
    from chalicelib.auth.tokens import verify_token
    from chalicelib.settings import get_settings

    settings = get_settings()
    token = services.identity_provider().sign_in(username, password).access_token
    for _ in range(30):  # warm-up: clients, key, connection pool
        current_token(token, settings)
    verify = summary(timed(lambda: verify_token(token, settings)))
    hit = summary(timed(lambda: current_token(token, settings)))
    miss = summary(timed(lambda: current_token(token, settings), before=REVOKED.clear))
    from chalicelib.storage import clients

    table = settings.table("events")
    get_item = summary(timed(lambda: clients.dynamodb().get_item(TableName=table, Key={
        "pk": {"S": "EVENT#none"}, "sk": {"S": "META"}})))
    print(f"{'':34}{'median ms':>10}{'p95 ms':>10}")
    for label, (median, p95) in (("verify token only", verify), ("verify + check, mark cached", hit),
                                 ("verify + check, cache empty", miss), ("plain GetItem (for scale)", get_item)):
        print(f"{label:34}{median:10.3f}{p95:10.3f}")
    hit_cost, miss_cost = hit[0] - verify[0], miss[0] - verify[0]
    met = hit_cost < GOALS["hit_ms"] and miss_cost < GOALS["miss_ms"]
    print(f"RESULT revocation: cached check +{hit_cost:.3f} ms, uncached (GetItem) +{miss_cost:.2f} ms per request "
          f"(median) | goal cached < {GOALS['hit_ms']} ms, uncached < {GOALS['miss_ms']} ms | "
          f"{'met' if met else 'not met'}")


if __name__ == "__main__":
    main()
