"""Can the live server take a crowd of spectators polling the leaderboard?

Starts a durable moto server, the live server (drem_live, `--workers` processes sharing its port with SO_REUSEPORT,
default one per core) and the real app server (bench/_stack.py), materialises a 50-racer board through the real
publisher, and drives the board poll with wrk over 200 concurrent keep-alive connections:
  - live changed:   `GET /live/api/leaderboard/{event}?track=1` holding an old version (If-None-Match "v0") -> 200,
  - live unchanged: the same holding the current version -> 304, empty body,
side by side, in the same run and in alternating rounds, with
  (a) nginx (Debian package, unprivileged child on a free port) serving the same bytes as a static file, with as many
      worker processes as the live server has in this run (`--workers`) sharing its port the same way (`listen ...
      reuseport`: one socket per worker, the kernel spreads connections): the "x nginx" ratio compares the two
      servers process for process on the same cores, not N live processes with one nginx worker,
  (b) the app's own `GET /api/leaderboard/{event}?track=1` (the path the live server replaces), changed case.
Starved clients: while each wrk run is under way, `ss -ti` lists the server's established connections; one whose
server side has sent no data segment has had no response. wrk's own errors/timeouts are reported too.
Goal (issue 27, raised): both live cases >= 2,000 polls/s at p99 <= 50 ms with 0 starved clients, and saturated
>= 0.5x nginx process for process.

    .venv/bin/python bench/spectators.py [--seconds 8] [--rounds 2] [--connections 200] [--workers N]
"""
from __future__ import annotations

import argparse
import os
import pwd
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import _stack  # noqa: E402

EVENT_ID = "bench-spectators"
NGINX = "/usr/sbin/nginx"
WRK_THREADS = 1  # one core for wrk, one for the server under test (the machine has two)

POLL_LUA = """
wrk.headers["Accept"] = "application/json"
wrk.headers["If-None-Match"] = '%s'
function response(status, headers, body) summary_status(status) end
"""
# Paced: every connection polls about every 85 ms (jittered so they do not move in lockstep): 200 connections offer
# ~2,300 polls/s, a little over the goal so that wrk's ramp-up and each answer's own time do not keep a server that
# keeps up below 2,000/s. wrk times each request from send to response; the pause is not counted.
PACED_LUA = """
function init(args) math.randomseed(os.time() * 1000 + (id or 0)) end
function delay() return math.random(60, 110) end
"""
PLAIN_LUA = """
function response(status, headers, body) summary_status(status) end
"""

# worker_processes: the live server's process count in this run (start_nginx); reuseport: each worker its own
# listening socket on the port, as the live server's processes have with SO_REUSEPORT.
NGINX_CONF = """
worker_processes {workers};
daemon off;
pid {tmp}/nginx.pid;
error_log {tmp}/nginx-error.log warn;
events {{ worker_connections 1024; }}
http {{
    access_log off;
    client_body_temp_path {tmp}/client_body;
    proxy_temp_path {tmp}/proxy;
    fastcgi_temp_path {tmp}/fastcgi;
    uwsgi_temp_path {tmp}/uwsgi;
    scgi_temp_path {tmp}/scgi;
    keepalive_requests 10000000;
    keepalive_timeout 75s;
    types {{ application/json json; }}
    server {{
        listen 127.0.0.1:{port} reuseport;
        root {root};
        location / {{ }}
    }}
}}
"""


def start_nginx(body: bytes, workers: int) -> tuple[subprocess.Popen[bytes], int, Path]:
    """nginx with `workers` worker processes, as an unprivileged child (as `nobody` when this bench runs as root) in
    its own temp dir."""
    from drem_local import stack as local_stack

    tmp = Path(tempfile.mkdtemp(prefix="drem-bench-nginx-"))
    root = tmp / "root"
    root.mkdir()
    (root / "board.json").write_bytes(body)
    port = local_stack.free_port()
    conf = tmp / "nginx.conf"
    conf.write_text(NGINX_CONF.format(tmp=tmp, port=port, root=root, workers=workers))
    drop: dict[str, Any] = {}
    if os.geteuid() == 0:
        nobody = pwd.getpwnam("nobody")
        for path in (tmp, root, root / "board.json", conf):
            os.chown(path, nobody.pw_uid, nobody.pw_gid)
        tmp.chmod(0o755)
        drop = {"user": nobody.pw_uid, "group": nobody.pw_gid, "extra_groups": []}
    process = subprocess.Popen([NGINX, "-p", str(tmp), "-c", str(conf), "-e", str(tmp / "nginx-error.log")],
                               stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, **drop)
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        answer = local_stack.http_get(f"http://127.0.0.1:{port}/board.json")
        if answer is not None and answer[1] == body:
            return process, port, tmp
        time.sleep(0.05)
    process.kill()
    raise SystemExit(f"nginx did not serve the board:\n{(tmp / 'nginx-error.log').read_text()}")


def server_connections(port: int) -> tuple[int, int]:
    """(established server-side connections on `port`, those that have sent no data segment = no response yet)."""
    out = subprocess.run(["ss", "-tinH", "state", "established", f"( sport = :{port} )"], capture_output=True,
                         text=True, check=True).stdout
    sockets = [chunk for chunk in re.split(r"\n(?=\S)", out.strip()) if chunk]
    starved = sum(1 for s in sockets if not re.search(r"\bdata_segs_out:[1-9]", s))
    return len(sockets), starved


def run_case(name: str, url: str, port: int, lua: str, args: argparse.Namespace, tmp: Path) -> dict[str, Any]:
    process = _stack.start_wrk(url, lua, connections=args.connections, threads=WRK_THREADS, seconds=args.seconds,
                               tmp=tmp, name=name)
    probe: dict[str, tuple[int, int]] = {}
    timer = threading.Timer(args.seconds * 0.7, lambda: probe.setdefault("ss", server_connections(port)))
    timer.start()
    result = _stack.wrk_result(process, timeout=args.seconds + 30)
    timer.join()
    result["connections_seen"], result["starved"] = probe.get("ss", (0, args.connections))
    return result


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=8)
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--connections", type=int, default=200)
    parser.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                        help="live server processes, and as many nginx workers (default: one per core)")
    args = parser.parse_args(argv)
    for tool in (_stack.WRK, NGINX, shutil.which("ss")):
        if not tool or not Path(tool).exists():
            raise SystemExit(f"missing tool: {tool or 'ss'}")

    names = ("changed", "unchanged", "app changed", "nginx", "changed@2000/s", "unchanged@2000/s")
    runs: dict[str, list[dict[str, Any]]] = {name: [] for name in names}
    load_before = _stack.machine_load()
    with _stack.bench_stack(live_workers=args.workers) as stack:
        _stack.seed_board(stack.env, EVENT_ID, racers=50)
        app_url = f"{stack.url}/api/leaderboard/{EVENT_ID}?track=1"
        poll_url = f"http://127.0.0.1:{stack.live_port}/live/api/leaderboard/{EVENT_ID}?track=1"
        with _stack._NO_PROXY.open(urllib.request.Request(poll_url), timeout=10) as reply:
            body, etag = reply.read(), reply.headers["ETag"]
        with _stack._NO_PROXY.open(urllib.request.Request(app_url), timeout=10) as reply:
            if reply.read() != body:
                raise SystemExit("the live server's board differs from the app's")
        nginx, nginx_port, nginx_dir = start_nginx(body, args.workers)
        try:
            cases = {
                "changed": (poll_url, stack.live_port, POLL_LUA % '"v0"'),
                "unchanged": (poll_url, stack.live_port, POLL_LUA % etag),
                "app changed": (app_url, stack.port, POLL_LUA % '"v0"'),
                "nginx": (f"http://127.0.0.1:{nginx_port}/board.json", nginx_port, PLAIN_LUA),
                "changed@2000/s": (poll_url, stack.live_port, POLL_LUA % '"v0"' + PACED_LUA),
                "unchanged@2000/s": (poll_url, stack.live_port, POLL_LUA % etag + PACED_LUA),
            }
            for round_index in range(args.rounds):
                for name, (url, port, lua) in cases.items():
                    result = run_case(f"{name.replace('@2000/s', '-paced').replace(' ', '-')}-{round_index}", url,
                                      port, lua, args, stack.tmp)
                    runs[name].append(result)
                    print(f"  round {round_index + 1} {name:16s} {result['rate']:9.0f} req/s  "
                          f"p99 {result['p99_us'] / 1000:7.1f} ms  starved {result['starved']}", flush=True)
        finally:
            nginx.terminate()
            nginx.wait(10)
            shutil.rmtree(nginx_dir, ignore_errors=True)

    def rate(name: str) -> float:
        return statistics.median(r["rate"] for r in runs[name])

    def worst(name: str, key: str) -> float:
        return max(r[key] for r in runs[name])

    def errors(name: str) -> int:
        return sum(r["connect_errors"] + r["read_errors"] + r["write_errors"] + r["timeouts"] + r["non_2xx_3xx"]
                   for r in runs[name])

    print(f"\n{args.connections} keep-alive connections, wrk -t {WRK_THREADS}, {args.rounds} rounds x "
          f"{args.seconds:.0f} s per case (alternating); board body {len(body)} bytes; live server: {args.workers} "
          f"worker process(es) on one port (SO_REUSEPORT), nginx the same number of workers (reuseport); "
          f"'app changed' = the app's /api/leaderboard")
    print(f"machine load before the bench: {load_before} (the machine is shared with other work)")
    print("saturated = every connection sends its next request as soon as the answer is in (max throughput);")
    print("@2000/s   = every connection polls every ~85 ms (200 x ~11.8/s offered, ~2,300/s)")
    print(f"{'case':17s} {'req/s':>9s} {'p50 ms':>8s} {'p99 ms':>8s} {'max ms':>8s} {'errors':>7s} {'starved':>8s} "
          f"{'statuses':>22s}")
    for name, results in runs.items():
        statuses = f"200:{sum(r['s200'] for r in results)} 304:{sum(r['s304'] for r in results)}"
        print(f"{name:17s} {rate(name):9.0f} {statistics.median(r['p50_us'] for r in results) / 1000:8.2f} "
              f"{worst(name, 'p99_us') / 1000:8.2f} {worst(name, 'max_us') / 1000:8.1f} {errors(name):7d} "
              f"{int(worst(name, 'starved')):8d} {statuses:>22s}")
    figures, met = [], True
    for case in ("changed", "unchanged"):
        paced = f"{case}@2000/s"
        vs_app, vs_nginx = rate(case) / rate("app changed"), rate(case) / rate("nginx")
        p99 = worst(paced, "p99_us") / 1000
        starved = int(max(worst(case, "starved"), worst(paced, "starved")))
        print(f"live {case}: saturated {vs_nginx:.3f}x nginx, {vs_app:.2f}x the app's poll; at ~2000/s offered: "
              f"{rate(paced):.0f}/s, p99 {p99:.1f} ms")
        met &= (rate(paced) >= 2000 and p99 <= 50 and starved == 0 and errors(case) + errors(paced) == 0
                and vs_nginx >= 0.5)
        figures.append(f"live {case}: {rate(paced):.0f}/s p99={p99:.1f}ms starved={starved} max={rate(case):.0f}/s "
                       f"{vs_nginx:.3f}x_nginx {vs_app:.1f}x_app")
    figures.append(f"app={rate('app changed'):.0f}/s nginx={rate('nginx'):.0f}/s workers={args.workers} "
                   f"nginx_workers={args.workers} "
                   f"load={_stack.machine_load()}")
    print(f"RESULT spectators: {'; '.join(figures)} | goal >=2000 polls/s at p99<=50ms, 0 starved, saturated "
          f">=0.5x nginx | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
