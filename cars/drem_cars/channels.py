"""Names of the vehicle loop's shared channels (donkeycar-style slash-namespaced keys), in one place."""
from __future__ import annotations

CAMERA_IMAGE = "cam/image"              # uint8 HxW grayscale frame
CAMERA_FRAME_TIME = "cam/frame_time"    # monotonic seconds at capture
PILOT_STEERING = "pilot/steering_angle"  # degrees, + = left
PILOT_SPEED = "pilot/speed"              # action-space speed
PILOT_INFERENCE_MS = "pilot/inference_ms"
PILOT_ENABLED = "pilot/enabled"          # run_condition of the pilot
SAFETY_STOPPED = "safety/stopped"
SAFETY_REASON = "safety/reason"
DRIVE_STEERING = "drive/steering"        # unit steering in [-1, 1] after safety
DRIVE_THROTTLE = "drive/throttle"        # unit throttle in [0, 1] after safety and the staff cap
SIM_LAP_CROSSINGS = "sim/crossings"      # list of (timestamp_ms, sensor) crossed this tick
TELEMETRY_FPS = "telemetry/fps"
TELEMETRY_INFERENCE_MS = "telemetry/inference_ms"
PILOT_ABSENT = "pilot/absent"            # run_condition of the simulator's stand-in driver
PWM_SERVO_NS = "pwm/servo_duty_ns"       # duty cycle written to the steering servo
PWM_MOTOR_NS = "pwm/motor_duty_ns"       # duty cycle written to the drive motor
