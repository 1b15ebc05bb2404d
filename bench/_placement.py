"""Which of this machine's cores a bench's stand-ins run on (bench/car_video.py).

At a venue the event laptop runs the live server, the app and storage; the car is a computer of its own, and the
viewers are phones and OBS PCs. A bench that runs all of them on this machine's 2 shared cores measures contention
that does not exist at a venue (the viewers' stand-in reading 500 streams competing with the live server writing
them). So the laptop's processes get one core, the car's the other, and the stand-ins for the crowd of other machines
run SCHED_IDLE (only on CPU time neither wants) on the laptop's core: the viewers' crowd and the OBS PC's browser
alike. Not on the car's: a car's CPU never does a phone's or the OBS PC's work, and left unplaced they did, even at
SCHED_IDLE (the kernel's receiving of 7,500 frames a second runs on the reader's core ahead of any process, and the
browser's decoding of the car's eye ran between the drive loop's ticks: loop jitter p99 3.5 ms with video against
1.4 ms without; with both kept on the laptop's core 0.5 against 0.3 ms). On the laptop's core they overstate the
laptop's load instead (a venue's laptop neither reads the viewers' streams nor paints the overlay), so lap-to-screen
is measured on the heavy side. The same placement holds for both halves of a side-by-side run.
"""
from __future__ import annotations

import os
from pathlib import Path

CAR_CORES = {0}
LAPTOP_CORES = {1}
STAND_IN_CORES = LAPTOP_CORES  # the viewers' crowd and the OBS PC's browser: anywhere but the car's core


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
            f"core {sorted(CAR_CORES)}, viewers' stand-in and the OBS PC's browser SCHED_IDLE on core "
            f"{sorted(STAND_IN_CORES)}")
