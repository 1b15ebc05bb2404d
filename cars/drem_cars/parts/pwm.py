"""Steering servo and drive motor through Linux sysfs PWM, with DeepRacer's calibration and wiring.

`/sys/class/pwm/pwmchipN/pwmM/{period,duty_cycle,enable}` in nanoseconds; 50 Hz (period 20 ms). A unit value v in
[-1, 1] (× polarity) maps to duty = mid + v·(mid − min) when v < 0 and mid + v·(max − mid) when v > 0, as DeepRacer's
servo node does. What the DeepRacer board does, read in aws-deepracer/aws-deepracer-servo-pkg:

- `src/pwm.cpp`: the PWM chip is the `/sys/class/pwm/pwmchip*` entry whose link points at device `0000:00:17.0`
  (its number is not fixed); `src/servo_mgr.cpp`: throttle (ESC) on channel 0, steering on channel 1.
- `include/servo_pkg/servo_mgr.hpp`: the servos are powered through GPIO 436, active low (`calibrateServo` writes
  0 to enable, 1 to disable); defaults servo 1.2/1.45/1.7 ms (polarity +1), motor 1.311/1.446/1.6035 ms (−1).
- `src/servo_mgr.cpp`: the calibration lives in `/opt/aws/deepracer/calibration.json` as
  `{"Calibration": {"Servo": {"min", "mid", "max", "polarity"}, "Motor": {...}, "version": 1}}`, values in ns.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path

PERIOD_NS = 20_000_000  # 50 Hz
SYSFS_PWM = Path("/sys/class/pwm")
SYSFS_GPIO = Path("/sys/class/gpio")
DEEPRACER_PWM_DEVICE = "0000:00:17.0"
DEEPRACER_THROTTLE_CHANNEL, DEEPRACER_STEERING_CHANNEL = 0, 1
DEEPRACER_SERVO_ENABLE_GPIO = 436
DEEPRACER_CALIBRATION = Path("/opt/aws/deepracer/calibration.json")


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


def pwm_chip_dir(root: Path = SYSFS_PWM, chip: int | None = None) -> Path:
    """pwmchip<chip>, or (chip None) the DeepRacer board's chip: the entry linked to device 0000:00:17.0."""
    if chip is not None:
        return root / f"pwmchip{chip}"
    entries = sorted(root.iterdir()) if root.is_dir() else []
    for entry in entries:
        if entry.name.startswith("pwmchip") and entry.is_symlink() and DEEPRACER_PWM_DEVICE in os.readlink(entry):
            return entry
    raise PwmUnavailable(f"no PWM chip of the DeepRacer board (device {DEEPRACER_PWM_DEVICE}) under {root}; "
                         "on other hardware pass --pwm-chip N (and --servo-enable-gpio none)")


class ServoEnable:
    """The DeepRacer board's servo power switch, a GPIO that is active low (0 = servos on)."""

    def __init__(self, gpio: int = DEEPRACER_SERVO_ENABLE_GPIO, root: Path = SYSFS_GPIO) -> None:
        self.pin = root / f"gpio{gpio}"
        try:
            if not self.pin.is_dir():
                (root / "export").write_text(str(gpio))
            if not self.pin.is_dir():
                raise PwmUnavailable(f"GPIO {gpio} (servo enable) did not appear under {root} after export")
            (self.pin / "direction").write_text("out")
            (self.pin / "value").write_text("0")
        except OSError as exc:
            raise PwmUnavailable(f"cannot switch the servos on through GPIO {gpio} ({self.pin}): "
                                 f"{exc.strerror or exc} (may this user write to it?)") from None

    def disable(self) -> None:
        (self.pin / "value").write_text("1")


class PwmChannel:
    def __init__(self, chip_dir: Path, channel: int, calibration: Calibration) -> None:
        self.calibration = calibration
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

    def __init__(self, servo: PwmChannel, motor: PwmChannel, enable: ServoEnable | None = None) -> None:
        self.servo = servo
        self.motor = motor
        self.enable = enable

    def run(self, steering: float | None, throttle: float | None) -> tuple[int, int]:
        return self.servo.set(steering or 0.0), self.motor.set(throttle or 0.0)

    def shutdown(self) -> None:
        self.motor.disable()
        self.servo.disable()
        if self.enable is not None:
            self.enable.disable()
