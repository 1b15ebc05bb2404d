"""The devices of one door of bench/lan.py: headless Chromium on the leaderboard and the overlay, a timer device
posting strip crossings and a crowd of spectators (bench/_crowd.py, polling all the time), all against one app URL.
bench/lan.py runs one on loopback and one inside the venue network namespace, both for the whole run, and drives
them over stdin/stdout (one JSON line each way): a command is one lap, given to both doors at once.

Each lap is timed as bench/live_latency.py times it (POST sent -> first animation frame with the lap, per page, the
page clock's offset calibrated per lap), but posted at a chosen point of one page's poll cycle: `wait_ms` before
that page's next poll, read from the poll start times the page's htmx reports (`htmx:beforeRequest` on the live
region). Most of a lap's latency is the wait for the next poll (0-500 ms, uniform when laps land at random); both
doors get the same drawn waits, so a pair of laps differs only by what the doors cost. The wait actually achieved is
measured afterwards and reported.

    python bench/_lan_device.py '{"url": ..., "host": ..., "port": ..., "racer": ..., "race": {...}, "crowd": 100}'
"""
from __future__ import annotations

import json
import multiprocessing
import statistics
import sys
import time
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from bench import _crowd, _stack, live_latency  # noqa: E402

PAGES = {"leaderboard": "#board-live", "overlay": "#overlay-live"}
# Poll start times of the live region, in the page clock (a swap replaces the region: listen on the body).
POLL_RECORDER_JS = """selector => {
  window.__polls = [];
  document.body.addEventListener('htmx:beforeRequest', event => {
    if (event.target.matches && event.target.matches(selector)) {
      window.__polls.push(performance.timeOrigin + performance.now());
      if (window.__polls.length > 50) window.__polls.shift();
    }
  });
}"""
MARGIN_MS = 40.0  # the soonest we aim a POST at: reading the polls and sleeping take a few ms


def reply(message: dict[str, Any]) -> None:
    print("DEVICE " + json.dumps(message), flush=True)


def next_poll_wait(page: Any, offset_ms: float, wait_ms: float, poll_ms: int) -> float:
    """Sleep until `wait_ms` before the page's next poll (the soonest that is at least MARGIN_MS away)."""
    polls = page.evaluate("() => window.__polls.slice(-6)")
    if not polls:
        raise SystemExit("the page has not polled yet")
    # A dropped poll leaves a double gap.
    gaps = [b - a for a, b in zip(polls, polls[1:], strict=False) if b - a < 1.5 * poll_ms]
    period = statistics.median(gaps) if gaps else float(poll_ms)
    now_in_page = time.time() * 1000 + offset_ms
    next_poll = polls[-1] + period
    while next_poll - wait_ms < now_in_page + MARGIN_MS:
        next_poll += period
    delay_s = (next_poll - wait_ms - offset_ms) / 1000 - time.time()
    if delay_s > 0:
        time.sleep(delay_s)
    return period


def achieved_wait(page: Any, offset_ms: float, sent_ms: float) -> float | None:
    """How long after `sent_ms` (this process's clock) the page's next poll really started."""
    sent_in_page = sent_ms + offset_ms
    later = [p for p in page.evaluate("() => window.__polls.slice(-20)") if p >= sent_in_page]
    return min(later) - sent_in_page if later else None


def lap(pages: dict[str, Any], offsets: dict[str, float], lapper: live_latency.Lapper, spec: dict[str, Any],
        poll_ms: int) -> dict[str, Any]:
    """One strip crossing, aimed `wait_ms` before the target page's next poll; the latency on every page."""
    time.sleep(spec["pause_s"])
    lap_ms, key = lapper.next_lap_ms, f"lap-{lapper.count}"
    wants = {"leaderboard": {"key": key, "selector": f'[data-racer="{live_latency.RACER}"][data-time="{lap_ms}"]',
                             "text": ""},
             "overlay": {"key": key, "selector": '[data-testid="previous-lap"]', "text": live_latency.lap_text(lap_ms)}}
    for name, page in pages.items():
        page.evaluate("want => { window.__want = want; window.__check(); }", wants[name])
    target = spec["target"]
    next_poll_wait(pages[target], offsets[target], spec["wait_ms"], poll_ms)
    posted_ms, sent, answer = lapper.next_lap()
    post_ms = time.time() * 1000 - sent  # the timer's POST answered: the lap is stored and the board published
    if answer.get("lap", {}).get("time_ms") != posted_ms:
        raise SystemExit(f"the crossing did not give a {posted_ms} ms lap: {answer}")
    latencies = {}
    for name, page in pages.items():
        page.wait_for_function("key => window.__seen[key] && window.__seen[key].frame", arg=key, timeout=15_000)
        latencies[name] = page.evaluate("key => window.__seen[key]", key)["frame"] - offsets[name] - sent
    return {**spec, "achieved_wait_ms": achieved_wait(pages[target], offsets[target], sent), "post_ms": post_ms,
            "latencies": latencies}


def main(spec: dict[str, Any]) -> int:
    from playwright.sync_api import sync_playwright

    live_latency.RACER = spec["racer"]
    url, race = spec["url"], _stack.LiveRace(**spec["race"])
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=live_latency.CHROMIUM, args=live_latency.CHROMIUM_ARGS)
        pages: dict[str, Any] = {}
        for name, path, size in (("leaderboard", f"/leaderboard/{race.event_id}", (1280, 800)),
                                 ("overlay", f"/overlay/{race.event_id}?track=1", (1920, 1080))):
            page = browser.new_context(viewport={"width": size[0], "height": size[1]}).new_page()
            page.goto(url + path)
            page.evaluate(live_latency.OBSERVER_JS)
            page.evaluate(POLL_RECORDER_JS, PAGES[name])
            pages[name] = page
        poll_ms = live_latency.poll_period_ms(pages["leaderboard"], PAGES["leaderboard"])
        if live_latency.poll_period_ms(pages["overlay"], PAGES["overlay"]) != poll_ms:
            raise SystemExit("the leaderboard and the overlay poll at different periods; the crowd assumes one")
        lapper = live_latency.Lapper(url, race)
        fragments = [live_latency.live_path(page, PAGES[name]) for name, page in pages.items()]
        spawn = multiprocessing.get_context("spawn")
        stop, queue = spawn.Event(), spawn.Queue()
        crowd = spawn.Process(target=_crowd.run_crowd, args=(spec["host"], spec["port"], fragments, spec["crowd"],
                                                             poll_ms / 1000, stop, queue), daemon=True)
        crowd.start()
        time.sleep(live_latency.WARM_UP_S)
        reply({"ready": True, "poll_ms": poll_ms})
        try:
            for line in sys.stdin:
                command = json.loads(line)
                if command["cmd"] == "stop":
                    break
                offsets = {name: live_latency.clock_offset_ms(page)[0] for name, page in pages.items()}
                reply(lap(pages, offsets, lapper, command["lap"], poll_ms))
        finally:
            stop.set()
            load = queue.get(timeout=60)
            crowd.join(30)
            browser.close()
    reply({"crowd_rate": load["rate"], "crowd_p99_ms": load["p99_ms"], "crowd_errors": load["errors"] + load["other"],
           "crowd_first_error": load["first_error"]})
    return 0


if __name__ == "__main__":
    raise SystemExit(main(json.loads(sys.argv[1])))
