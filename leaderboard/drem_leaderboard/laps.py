"""The whole-lap rule, in one place: which stretches of a drive are lap attempts, which attempts are laps.

A lap attempt starts on the timing line (the standing start of an episode, or a crossing) and ends at the next
crossing (a completed lap, 100 %, timed crossing to crossing) or where the car leaves the track (the progress it had
reached, below 100 %). After an off-track the car is put back where it left: the stretch from there to the line is no
attempt at all, because the car never took the bend it left the track on, so it neither counts as a lap nor dilutes
completion. Every figure of a drive uses this: `drem sim eval`, scrutineering, DAgger and the league's re-drives
(`drem_sim.learn.evaluate.drive`, stepping the simulator), the simulator's own count (`RaceEnv.whole_laps`: a run
folder's metadata, `drem sim demo`/`record`, the `drem sim drive` page) and the booth's run metrics
(`chalicelib.domain.booth_runs.compute_metrics`, reading a run's recorded rows, and the live drive's figures).
Completion % is the mean of the attempts' progress (`ended`). Pure Python (no numpy), with the race rules, so the app
has it wherever it runs (the Lambda bundle vendors drem_leaderboard, not the simulator).
"""
from __future__ import annotations

UNFINISHED_CAP = 99.9  # an attempt that did not reach the line is never shown as a whole lap


class LapAttempts:
    """Feed a drive in order: `moved` with the distance driven so far, `crossed` at each timing-line crossing,
    `left_track` at each off-track; read `attempts` (progress % of each ended attempt) and `lap_times_s`."""

    def __init__(self, start_s: float = 0.0) -> None:
        self.attempts: list[float] = []
        self.lap_times_s: list[float] = []
        self._line_s: float | None = start_s  # when the running attempt left the line; None: from a put-back
        self._line_distance = 0.0  # the drive's distance (laps × 100 + progress, in %) when it did
        self._best = 0.0

    @property
    def laps_completed(self) -> int:
        return len(self.lap_times_s)

    @property
    def from_line(self) -> bool:
        """True while the attempt under way started on the line (it can still become a lap)."""
        return self._line_s is not None

    def moved(self, distance_pct: float) -> None:
        """The car is `distance_pct` along the drive (laps × 100 + lap progress: it never wraps at the line)."""
        if self._line_s is not None:
            self._best = max(self._best, distance_pct - self._line_distance)

    def crossed(self, at_s: float, distance_pct: float) -> None:
        """The car crossed the timing line at `at_s`: a lap if it drove there whole from the line."""
        if self._line_s is not None:
            self.lap_times_s.append(at_s - self._line_s)
            self.attempts.append(100.0)
        self._line_s, self._line_distance, self._best = at_s, distance_pct, 0.0

    def left_track(self) -> None:
        """The car left the track: the attempt from the line ends with what it reached; none runs until the line."""
        if self._line_s is not None:
            self.attempts.append(min(self._best, UNFINISHED_CAP))
        self._line_s, self._best = None, 0.0

    def restart_on_line(self, at_s: float, distance_pct: float = 0.0) -> None:
        """A new standing start on the line (a new episode): the attempt under way, if any, was already ended."""
        self._line_s, self._line_distance, self._best = at_s, distance_pct, 0.0

    def unfinished(self) -> float | None:
        """The progress of the attempt from the line still under way when the drive stopped (None after a put-back:
        that stretch is no attempt)."""
        return min(self._best, UNFINISHED_CAP) if self._line_s is not None else None

    def ended(self, *, out_of_time: bool = False) -> list[float]:
        """Every attempt's progress once the drive stopped: completion % is their mean. The attempt from the line
        still under way counts with what it reached, if it reached anything (a drive stopped on the line, or in the
        stretch after a put-back, adds no attempt). A drive stopped `out_of_time` before its attempts were driven (a
        stuck car, also one stuck after a put-back) counts the attempt under way even at 0 %."""
        unfinished = self.unfinished()
        if out_of_time:
            return [*self.attempts, unfinished or 0.0]
        return [*self.attempts, unfinished] if unfinished else list(self.attempts)
