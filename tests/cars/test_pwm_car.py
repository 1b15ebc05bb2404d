"""The DIY car's loop end to end without hardware: a video file the simulator's camera rendered stands in for the
camera, the real sample model (installed by the agent's own model store) drives, and a temp sysfs tree stands in for
the PWM chip. What the servo and motor receive must follow the pilot through DeepRacer's calibration."""
from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest

from drem_cars import channels as ch
from drem_cars import cli
from drem_cars.credentials import CredentialStore, StoredCredential
from drem_cars.model_store import InstalledModel, ModelStore, md5_of
from drem_cars.parts.drive_mapping import unit_throttle
from drem_cars.parts.pilot_onnx import OnnxPilot
from drem_cars.parts.pwm import MOTOR_DEFAULT, SERVO_DEFAULT
from drem_cars.pwm_car import PwmCar, PwmWiring, build_pwm_car

pytestmark = pytest.mark.unit

SAMPLE = Path(__file__).resolve().parents[2] / "sim" / "drem_sim" / "samples" / "drem-bc-sample.tar.gz"
VIDEO_FRAMES = 23  # about 1.5 s at 15 fps
LOOP_HZ = 15
BOUND_TICKS = LOOP_HZ * 30  # a loop that never meets its condition fails after 30 s instead of hanging
NEUTRAL_MOTOR, CENTRED_SERVO = MOTOR_DEFAULT.mid_ns, SERVO_DEFAULT.mid_ns


@pytest.fixture(scope="module")
def video(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The sim car's camera view while the simulator's demonstrator drives it off the start of reinvent_base,
    written losslessly (FFV1) so the test can decode exactly what the car's camera part will see."""
    from drem_cars.parts.sim_world import SimWorld
    from drem_sim.demonstrator import Demonstrator

    world = SimWorld("reinvent_base")
    demonstrator = Demonstrator(world.track)
    path = tmp_path_factory.mktemp("video") / "reinvent_base.avi"
    writer = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), 15, (160, 120), isColor=False)
    assert writer.isOpened()
    for _ in range(VIDEO_FRAMES):
        writer.write(world.render())
        world.command(demonstrator.act(world.params)["steering_angle"], 1.5)
        world.advance()
    writer.release()
    return path


@pytest.fixture(scope="module")
def sample_model(tmp_path_factory: pytest.TempPathFactory) -> InstalledModel:
    store = ModelStore(tmp_path_factory.mktemp("config") / "models")
    return store.install("sample", "drem-bc-sample", "drem-bc-sample", md5_of(SAMPLE),
                         download=lambda handle: handle.write(SAMPLE.read_bytes()))


def decoded_frames(path: Path) -> list[np.ndarray]:
    capture = cv2.VideoCapture(str(path))
    frames = []
    while True:
        ok, frame = capture.read()
        if not ok:
            return frames
        frames.append(cv2.cvtColor(frame, cv2.COLOR_BGR2GRAY))


SERVO_CHANNEL, MOTOR_CHANNEL = 1, 0  # a DeepRacer board: steering on 1, throttle on 0


def pwm_tree(base: Path) -> Path:
    """A temp stand-in for a DeepRacer's sysfs: class/pwm/pwmchip3 links to the board's PWM device 0000:00:17.0
    (channels 0 and 1 exported), class/gpio/gpio436 (the servo power switch) exported. Returns class/pwm."""
    chip = base / "devices" / "pci0000:00" / "0000:00:17.0" / "pwm" / "pwmchip3"
    for channel in (0, 1):
        (chip / f"pwm{channel}").mkdir(parents=True)
    (chip / "export").write_text("")
    pwm = base / "class" / "pwm"
    pwm.mkdir(parents=True)
    (pwm / "pwmchip3").symlink_to(chip)
    (base / "class" / "gpio" / "gpio436").mkdir(parents=True)
    return pwm


def gpio_root(pwm: Path) -> Path:
    return pwm.parent / "gpio"


def written(root: Path, channel: int, name: str) -> int:
    return int((root / "pwmchip3" / f"pwm{channel}" / name).read_text())


def servo_power(root: Path) -> str:
    return (gpio_root(root) / "gpio436" / "value").read_text()


class Recorder:
    """Last part of the loop: what each tick saw and what it wrote to the PWM files. After each tick it calls
    `after_tick(ticks)`, where a test acts on what it has seen so far (an emergency stop, stopping the loop)."""

    def __init__(self, root: Path, after_tick: Callable[[list[dict[str, Any]]], None] | None = None) -> None:
        self.root = root
        self.ticks: list[dict[str, Any]] = []
        self.after_tick = after_tick

    def run(self, image, steering, speed, stopped, reason, servo_ns, motor_ns):  # type: ignore[no-untyped-def]
        self.ticks.append({"image": None if image is None else image.copy(), "steering": steering, "speed": speed,
                           "stopped": stopped, "reason": reason, "servo_ns": servo_ns, "motor_ns": motor_ns,
                           "servo_file": written(self.root, SERVO_CHANNEL, "duty_cycle"),
                           "motor_file": written(self.root, MOTOR_CHANNEL, "duty_cycle"),
                           "servo_power": servo_power(self.root)})
        if self.after_tick is not None:
            self.after_tick(self.ticks)


def car_with_recorder(video: Path, root: Path, model: InstalledModel) -> tuple[PwmCar, Recorder]:
    car = build_pwm_car(str(video), PwmWiring(root=root, gpio_root=gpio_root(root)))
    car.driver.load_model(model)  # what the agent does once the assigned model is verified and unpacked
    recorder = Recorder(root)
    car.vehicle.add(recorder, inputs=[ch.CAMERA_IMAGE, ch.PILOT_STEERING, ch.PILOT_SPEED, ch.SAFETY_STOPPED,
                                      ch.SAFETY_REASON, ch.PWM_SERVO_NS, ch.PWM_MOTOR_NS])
    return car, recorder


def test_the_sample_model_drives_the_pwm_outputs_from_a_video_until_the_video_ends(
        video: Path, sample_model: InstalledModel, tmp_path: Path) -> None:
    root = pwm_tree(tmp_path / "pwm")
    frames = decoded_frames(video)
    assert len(frames) == VIDEO_FRAMES
    reference = OnnxPilot(sample_model.path)
    space = reference.action_space
    car, recorder = car_with_recorder(video, root, sample_model)
    assert written(root, 0, "period") == 20_000_000 and written(root, 1, "enable") == 1
    assert servo_power(root) == "0", "GPIO 436 low: servos powered (after both channels went neutral)"

    def stop_five_ticks_after_the_video_ended_and_its_last_frame_went_stale(ticks: list[dict[str, Any]]) -> None:
        stale = [i for i, t in enumerate(ticks) if t["reason"] and "camera frame is" in t["reason"]]
        if car.camera.ended and stale and len(ticks) - stale[0] >= 5:
            car.vehicle.stop()

    recorder.after_tick = stop_five_ticks_after_the_video_ended_and_its_last_frame_went_stale
    stats = car.vehicle.start(rate_hz=LOOP_HZ, max_loops=BOUND_TICKS)  # the 1.5 s video, then 0.5 s until stale
    assert stats.loops < BOUND_TICKS, "the loop stopped on its condition, not at the bound"

    driving = [t for t in recorder.ticks if not t["stopped"]]
    seen = set()
    for tick in driving:
        index = next(i for i, frame in enumerate(frames) if np.array_equal(frame, tick["image"]))
        seen.add(index)
        steering, speed, _ = reference.run(frames[index])
        assert (tick["steering"], tick["speed"]) == (steering, speed), "the car's pilot is the sample model"
        servo = SERVO_DEFAULT.duty_ns(steering / space.steering_scale)
        motor = MOTOR_DEFAULT.duty_ns(unit_throttle(speed, space.max_speed))
        assert (tick["servo_ns"], tick["motor_ns"]) == (servo, motor)
        assert (tick["servo_file"], tick["motor_file"]) == (servo, motor), "written to sysfs, in nanoseconds"
        assert tick["servo_power"] == "0"
        assert 1_200_000 <= servo <= 1_700_000
        assert speed >= space.speed[0] > 0 and motor < NEUTRAL_MOTOR, "forward (polarity −1: below mid)"
    assert len(seen) >= VIDEO_FRAMES // 2, f"the video played through the camera part (frames {sorted(seen)})"
    assert len({t["servo_ns"] for t in driving}) > 1, "steering follows the frames, not a constant"

    assert car.camera.ended
    last = recorder.ticks[-5:]
    assert all(t["stopped"] and "camera frame is" in t["reason"] for t in last), [t["reason"] for t in last]
    assert all((t["servo_file"], t["motor_file"]) == (CENTRED_SERVO, NEUTRAL_MOTOR) for t in last)
    assert written(root, MOTOR_CHANNEL, "duty_cycle") == NEUTRAL_MOTOR
    assert written(root, 0, "enable") == 0 and written(root, 1, "enable") == 0, "PWM disabled when the loop ends"
    assert servo_power(root) == "1", "and the servos' power switched off"


def test_throttle_cap_scales_the_motor_and_emergency_stop_puts_it_to_neutral(
        video: Path, sample_model: InstalledModel, tmp_path: Path) -> None:
    root = pwm_tree(tmp_path / "pwm")
    space = OnnxPilot(sample_model.path).action_space
    car, recorder = car_with_recorder(video, root, sample_model)
    stopped_at: list[int] = []

    def emergency_stop_after_three_driving_ticks_then_watch_six_more(ticks: list[dict[str, Any]]) -> None:
        if not stopped_at and sum(not t["stopped"] for t in ticks) == 3:
            car.driver.emergency_stop()  # what the agent does on staff's EMERGENCY_STOP
            stopped_at.append(len(ticks))
        elif stopped_at and len(ticks) - stopped_at[0] >= 6:
            car.vehicle.stop()

    recorder.after_tick = emergency_stop_after_three_driving_ticks_then_watch_six_more
    car.driver.set_throttle_cap(50)
    stats = car.vehicle.start(rate_hz=LOOP_HZ, max_loops=BOUND_TICKS)
    assert stats.loops < BOUND_TICKS and stopped_at, "the loop stopped on its condition, not at the bound"

    before, after = recorder.ticks[:stopped_at[0]], recorder.ticks[stopped_at[0]:]
    assert len(after) == 6
    driving = [t for t in before if not t["stopped"]]
    assert driving, [t["reason"] for t in before]
    for tick in driving:
        assert tick["motor_file"] == MOTOR_DEFAULT.duty_ns(0.5 * unit_throttle(tick["speed"], space.max_speed))
        assert tick["motor_file"] < NEUTRAL_MOTOR
    assert all(t["stopped"] and t["reason"] == "emergency stop" for t in after)
    assert all((t["servo_file"], t["motor_file"]) == (CENTRED_SERVO, NEUTRAL_MOTOR) for t in after)
    assert car.driver.faults() == ["stopped: emergency stop"], "the heartbeat tells staff why"


def run_args(config_dir: Path, *extra: str) -> argparse.Namespace:
    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    return parser.parse_args(["--config-dir", str(config_dir), "run", "--pwm", "--gpio-root",
                              str(config_dir / "no-gpio"), *extra])


def activated(config_dir: Path) -> Path:
    CredentialStore(config_dir).save(StoredCredential(api="http://127.0.0.1:9", device_id="car-1", device_kind="car",
                                                      hostname="diy-1", fleet_id="f", credential="car-1.secret"))
    return config_dir


def test_a_missing_camera_is_a_clear_message_and_exit_1(tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = activated(tmp_path / "config")
    root = pwm_tree(tmp_path / "pwm")
    assert cli.run(run_args(config, "--camera", str(tmp_path / "no-such.avi"), "--pwm-root", str(root))) == 1
    err = capsys.readouterr().err
    assert "cannot open camera" in err and "no-such.avi" in err and "Traceback" not in err
    assert not (root / "pwmchip3" / "pwm0" / "duty_cycle").exists(), "nothing driven without a camera"
    assert cli.run(run_args(config, "--camera", "7", "--pwm-root", str(root))) == 1
    assert "cannot open camera '/dev/video7'" in capsys.readouterr().err


def test_a_missing_pwm_chip_or_bad_calibration_is_a_clear_message_and_exit_1(
        video: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = activated(tmp_path / "config")
    assert cli.run(run_args(config, "--camera", str(video), "--pwm-root", str(tmp_path / "nothing"))) == 1
    err = capsys.readouterr().err
    assert f"no PWM chip of the DeepRacer board (device 0000:00:17.0) under {tmp_path / 'nothing'}" in err
    assert "Traceback" not in err
    calibration = tmp_path / "calibration.json"
    calibration.write_text(json.dumps({"Calibration": {"Servo": {"min": 1}}}))
    root = pwm_tree(tmp_path / "pwm")
    assert cli.run(run_args(config, "--camera", str(video), "--pwm-root", str(root),
                            "--calibration", str(calibration))) == 1
    assert f"calibration file {calibration}" in capsys.readouterr().err


def test_servos_that_cannot_be_powered_are_a_clear_message_exit_1_and_leave_pwm_off(
        video: Path, tmp_path: Path, capsys: pytest.CaptureFixture) -> None:
    config = activated(tmp_path / "config")
    root = pwm_tree(tmp_path / "sys")
    assert cli.run(run_args(config, "--camera", str(video), "--pwm-root", str(root))) == 1  # no gpio436 there
    err = capsys.readouterr().err
    assert "cannot switch the servos on through GPIO 436" in err and "Traceback" not in err
    assert written(root, 0, "enable") == 0 and written(root, 1, "enable") == 0
    assert cli.run(run_args(config, "--camera", str(video), "--servo-enable-gpio", "pin7")) == 2
    assert "--servo-enable-gpio takes a GPIO number or 'none'" in capsys.readouterr().err
