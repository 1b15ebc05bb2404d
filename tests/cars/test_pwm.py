from __future__ import annotations

import json
from pathlib import Path

import pytest

from drem_cars.parts.pwm import (
    MOTOR_DEFAULT,
    SERVO_DEFAULT,
    PwmActuator,
    PwmChannel,
    PwmUnavailable,
    ServoEnable,
    load_calibration,
    pwm_chip_dir,
)

pytestmark = pytest.mark.unit


def sysfs_tree(root: Path, chip: int = 0, channels: int = 2) -> Path:
    """A temp stand-in for /sys/class/pwm: exporting creates the channel folder, as the kernel does."""
    chip_dir = root / f"pwmchip{chip}"
    chip_dir.mkdir(parents=True)
    (chip_dir / "npwm").write_text(str(channels))
    return root


def read(root: Path, channel: int, name: str) -> str:
    return (root / "pwmchip0" / f"pwm{channel}" / name).read_text()


def exported_channel(root: Path, channel: int) -> None:
    (root / "pwmchip0" / f"pwm{channel}").mkdir()


def test_deepracer_defaults_map_unit_values_to_duty_cycles() -> None:
    assert SERVO_DEFAULT.duty_ns(-1) == 1_200_000 and SERVO_DEFAULT.duty_ns(0) == 1_450_000
    assert SERVO_DEFAULT.duty_ns(1) == 1_700_000 and SERVO_DEFAULT.duty_ns(0.5) == 1_575_000
    # motor polarity −1: full forward throttle is the *min* pulse
    assert MOTOR_DEFAULT.duty_ns(1) == 1_311_000 and MOTOR_DEFAULT.duty_ns(-1) == 1_603_500
    assert MOTOR_DEFAULT.duty_ns(0) == 1_446_000 and MOTOR_DEFAULT.duty_ns(7) == 1_311_000, "clipped to ±1"


def test_actuator_writes_50hz_period_duty_and_enable_then_goes_neutral_on_shutdown(tmp_path: Path) -> None:
    root = sysfs_tree(tmp_path)
    exported_channel(root, 0)
    exported_channel(root, 1)
    chip = root / "pwmchip0"
    actuator = PwmActuator(PwmChannel(chip, 0, SERVO_DEFAULT), PwmChannel(chip, 1, MOTOR_DEFAULT))
    assert read(root, 0, "period") == "20000000" and read(root, 0, "enable") == "1"
    assert read(root, 1, "duty_cycle") == "1446000", "motor starts neutral"
    assert actuator.run(-1.0, 0.5) == (1_200_000, 1_378_500)
    assert read(root, 0, "duty_cycle") == "1200000" and read(root, 1, "duty_cycle") == "1378500"
    actuator.shutdown()
    assert read(root, 1, "duty_cycle") == "1446000" and read(root, 1, "enable") == "0"


def test_calibration_json_from_the_car_is_read(tmp_path: Path) -> None:
    path = tmp_path / "calibration.json"
    path.write_text(json.dumps({"Calibration": {
        "Servo": {"min": 1_250_000, "mid": 1_460_000, "max": 1_690_000, "polarity": 1},
        "Motor": {"min": 1_300_000, "mid": 1_450_000, "max": 1_600_000, "polarity": -1}, "version": 1}}))
    servo, motor = load_calibration(path)
    assert servo.duty_ns(1) == 1_690_000 and motor.duty_ns(1) == 1_300_000


def deepracer_sysfs(tmp_path: Path) -> Path:
    """/sys/class/pwm as on a DeepRacer: pwmchipN are links into /sys/devices; the board's chip is 0000:00:17.0's."""
    devices = tmp_path / "devices" / "pci0000:00"
    pwm = tmp_path / "class" / "pwm"
    pwm.mkdir(parents=True)
    for chip, device in ((0, "0000:00:1a.0"), (2, "0000:00:17.0")):
        target = devices / device / "pwm" / f"pwmchip{chip}"
        target.mkdir(parents=True)
        (pwm / f"pwmchip{chip}").symlink_to(target)
    return pwm


def test_the_deepracer_pwm_chip_is_found_by_its_device_link_not_its_number(tmp_path: Path) -> None:
    pwm = deepracer_sysfs(tmp_path)
    assert pwm_chip_dir(pwm) == pwm / "pwmchip2"
    assert pwm_chip_dir(pwm, 0) == pwm / "pwmchip0", "an explicit number wins (other hardware)"
    with pytest.raises(PwmUnavailable, match="no PWM chip of the DeepRacer board"):
        pwm_chip_dir(tmp_path / "empty")


def test_servos_are_enabled_by_writing_gpio_436_low_and_disabled_high(tmp_path: Path) -> None:
    gpio = tmp_path / "gpio"
    (gpio / "gpio436").mkdir(parents=True)
    enable = ServoEnable(436, gpio)
    assert (gpio / "gpio436" / "direction").read_text() == "out"
    assert (gpio / "gpio436" / "value").read_text() == "0", "active low: 0 powers the servos"
    enable.disable()
    assert (gpio / "gpio436" / "value").read_text() == "1"


def test_an_unexported_gpio_is_exported_and_a_missing_one_is_a_clear_error(tmp_path: Path) -> None:
    gpio = tmp_path / "gpio"
    gpio.mkdir()
    with pytest.raises(PwmUnavailable, match="GPIO 436 .servo enable. did not appear"):
        ServoEnable(436, gpio)
    assert (gpio / "export").read_text() == "436"
