"""Which of this machine's cores a bench's stand-ins run on (bench/car_video.py).

At a venue the event laptop runs the live server, the app and storage; the car is a computer of its own, and the
viewers are phones and OBS PCs. A bench that runs all of them on this machine's 2 shared cores measures contention
that does not exist at a venue (the viewers' stand-in reading 500 streams competing with the live server writing
them). So the laptop's processes get one core, the car's the other, and the stand-ins for the crowd of other machines
run SCHED_IDLE (only on CPU time neither wants): the viewers' crowd and the OBS PC's browser alike. The same placement
holds for both halves of a side-by-side run.
"""
from __future__ import annotations

import os
from pathlib import Path

CAR_CORES = {0}
LAPTOP_CORES = {1}


def two_cores() -> bool:
    return len(os.sched_getaffinity(0)) >= 2 and {0, 1} <= os.sched_getaffinity(0)


def process_tree(pid: int) -> list[int]:
    """`pid` and every process it started, as far down as they go (read from /proc)."""
    tree, todo = [], [pid]
    while todo:
        current = todo.pop()
        tree.append(current)
        for task in Path(f"/proc/{current}/task").glob("*"):
            try:
                todo.extend(int(child) for child in (task / "children").read_text().split())
            except OSError:
                continue
    return tree


def threads(pid: int) -> list[int]:
    return [int(task.name) for task in Path(f"/proc/{pid}/task").glob("*")]


def pin(pid: int, cores: set[int]) -> None:
    """The process, its threads and its children on `cores` (children started later inherit it)."""
    for process in process_tree(pid):
        for thread in threads(process):
            try:
                os.sched_setaffinity(thread, cores)
            except OSError:
                pass  # gone meanwhile


def idle(pid: int) -> None:
    """The process, its threads and its children at SCHED_IDLE: they run only when nothing else wants the CPU."""
    for process in process_tree(pid):
        for thread in threads(process):
            try:
                os.sched_setscheduler(thread, os.SCHED_IDLE, os.sched_param(0))
            except OSError:
                pass


def processes_running(program: str, root: int) -> list[int]:
    """The processes under `root` whose executable file is named `program` (from /proc/<pid>/exe: Chromium rewrites
    its command line): a browser and every helper it started."""
    found = []
    for pid in process_tree(root):
        try:
            if Path(os.readlink(f"/proc/{pid}/exe")).name == program:
                found.append(pid)
        except OSError:
            continue
    return found


def describe() -> str:
    return (f"laptop (storage, live server, app) on core {sorted(LAPTOP_CORES)}, car (drive loop, video relay) on "
            f"core {sorted(CAR_CORES)}, viewers' stand-in and the OBS PC's browser SCHED_IDLE")
