"""Crash consistency under an event's traffic, inside multi-step operations, and on a full disk.

1. Traffic: `--rounds` rounds of kill -9 (storage or app, at random moments) while timers post laps, the desk registers
   racers, an operator creates events and a racer uploads models, all retrying as real clients do
   (tests/chaos_harness.py).
2. Operations: `--rounds` rounds more, each one operation (racer registration, queue start, `drem import`, model
   upload + check + conversion, booth training) killed -9 right after its Nth journal record, N drawn over the
   records an uncut run of it writes; the processes killed take turns: storage, app, the worker (the scrutineering
   worker; for an import, the `drem import` process itself; for booth training, the trainer worker) and everything
   (tests/chaos_operations.py). A booth round is a new visitor's 300-frame drive of drem_oval and Train with the
   form's Epochs at 1 (tests/chaos_booth.py): a few seconds of training, the same kind of model as 8 epochs.
3. Disk full: a stack on a 96 MiB tmpfs filled to the last byte, writes until they are refused, a power cut, space
   freed, a restart (tests/chaos_disk.py; needs root to mount the tmpfs, otherwise the round says it was skipped).

Prints acknowledged / lost / duplicated / stale / half-created per kind, and the time from the crash (or the clean
stop) to the first authenticated 200, crash next to clean restart.

    .venv/bin/python bench/chaos.py [--rounds 30] [--seed 19] [--no-disk-round]

Goal: 0 lost, 0 duplicated, 0 stale boards, 0 half-created, 0 model checks left "Checking…" (the scrutineering worker
resumes a cut-off check; here it looks every 2 s and takes over a check 5 s old), every training job DONE with exactly
one version (its archive stored) and one finished autonomous run, and a restart after a crash within 1.5x a clean one.
A crash restarts only the child that died (timed from the kill, so noticing it and the journal replay count); a clean
restart starts both (timed from the start, after the clean stop).
"""
from __future__ import annotations

import argparse
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "functions"))

from tests.chaos_disk import DiskFullFigures, disk_full_round  # noqa: E402
from tests.chaos_harness import Chaos  # noqa: E402
from tests.chaos_operations import OPERATIONS, OperationKills  # noqa: E402

CLEAN_RESTARTS = 2
VISIBILITY_SAMPLES = 3
VICTIMS_OF = {"registration": ("storage", "app", "everything"), "queue start": ("storage", "app", "everything"),
              "import": ("storage", "app", "worker", "everything"),
              "model upload": ("storage", "app", "worker", "everything"),
              "booth training": ("storage", "app", "worker", "everything")}
RESTART_RATIO_GOAL = 1.5


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--rounds", type=int, default=30)
    parser.add_argument("--seed", type=int, default=19)
    parser.add_argument("--no-disk-round", action="store_true", help="leave out the disk-full round")
    args = parser.parse_args(argv)

    os.environ.setdefault("DREM_CHECK_STALE_AFTER_S", "5")  # the field's 180 s would only make the settle longer
    os.environ.setdefault("DREM_RESUME_CHECKS_EVERY_S", "2")
    started = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="drem-chaos-") as tmp:
        chaos = Chaos(Path(tmp) / "state", seed=args.seed, say=lambda line: print("   ", line, flush=True))
        try:
            chaos.start()
            print(f"stack up; {args.rounds} kill -9 rounds under traffic ...", flush=True)
            report = chaos.run(args.rounds)
            print(f"{CLEAN_RESTARTS} clean restarts (stop like Ctrl-C, start again) ...", flush=True)
            for _ in range(CLEAN_RESTARTS):
                chaos.clean_restart()
            # (before the operation rounds: their supervising thread would restart what a clean stop stops)
            print(f"{args.rounds} operation rounds, each killed -9 after a journal record drawn over its own ...",
                  flush=True)
            kills = OperationKills(chaos, Path(tmp))
            try:
                for index in range(args.rounds):
                    operation = OPERATIONS[index % len(OPERATIONS)]
                    victims = VICTIMS_OF[operation]
                    victim = victims[(index // len(OPERATIONS)) % len(victims)]
                    round_started = time.perf_counter()
                    kills.run(operation, victim)
                    print(f"    {operation} (kill {victim}): {kills.figures[operation].line()}, "
                          f"{time.perf_counter() - round_started:.0f}s", flush=True)
                print("registration cut off by a storage kill after its account record, not registered again ...",
                      flush=True)
                visible_s = [kills.registration_visibility() for _ in range(VISIBILITY_SAMPLES)]
            finally:
                kills.close()
        finally:
            chaos.close()
        disk = DiskFullFigures(skipped="--no-disk-round")
        if not args.no_disk_round:
            print("disk-full round ...", flush=True)
            disk = disk_full_round(Path(tmp), say=lambda line: print("   ", line, flush=True))

    crash_s = statistics.median(report.crash_restart_s)
    clean_s = statistics.median(report.clean_restart_s)
    ratio = crash_s / clean_s
    print(f"\nrounds: {report.rounds} (killed storage {report.kills['storage']}x, app {report.kills['app']}x), "
          f"{time.perf_counter() - started:.0f}s in all")
    print(f"{'':28}{'acknowledged':>13}{'lost':>6}{'duplicated':>11}")
    print(f"{'laps':28}{report.laps_acknowledged:>13}{report.laps_lost:>6}{report.laps_duplicated:>11}")
    print(f"{'racers registered':28}{report.racers_acknowledged:>13}{report.racers_lost:>6}{0:>11}")
    print(f"{'events created':28}{report.events_acknowledged:>13}{report.events_lost:>6}"
          f"{report.events_duplicated:>11}")
    print(f"{'model uploads (file stored)':28}{report.models_acknowledged:>13}{report.models_lost:>6}{0:>11}"
          f"   still Checking… after settling: {report.models_stuck}")
    print(f"stale boards after restart: {report.stale_boards}; half-created accounts: {report.half_created_accounts}; "
          f"misleading error answers: {len(report.misleading_answers)}; unexplained errors: {len(report.errors)}")
    for error in report.errors[:5]:
        print("   error:", error)
    print("\nrestart to first authenticated 200      median    max")
    print(f"  after kill -9 ({len(report.crash_restart_s):>2} crashes)          "
          f"{crash_s:6.2f}s {max(report.crash_restart_s):6.2f}s")
    for role, seconds in sorted(report.crash_restart_by_role.items()):
        print(f"    of which {role:<8} ({len(seconds):>2})          "
              f"{statistics.median(seconds):6.2f}s {max(seconds):6.2f}s")
    print(f"  clean stop and start ({len(report.clean_restart_s)}x)          "
          f"{clean_s:6.2f}s {max(report.clean_restart_s):6.2f}s")
    print("\noperations killed on the journal     records  acknowledged/lost/duplicated/stale/half (killed of runs)")
    for operation, figures in kills.figures.items():
        print(f"  {operation:<34}{figures.records:>5}  {figures.line()}  victims {dict(figures.victims)}")
        for problem in figures.problems[:3]:
            print("     problem:", problem)
    print(f"a sign-up cut off by a storage kill is whole (racer group) after: "
          f"{', '.join(f'{seconds:.1f}s' for seconds in visible_s)} (from the kill, restart included)")
    print(f"disk-full round: {disk.line()}")
    for refusal in disk.wordless_refusals[:3]:
        print("   refusal without the words:", refusal)
    operations_met = all(figures.clean for figures in kills.figures.values())
    met = (operations_met and (disk.clean or args.no_disk_round)
           and report.lost == 0 and report.duplicated == 0 and report.stale_boards == 0
           and report.half_created_accounts == 0 and report.models_stuck == 0 and not report.errors
           and ratio <= RESTART_RATIO_GOAL)
    print(f"RESULT chaos: acknowledged {report.acknowledged}, lost {report.lost}, duplicated {report.duplicated}, "
          f"stale boards {report.stale_boards}, half-created {report.half_created_accounts}, "
          f"stuck model checks {report.models_stuck}; "
          + "; ".join(f"{name} {figures.line()}" for name, figures in kills.figures.items())
          + f"; disk full {disk.line()}; cut-off sign-up whole after max {max(visible_s):.1f}s; restart after crash "
          f"{crash_s:.2f}s vs clean {clean_s:.2f}s ({ratio:.2f}x) | goal 0 lost/dup/stale/half everywhere, "
          f"507 with words on a full disk, <= {RESTART_RATIO_GOAL}x | "
          f"{'met' if met else 'not met'}")
    return 0 if met else 1


if __name__ == "__main__":
    sys.exit(main())
