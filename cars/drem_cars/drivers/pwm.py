"""Steering servo and drive motor through Linux sysfs PWM, with DeepRacer's calibration.

`/sys/class/pwm/pwmchipN/pwmM/{period,duty_cycle,enable}` in nanoseconds; 50 Hz (period 20 ms). A unit value v in
[-1, 1] (× polarity) maps to duty = mid + v·(mid − min) when v < 0 and mid + v·(max − mid) when v > 0, as DeepRacer's
servo node does. Defaults are DeepRacer's: servo 1.2/1.45/1.7 ms (polarity +1), motor 1.311/1.446/1.6035 ms
(polarity −1). DeepRacer keeps them in `/opt/aws/deepracer/calibration.json`; `load_calibration` reads that file.
"""
from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

PERIOD_NS = 20_000_000  # 50 Hz
SYSFS_PWM = Path("/sys/class/pwm")


class PwmUnavailable(RuntimeError):
    """A PWM chip or channel cannot be opened, or the calibration file cannot be read; the message says which."""


@dataclass(frozen=True)
class Calibration:
    min_ns: int
    mid_ns: int
    max_ns: int
    polarity: int = 1

    def duty_ns(self, value: float) -> int:
        v = max(-1.0, min(1.0, value)) * (1 if self.polarity >= 0 else -1)
        if v < 0:
            return round(self.mid_ns + v * (self.mid_ns - self.min_ns))
        return round(self.mid_ns + v * (self.max_ns - self.mid_ns))


SERVO_DEFAULT = Calibration(1_200_000, 1_450_000, 1_700_000, 1)
MOTOR_DEFAULT = Calibration(1_311_000, 1_446_000, 1_603_500, -1)


def load_calibration(path: Path) -> tuple[Calibration, Calibration]:
    """(servo, motor) from DeepRacer's calibration.json ({"Calibration": {"Servo": {...}, "Motor": {...}}})."""
    def one(entry: dict) -> Calibration:
        calibration = Calibration(int(entry["min"]), int(entry["mid"]), int(entry["max"]),
                                  int(entry.get("polarity", 1)))
        if not 0 < calibration.min_ns <= calibration.mid_ns <= calibration.max_ns < PERIOD_NS:
            raise ValueError(f"min <= mid <= max within one 20 ms period is required, got {entry}")
        return calibration

    try:
        data = json.loads(path.read_text())["Calibration"]
        return one(data["Servo"]), one(data["Motor"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise PwmUnavailable(f"calibration file {path}: {type(exc).__name__}: {exc} (expected DeepRacer's "
                             '{"Calibration": {"Servo": {"min", "mid", "max", "polarity"}, "Motor": {...}}})') from None


class PwmChannel:
    def __init__(self, chip: int, channel: int, calibration: Calibration, root: Path = SYSFS_PWM) -> None:
        self.calibration = calibration
        chip_dir = root / f"pwmchip{chip}"
        self.path = chip_dir / f"pwm{channel}"
        if not chip_dir.is_dir():
            raise PwmUnavailable(f"no PWM chip at {chip_dir}: enable hardware PWM (on a Raspberry Pi "
                                 "`dtoverlay=pwm-2chan` in config.txt) or pass --pwm-root / --pwm-chip")
        try:
            if not self.path.exists():
                (chip_dir / "export").write_text(str(channel))
            self._write("period", PERIOD_NS)
            self.set(0.0)
            self._write("enable", 1)
        except OSError as exc:
            raise PwmUnavailable(f"cannot drive PWM channel {self.path}: {exc.strerror or exc} (is the channel "
                                 "number right, and may this user write to it?)") from None

    def _write(self, name: str, value: int) -> None:
        (self.path / name).write_text(str(value))

    def set(self, value: float) -> int:
        duty = self.calibration.duty_ns(value)
        self._write("duty_cycle", duty)
        return duty

    def neutral(self) -> None:
        self.set(0.0)

    def disable(self) -> None:
        self.neutral()
        self._write("enable", 0)


class PwmActuator:
    """Part: (unit steering, unit throttle) → servo and motor duty cycles; neutral and disabled on shutdown."""

    def __init__(self, servo: PwmChannel, motor: PwmChannel) -> None:
        self.servo = servo
        self.motor = motor

    def run(self, steering: float | None, throttle: float | None) -> tuple[int, int]:
        return self.servo.set(steering or 0.0), self.motor.set(throttle or 0.0)

    def shutdown(self) -> None:
        self.motor.disable()
        self.servo.disable()
