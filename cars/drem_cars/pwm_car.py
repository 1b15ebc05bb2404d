"""Composition root of a DIY car (camera + PWM): which parts, in which order, on which channels.

    OpenCV camera → ONNX pilot (the agent's pilot slot) → action→drive mapping → safety → PWM servo + motor
                  → telemetry → driver status

Without a loaded model the pilot outputs nothing and the mapping gives no throttle: the car waits, wheels straight.
Hardware is opened camera first, then PWM; if any of it fails, what was opened is closed again and
`HardwareUnavailable` says what is missing, so the command can print it and exit 1.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from drem_cars import channels as ch
from drem_cars.drivers.local import LocalDriver
from drem_cars.parts.camera_cv import CameraUnavailable, OpenCvCamera
from drem_cars.parts.drive_mapping import ActionToDrive
from drem_cars.parts.pilot_slot import PilotSlot
from drem_cars.parts.pwm import (
    DEEPRACER_SERVO_ENABLE_GPIO,
    DEEPRACER_STEERING_CHANNEL,
    DEEPRACER_THROTTLE_CHANNEL,
    MOTOR_DEFAULT,
    SERVO_DEFAULT,
    SYSFS_GPIO,
    SYSFS_PWM,
    Calibration,
    PwmActuator,
    PwmChannel,
    PwmUnavailable,
    ServoEnable,
    load_calibration,
    pwm_chip_dir,
)
from drem_cars.parts.safety import Safety
from drem_cars.parts.telemetry import Telemetry
from drem_cars.vehicle import Vehicle
from drem_cars.video_sources import FrameTap


class HardwareUnavailable(RuntimeError):
    """The camera, the PWM outputs or the calibration cannot be used; the message is for the person at the car."""


@dataclass(frozen=True)
class PwmWiring:
    """Defaults are a DeepRacer chassis (with `deepracer-core` stopped, so the car's own servo node lets go)."""
    root: Path = SYSFS_PWM
    chip: int | None = None  # None: the DeepRacer board's chip, found by its device link; N: pwmchipN
    servo_channel: int = DEEPRACER_STEERING_CHANNEL
    motor_channel: int = DEEPRACER_THROTTLE_CHANNEL
    calibration: Path | None = None  # DeepRacer's calibration.json; None = DeepRacer's defaults
    servo_enable_gpio: int | None = DEEPRACER_SERVO_ENABLE_GPIO  # None: the board has no servo power switch
    gpio_root: Path = SYSFS_GPIO


@dataclass
class PwmCar:
    vehicle: Vehicle
    camera: OpenCvCamera
    actuator: PwmActuator
    pilot: PilotSlot
    driver: LocalDriver
    safety: Safety
    camera_tap: FrameTap  # the camera's newest frame, for the video relay


def build_pwm_car(camera: int | str, wiring: PwmWiring = PwmWiring(), *, safety: Safety | None = None,
                  slot: PilotSlot | None = None) -> PwmCar:
    try:
        servo_cal, motor_cal = (load_calibration(wiring.calibration) if wiring.calibration is not None
                                else (SERVO_DEFAULT, MOTOR_DEFAULT))
        capture = OpenCvCamera(camera)
    except (CameraUnavailable, PwmUnavailable) as exc:
        raise HardwareUnavailable(str(exc)) from None
    try:
        actuator = _open_actuator(wiring, servo_cal, motor_cal)
    except PwmUnavailable as exc:
        capture.shutdown()
        raise HardwareUnavailable(str(exc)) from None
    slot = slot or PilotSlot()
    safety = safety or Safety()
    telemetry = Telemetry()
    driver = LocalDriver(slot, safety, telemetry)
    vehicle = Vehicle()
    vehicle.add(capture, outputs=[ch.CAMERA_IMAGE, ch.CAMERA_FRAME_TIME], name="OpenCvCamera")
    tap = FrameTap()
    vehicle.add(tap, inputs=[ch.CAMERA_IMAGE], name="CameraTap")
    vehicle.add(slot, inputs=[ch.CAMERA_IMAGE], outputs=[ch.PILOT_STEERING, ch.PILOT_SPEED, ch.PILOT_INFERENCE_MS],
                name="OnnxPilot")
    vehicle.add(ActionToDrive(slot.action_space), inputs=[ch.PILOT_STEERING, ch.PILOT_SPEED],
                outputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE])
    vehicle.add(safety, inputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE, ch.CAMERA_FRAME_TIME],
                outputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE, ch.SAFETY_STOPPED, ch.SAFETY_REASON])
    vehicle.add(actuator, inputs=[ch.DRIVE_STEERING, ch.DRIVE_THROTTLE], outputs=[ch.PWM_SERVO_NS, ch.PWM_MOTOR_NS])
    vehicle.add(telemetry, inputs=[ch.CAMERA_FRAME_TIME, ch.PILOT_INFERENCE_MS],
                outputs=[ch.TELEMETRY_FPS, ch.TELEMETRY_INFERENCE_MS])
    vehicle.add(driver, inputs=[ch.SAFETY_STOPPED, ch.SAFETY_REASON])
    return PwmCar(vehicle, capture, actuator, slot, driver, safety, tap)


def _open_actuator(wiring: PwmWiring, servo_cal: Calibration, motor_cal: Calibration) -> PwmActuator:
    """Both channels at neutral first, then the servos' power on: they wake up holding still."""
    chip_dir = pwm_chip_dir(wiring.root, wiring.chip)
    servo = PwmChannel(chip_dir, wiring.servo_channel, servo_cal)
    try:
        motor = PwmChannel(chip_dir, wiring.motor_channel, motor_cal)
    except PwmUnavailable:
        servo.disable()
        raise
    try:
        enable = (ServoEnable(wiring.servo_enable_gpio, wiring.gpio_root)
                  if wiring.servo_enable_gpio is not None else None)
    except PwmUnavailable:
        motor.disable()
        servo.disable()
        raise
    return PwmActuator(servo, motor, enable)
