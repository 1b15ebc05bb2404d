"""What a racer reads when a test drive could not check their model, and what staff read beside it.

Every way a scrutineering drive can stop without a verdict ends here, so racers see one kind of sentence (what was
tried, what went wrong, what to do) and never an exception's name; the technical detail (the exception, the
simulator's last line of output) goes to `detail`, which only staff pages and logs show.
"""
from __future__ import annotations

from typing import NamedTuple

GiB = 1024 ** 3


class PlainFailure(NamedTuple):
    message: str  # for the racer: a sentence, no code names
    detail: str  # for staff: what the software said


def _technical(error: BaseException) -> str:
    return f"{type(error).__module__}.{type(error).__qualname__}: {error}"[:600]


def track_unavailable(track: str, error: BaseException) -> PlainFailure:
    return PlainFailure(
        f"drem could not open the track “{track}” for this test drive, so your model was not checked. This is a "
        "problem of this drem installation, not of your model: tell the staff, who see the details.",
        _technical(error))


def archive_unusable(reason: str) -> PlainFailure:
    return PlainFailure(
        f"drem could not read the model inside this archive ({reason}), so it was not test-driven. Upload the archive "
        "again exactly as your training tool saved it.",
        reason)


def console_model_unusable(reason: str) -> PlainFailure:
    return PlainFailure(
        "drem could not turn this console model into one its simulator can drive, so it was not test-driven. It can "
        "still be loaded on a stock DeepRacer; the staff see why it could not be converted.",
        reason)


def not_raceable(reason: str, detail: str | None) -> PlainFailure:
    return PlainFailure(f"This model cannot race: {reason}.", detail or reason)  # the reason says what to do


def model_stopped(track: str, error: BaseException) -> PlainFailure:
    return PlainFailure(
        f"Your model stopped with an error while drem test-drove it on “{track}”, so it was not checked. Try “Drive "
        "again”; if it stops again, show the model to the staff before you race it, as it may fail on the car too.",
        _technical(error))


def drive_timed_out(seconds: float) -> PlainFailure:
    return PlainFailure(
        f"The test drive took longer than {seconds:g} s and was stopped, so your model was not checked. The laptop "
        "may be busy: try “Drive again” in a few minutes.",
        f"wall-clock limit of {seconds:g} s reached")


def drive_out_of_cpu(seconds: int) -> PlainFailure:
    return PlainFailure(
        f"The test drive used more than {seconds} s of processor time and was stopped, so your model was not "
        "checked. Try “Drive again” later; if it stops again, show the model to the staff.",
        f"CPU-time limit of {seconds} s reached (SIGXCPU)")


def drive_out_of_memory(memory_bytes: int, text: str) -> PlainFailure:
    return PlainFailure(
        f"Your model needed more than {memory_bytes // GiB} GiB of memory in the simulator and was stopped, so it "
        "was not checked. A model this large may not run on a DeepRacer car either: show it to the staff.",
        text[-600:])


def simulator_crashed(how: str, text: str) -> PlainFailure:
    return PlainFailure(
        "drem's simulator stopped unexpectedly while test-driving your model, so it was not checked. Try “Drive "
        "again”; if it happens again, tell the staff, who see the details.",
        f"{how}: {text[-600:]}".rstrip(": "))


def no_answer(text: str) -> PlainFailure:
    return simulator_crashed("the drive printed no report", text)


def simulator_missing() -> PlainFailure:
    return PlainFailure(
        "This drem server has no simulator installed, so models cannot be test-driven here. Tell the staff.",
        "drem_sim (the 'sim' extra) is not importable in the app's environment")
