"""`drem status`: what is running, where the data lives and how big it is, in plain words."""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

HELP = "show whether the local stack is running, where its data lives and how big it is"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--state-dir", type=Path, default=Path(os.environ.get("DREM_STATE_DIR", ".drem")),
                        help="the state directory to look at (default .drem, or $DREM_STATE_DIR)")
    parser.add_argument("--json", action="store_true", help="print the same facts as JSON")


def run(args: argparse.Namespace) -> int:
    facts = gather(args.state_dir)
    print(json.dumps(facts, indent=2) if args.json else describe(facts))
    return 0


def gather(state_dir: Path) -> dict:
    from drem_local.durable.journal import read_all
    from drem_local.durable.state import JOURNAL_FILE, SNAPSHOT_DIR, VERSION_FILE
    from drem_local.stack import APP_HEALTH_PATH, HEALTH_PATH, LIVE_HEALTH_PATH, http_get, pid_is_drem, read_stack_file

    info = read_stack_file(state_dir) or {}
    urls = info.get("urls", {})
    pids = info.get("pids", {})
    facts: dict = {
        "state_dir": str(state_dir.resolve()),
        "exists": state_dir.is_dir(),
        "moto_version": _read(state_dir / VERSION_FILE),
    }
    # The journal file is preallocated; its records, not its size, say how much is waiting for a snapshot.
    journal = read_all(state_dir / JOURNAL_FILE)
    facts.update({
        "journal_bytes": journal.valid_bytes,
        "journal_records": len(journal.records),
        "snapshot_bytes": _size(state_dir / SNAPSHOT_DIR),
        "logs_dir": str((state_dir / "logs").resolve()),
        "admin_username": info.get("admin_username"),
        "urls": urls,
        "processes": {name: {"pid": pids.get(name), "alive": pid_is_drem(pids.get(name))}
                      for name in ("storage", "app", "live", "trainer", "scrutineer")},
    })
    manifest = state_dir / SNAPSHOT_DIR / "manifest.json"
    if manifest.exists():
        facts["last_snapshot_age_s"] = round(time.time() - json.loads(manifest.read_text())["written_at"], 1)
    storage_answer = http_get(urls["storage"] + HEALTH_PATH) if urls.get("storage") else None
    facts["storage_health"] = _json_or_none(storage_answer)
    app_url = urls.get("app_local") or urls.get("app")  # the public URL may be a proxy this machine cannot reach
    app_answer = http_get(app_url + APP_HEALTH_PATH) if app_url else None
    facts["app_answering"] = bool(app_answer and app_answer[0] == 200)
    live_url = urls.get("live_local")
    facts["live_health"] = _json_or_none(http_get(live_url + LIVE_HEALTH_PATH)) if live_url else None
    facts["disk"] = _disk_facts(state_dir) if facts["exists"] else None
    return facts


def _disk_facts(state_dir: Path) -> dict:
    from drem_local.disk import disk_state

    state = disk_state(state_dir)
    return {"problem": state.problem, "free_bytes": state.free_bytes}


_WRITES = {
    "accepted": "accepted",
    "journal-only": "still accepted, into the journal's reserved room ({room} left), but snapshots fail",
    "refused": "REFUSED (the app answers 507 with this message)",
}


def _disk_line(facts: dict, health: dict | None) -> str:
    """The disk, truthfully: what the running storage server can still do (its health), else what statvfs says."""
    from drem_local.disk import sentence

    disk = (health or {}).get("disk")
    if disk:
        if not disk["problem"]:
            return f"Data disk: {_human(disk['free_bytes'])} free; writes are accepted."
        writes = _WRITES[disk["writes"]].format(room=_human(disk["journal_room_bytes"]))
        return f"{disk['message']} Writes right now: {writes}."
    local = facts.get("disk")
    if not local:
        return "Data disk: unknown (the state dir does not exist yet)."
    if local["problem"]:
        return sentence(local["problem"], Path(facts["state_dir"]), "run drem up.")
    return f"Data disk: {_human(local['free_bytes'])} free."


def describe(facts: dict) -> str:
    if not facts["exists"]:
        return (f"No drem state at {facts['state_dir']}: nothing has been started here yet. "
                "Run `drem up` to start the local stack.")
    lines = []
    storage, app = facts["processes"]["storage"], facts["processes"]["app"]
    health = facts["storage_health"]
    urls = facts["urls"]
    if health:
        lines.append(f"Storage (durable moto {health['moto_version']}) is running at {urls['storage']} "
                     f"(pid {storage['pid']}).")
    elif storage["alive"]:
        lines.append(f"Storage process {storage['pid']} is alive but not answering at {urls.get('storage')}.")
    else:
        lines.append("Storage is not running.")
    if facts["app_answering"]:
        lines.append(f"The app is running: open {urls['app']} (pid {app['pid']}).")
    elif app["alive"]:
        lines.append(f"App process {app['pid']} is alive but {urls.get('app')}/healthz does not answer.")
    else:
        lines.append("The app is not running. Start everything with `drem up`.")
    live, live_health = facts["processes"]["live"], facts["live_health"]
    if live_health:
        lines.append(f"The live server is pushing the public pages at {urls.get('live') or urls.get('live_local')} "
                     f"(pid {live['pid']}; {live_health['streams']} viewers on {live_health['channels']} pages).")
    elif live["alive"]:
        lines.append(f"Live server process {live['pid']} is alive but {urls.get('live_local')}/live/healthz does not "
                     "answer (the public pages poll the app meanwhile).")
    elif live["pid"] or urls.get("live_local"):
        lines.append("The live server is not running (the public pages poll the app).")
    trainer = facts["processes"].get("trainer") or {}
    if trainer.get("alive"):
        lines.append(f"The learning booth's trainer is running (pid {trainer['pid']}; log: "
                     f"{facts['logs_dir']}/trainer.log).")
    elif trainer.get("pid"):
        lines.append("The learning booth's trainer is not running (drem up restarts it).")
    worker = facts["processes"]["scrutineer"]
    if worker["alive"]:
        lines.append(f"The scrutineering worker is running (pid {worker['pid']}): it test-drives uploaded models "
                     "in the background (log: scrutineer.log).")
    elif facts["app_answering"]:
        lines.append("The scrutineering worker is not running: uploaded models wait in its queue until it is.")
    lines.append(f"Data lives in {facts['state_dir']}: snapshots {_human(facts['snapshot_bytes'])}, "
                 f"journal {_human(health['journal_bytes'] if health else facts['journal_bytes'])} "
                 f"(moto {facts['moto_version'] or 'unknown'}).")
    age = health["last_snapshot_age_s"] if health else facts.get("last_snapshot_age_s")
    if age is not None:
        lines.append(f"Last snapshot {age:.0f}s ago; writes since then are in the journal and survive a crash.")
    waiting = health["journal_records"] if health else facts["journal_records"]
    lines.append(f"Journal: {waiting} writes not yet in a snapshot"
                 + (" (they are replayed on the next start)." if not health and waiting else "."))
    lines.append(_disk_line(facts, health))
    if facts["admin_username"]:
        lines.append(f"Admin user: {facts['admin_username']}.")
    lines.append(f"Logs: {facts['logs_dir']}.")
    return "\n".join(lines)


def _json_or_none(answer: tuple[int, bytes] | None) -> dict | None:
    """The health JSON, or None when nothing (or something that is not our server) answers on that port."""
    if not answer or answer[0] != 200:
        return None
    try:
        return json.loads(answer[1])
    except ValueError:
        return None


def _read(path: Path) -> str | None:
    try:
        return path.read_text().strip()
    except OSError:
        return None


def _size(path: Path) -> int:
    if path.is_file():
        return path.stat().st_size
    if path.is_dir():
        return sum(p.stat().st_size for p in path.rglob("*") if p.is_file())
    return 0


def _human(size: float) -> str:
    for unit in ("B", "KB", "MB", "GB"):
        if size < 1024 or unit == "GB":
            return f"{size:.0f} {unit}" if unit == "B" else f"{size:.1f} {unit}"
        size /= 1024
    return f"{size} B"
