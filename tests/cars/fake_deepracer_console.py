"""A stand-in for an AWS DeepRacer's device console, rebuilt from the car's own source code.

The real console is a Flask app (aws-deepracer/aws-deepracer-webserver-pkg) that turns HTTP calls into ROS 2 service
calls to the other nodes on the car. This fake is a Flask app too, with the same routes, methods, field names and
answers, and the behaviour of the nodes behind them (ctrl_pkg's mode state machine, systems_pkg's model loader, the
model optimizer and the battery node), each cited where it is modelled. `[webserver models.py]` etc. below name files
of:

- aws-deepracer/aws-deepracer-webserver-pkg  webserver_pkg/webserver_pkg/{webserver,models,vehicle_control,calibration,
  led_api,device_info_api,constants,webserver_publisher_node}.py
- aws-deepracer/aws-deepracer-ctrl-pkg        ctrl_pkg/src/ctrl_node.cpp, ctrl_pkg/src/ctrl_state.cpp,
  ctrl_pkg/include/ctrl_pkg/ctrl_state.hpp
- aws-deepracer/aws-deepracer-systems-pkg     deepracer_systems_pkg/model_loader_module/{model_loader_node,
  model_install_state,model_loader_config}.py, deepracer_systems_pkg/file_system_utils.py
- aws-deepracer/aws-deepracer-model-optimizer-pkg  model_optimizer_pkg/model_optimizer_node.py
- aws-deepracer/aws-deepracer-i2c-pkg         i2c_pkg/src/battery_node.cpp
- aws-deepracer/aws-deepracer-camera-pkg      camera_pkg/src/camera_node.cpp (publishes the `display_mjpeg` topic)
- RobotWebTools/web_video_server              src/multipart_stream.cpp (the MJPEG the console hands out): the car's
  camera is `GET /route?topic=/camera_pkg/display_mjpeg&width=480&height=360`, behind the console login, as DREM's
  device links and the community console (deepracer-custom-console) open it; the route itself is in [webserver.py],
  which our index does not hold, so only its URL and the login in front of it are modelled, not its code
- aws-deepracer/aws-deepracer-navigation-pkg  deepracer_navigation_pkg/deepracer_navigation_node.py (throttle_scale
  starts at 0.0), as recorded in ../shared/reference/deepracer-formats.md §2.2 (that file was not in our index)

What is real here: CSRF is Flask-WTF's own CSRFProtect (every POST/PUT, including POST /login; the token comes from
`<meta name="csrf-token">`; 400 "The CSRF token has expired." after WTF_CSRF_TIME_LIMIT, 3600 s), and the session
cookie is marked Secure as on the car (`SESSION_COOKIE_SECURE=True`). What is not: the real car serves HTTPS through
nginx; this fake serves plain HTTP on loopback (a client must send the Secure cookie back anyway). The car's login
module (login page, password hashing) is not in the public source we could read; the fake keeps what clients rely on
and what the community console (aws-deepracer-community/deepracer-custom-console website/src/pages/login.tsx,
common/helpers/api-helper.ts) expects: form field `password`, the answer "failure" and no cookie on a wrong
password, one `deepracer_token` cookie with max_age 1 h, 401 on /api calls without the current token.

A restart (`FakeConsole.restart()`, what a battery swap does; `power_off()` then `power_on()` when a test needs to
see the car down in between): the web server process starts again. What it keeps of the logins follows what we could
read upstream: [webserver constants.py] keeps the login token in a file, TOKEN_PATH = /opt/aws/deepracer/token.txt,
which a restart does not remove; the Flask session (and with it the CSRF secret) is signed with a SECRET_KEY that the
copies of [webserver.py] we could read set to a constant, "secret_" (UNSW-Sunswift/aws-deepracer-webserver-pkg
webserver_pkg/webserver_pkg/webserver.py, a fork keeping Amazon's header; Amazon's own webserver.py and login.py are
not in our index). So a plain restart keeps our login and session; `restart(forget_logins=True)` is the case we cannot
rule out without login.py (a token cleared at boot): a fresh key and no token. The nodes boot as at power-on: manual
mode, `modelLoadingStatus_ = "error"`, no model loaded, throttle_scale 0 ([ctrl_node.cpp] init(), [ctrl_state.hpp],
[deepracer_navigation_node.py]). What is on disk stays: the model folders under /opt/aws/deepracer/artifacts, which
`/api/uploaded_model_list` lists by reading that directory ([webserver models.py] get_uploaded_models_list,
get_file_and_folder_info). While it is off the car answers nothing (connection refused).

Time: `FakeConsole.advance_clock(seconds)` moves the clock that Flask-WTF's token check (itsdangerous) and the
login's cookie age read, so a test can pass the one-hour limits without waiting an hour.
"""
from __future__ import annotations

import gzip
import hashlib
import io
import json
import logging
import os
import ssl
import tarfile
import threading
import time
import uuid
from dataclasses import dataclass, field
from functools import wraps
from typing import Any

import itsdangerous.timed
from flask import (
    Flask,
    Response,
    jsonify,
    make_response,
    redirect,
    render_template_string,
    request,
    stream_with_context,
)
from flask_wtf.csrf import CSRFProtect
from werkzeug.serving import make_server

from drem_local.stack import free_port

# [webserver constants.py]
LED_SCALING_FACTOR = 39215
MAX_AUTO_THROTTLE_VAL = 100.0
MODEL_FILE_TYPE = ".pb"
DEEPRACER_TOKEN = "deepracer_token"
SENSOR_KEYS = {"observation": 1, "LIDAR": 2, "SECTOR_LIDAR": 3, "LEFT_CAMERA": 4, "FRONT_FACING_CAMERA": 5,
               "STEREO_CAMERAS": 6}
SENSOR_NAMES = {1: "Camera", 2: "LiDAR", 3: "LiDAR", 4: "Left camera", 5: "Front-facing camera", 6: "Stereo camera"}
TRAINING_ALGORITHMS = {"clipped_ppo": "Clipped PPO", "sac": "Soft actor critic"}
ACTION_SPACE_TYPES = {"discrete": "Discrete", "continuous": "Continuous"}
# [ctrl_node.cpp] enum CtrlState
MANUAL, AUTONOMOUS, CALIBRATION = 0, 1, 2
COOKIE_MAX_AGE_S = 3600
# [camera_node.cpp] DISPLAY_MSG_TOPIC "display_mjpeg" in the camera_pkg namespace; [multipart_stream.cpp] and
# web_video_server's MJPEG streamer use the boundary "boundarydonotcross"; the camera delivers 15 fps.
DISPLAY_TOPIC = "/camera_pkg/display_mjpeg"
VIDEO_BOUNDARY = "boundarydonotcross"
CAMERA_FPS = 15

PAGE = """<!doctype html><html><head><meta charset="utf-8"><title>AWS DeepRacer</title>
<meta name="csrf-token" content="{{ csrf_token() }}"></head><body>{{ body }}</body></html>"""


class ConsoleClock:
    """time.time() plus an offset a test can move forward; stands in for itsdangerous' clock while the fake runs."""

    def __init__(self) -> None:
        self.offset = 0.0

    def time(self) -> float:
        return time.time() + self.offset


@dataclass
class CarState:
    """What the ROS nodes behind the web server hold."""
    password: str
    clock: ConsoleClock
    load_seconds: float = 0.3
    optimizer_fails: bool = False              # [ctrl_state.cpp] "Model optimizer failed." -> "error"
    battery_level: int = 7                     # [battery_node.cpp] 0..11, -1 when the chip cannot be read
    camera_connected: bool = True
    frames_served: int = 0                     # camera frames sent on /route, all viewers together
    token: str | None = None                   # [login] one token at a time: a new login replaces it
    token_issued: float = 0.0
    mode: int = MANUAL                         # [ctrl_node.cpp] init(): the manual state is active at boot
    active: dict[int, bool] = field(default_factory=lambda: {MANUAL: True, AUTONOMOUS: False, CALIBRATION: False})
    auto_loading_status: str = "error"         # [ctrl_state.hpp] modelLoadingStatus_ = "error"
    loaded_model: str | None = None
    load_requests: int = 0
    throttle_scale: float = 0.0                # [deepracer_navigation_node.py] throttle_scale starts at 0.0
    led_pwm: tuple[int, int, int] = (0, 0, 0)
    artifacts: dict[str, dict[str, bytes]] = field(default_factory=dict)  # /opt/aws/deepracer/artifacts/<dir>/<file>
    calls: list[tuple[str, str, Any]] = field(default_factory=list)
    lock: threading.RLock = field(default_factory=threading.RLock)
    stopping: threading.Event = field(default_factory=threading.Event)

    @property
    def driving(self) -> bool:
        """The model drives the wheels: autonomous, started, a model loaded and a throttle above 0."""
        with self.lock:
            return (self.mode == AUTONOMOUS and self.active[AUTONOMOUS] and self.auto_loading_status == "loaded"
                    and self.throttle_scale > 0)

    @property
    def tail_light(self) -> tuple[int, int, int]:
        return tuple(value // LED_SCALING_FACTOR for value in self.led_pwm)  # type: ignore[return-value]

    # --- ctrl_pkg ---
    def set_mode(self, mode: int) -> None:
        """[ctrl_node.cpp] stateHdl: the current state is deactivated, then the new one becomes current."""
        with self.lock:
            self.active[self.mode] = False
            self.mode = mode

    def loading_status(self) -> str:
        """[ctrl_node.cpp] isModelLoadingHdl asks the current state; manual and calibration answer "error"."""
        with self.lock:
            return self.auto_loading_status if self.mode == AUTONOMOUS else "error"

    def request_load(self, model_path: str) -> None:
        """[ctrl_node.cpp] loadModelHdl runs the current state's loadModelReq in a detached thread and answers
        success at once; [ctrl_state.cpp] ManualDriveCtrl/CalibrationCtrl::loadModelReq refuse without a trace."""
        with self.lock:
            self.load_requests += 1
            seq, mode = self.load_requests, self.mode
        if mode == AUTONOMOUS:
            threading.Thread(target=self._load, args=(seq, model_path), daemon=True).start()

    def _load(self, seq: int, model_path: str) -> None:
        """[ctrl_state.cpp] AutoDriveCtrl::loadModelReq: "loading", model optimizer, inference node, action space;
        a newer request wins. [model_optimizer_node.py] optimize_tf_model appends ".pb" to the name it is given."""
        with self.lock:
            self.auto_loading_status = "loading"
        if self.stopping.wait(self.load_seconds):
            return
        folder, _, name = model_path.partition("/")
        with self.lock:
            if self.load_requests > seq:
                return
            found = f"{name}{MODEL_FILE_TYPE}" in self.artifacts.get(folder, {}) and not self.optimizer_fails
            self.auto_loading_status = "loaded" if found else "error"
            if found:
                self.loaded_model = folder

    def boot(self, *, forget_logins: bool = False) -> None:
        """Power-on state of the nodes (see the module docstring); the artifacts on disk are kept, and the login
        token too (token.txt) unless `forget_logins`."""
        with self.lock:
            self.load_requests += 1  # a load still running in the old process never finishes
            if forget_logins:
                self.token, self.token_issued = None, 0.0
            self.mode = MANUAL
            self.active = {MANUAL: True, AUTONOMOUS: False, CALIBRATION: False}
            self.auto_loading_status = "error"
            self.loaded_model = None
            self.throttle_scale = 0.0
            self.led_pwm = (0, 0, 0)

    # --- systems_pkg model loader ---
    def install_upload(self, folder: str, archive_name: str, data: bytes) -> None:
        """[model_loader_node.py] transfer_models + [model_install_state.py] install_thread: unpack the archive,
        take the one *.pb found anywhere in it as <model name>/model.pb, the root model_metadata.json beside it,
        and write checksum.txt; no .pb (or more than one) installs nothing. The model name is the archive name up
        to its first dot, spaces replaced by '_'."""
        model_name = archive_name.split(".", 1)[0].replace(" ", "_")
        try:
            with tarfile.open(fileobj=io.BytesIO(gzip.decompress(data)), mode="r:") as tar:
                files = {os.path.normpath(m.name): tar.extractfile(m).read()  # type: ignore[union-attr]
                         for m in tar.getmembers() if m.isfile()}
        except (OSError, EOFError, tarfile.TarError):
            return  # [model_loader_node.py] extract_archive fails: the model is ignored
        models = [name for name in files if os.path.splitext(name)[1] == MODEL_FILE_TYPE]
        if len(models) != 1:
            return
        installed = {"model.pb": files[models[0]],
                     "checksum.txt": (hashlib.md5(files[models[0]]).hexdigest() + "\n").encode()}
        if "model_metadata.json" in files:
            installed["model_metadata.json"] = files["model_metadata.json"]
        with self.lock:
            self.artifacts[model_name] = installed


SECRET_KEY = "secret_"  # [webserver.py] as the fork we could read sets it: the same key at every start


def create_app(state: CarState, secret_key: str = SECRET_KEY) -> Flask:
    app = Flask(__name__)
    # [webserver.py] SECRET_KEY, SESSION_COOKIE_SECURE, CSRFProtect().init_app(app); WTF_CSRF_TIME_LIMIT is
    # Flask-WTF's default 3600 s.
    app.config.update(SECRET_KEY=secret_key, SESSION_COOKIE_SECURE=True, WTF_CSRF_TIME_LIMIT=3600)
    CSRFProtect(app)

    def logged_in() -> bool:
        with state.lock:
            token = request.cookies.get(DEEPRACER_TOKEN)
            # An hour after the login the browser drops the cookie (max_age); the car then sees no token.
            return (token is not None and token == state.token
                    and state.clock.time() - state.token_issued < COOKIE_MAX_AGE_S)

    def authenticated(view):  # type: ignore[no-untyped-def]
        @wraps(view)
        def wrapper(*args: Any, **kwargs: Any):  # type: ignore[no-untyped-def]
            if not logged_in():
                return "Unauthorized", 401
            return view(*args, **kwargs)
        return wrapper

    def record(value: Any = None) -> None:
        with state.lock:
            state.calls.append((request.method, request.path, value))

    def body() -> dict[str, Any]:
        data = request.get_json(silent=True)
        record(data)
        return data if isinstance(data, dict) else {}

    @app.get("/")
    def home():  # type: ignore[no-untyped-def]
        if not logged_in():
            return redirect("/login")
        return render_template_string(PAGE, body="DeepRacer home")

    @app.route("/login", methods=["GET", "POST"])
    def login():  # type: ignore[no-untyped-def]
        if request.method == "GET":
            return render_template_string(PAGE, body='<form method="post"><input name="password"></form>')
        record("password")
        if request.form.get("password") != state.password:
            return "failure"
        with state.lock:
            state.token, state.token_issued = str(uuid.uuid4()), state.clock.time()
            token = state.token
        reply = make_response("success")
        reply.set_cookie(DEEPRACER_TOKEN, token, max_age=COOKIE_MAX_AGE_S, httponly=True)
        return reply

    # --- [webserver vehicle_control.py] ---
    @app.route("/api/drive_mode", methods=["PUT", "POST"])
    @authenticated
    def drive_mode():  # type: ignore[no-untyped-def]
        mode = body().get("drive_mode")
        if mode is None:
            return jsonify({"success": False, "reason": "drive_mode must be set."})
        state.set_mode(MANUAL if mode == "manual" else AUTONOMOUS)
        return jsonify(success=True)

    @app.route("/api/start_stop", methods=["PUT", "POST"])
    @authenticated
    def start_stop():  # type: ignore[no-untyped-def]
        value = body().get("start_stop")
        if value is None:
            return jsonify({"success": False, "reason": "start_stop must be set."})
        with state.lock:  # [ctrl_node.cpp] ctrlStateHdl: (de)activates the current state
            state.active[state.mode] = value != "stop"
        return jsonify({"success": True})

    @app.route("/api/max_nav_throttle", methods=["PUT", "POST"])
    @authenticated
    def max_nav_throttle():  # type: ignore[no-untyped-def]
        value = body().get("throttle")
        if value is None:
            return jsonify({"success": False, "reason": "value must be set."})
        try:
            scale = value / MAX_AUTO_THROTTLE_VAL
        except TypeError:
            return jsonify(success=False, reason="Unable to reach navigation throttle server")
        with state.lock:  # [ctrl_state.cpp] only AutoDriveCtrl::setConstantThrottle applies it, within 0..1
            if state.mode == AUTONOMOUS and 0.0 <= scale <= 1.0:
                state.throttle_scale = scale
        return jsonify({"success": True})

    # --- [webserver calibration.py] ---
    @app.get("/api/set_calibration_mode")
    @authenticated
    def set_calibration_mode():  # type: ignore[no-untyped-def]
        record()
        state.set_mode(CALIBRATION)
        with state.lock:
            state.active[CALIBRATION] = True
        return jsonify(success=True)

    # --- [webserver led_api.py] + [ctrl_state.cpp] set/getLedValue: only CalibrationCtrl reaches the servo node ---
    @app.post("/api/set_led_color")
    @authenticated
    def set_led_color():  # type: ignore[no-untyped-def]
        data = body()
        try:
            rgb = [int(data[key]) for key in ("red", "green", "blue")]
        except (KeyError, TypeError, ValueError):
            return jsonify(success=False, reason="Error")
        if any(value < 0 or value > 255 for value in rgb):
            return jsonify(success=False, reason="Input is not valid")
        with state.lock:
            if state.mode == CALIBRATION:
                state.led_pwm = tuple(value * LED_SCALING_FACTOR for value in rgb)  # type: ignore[assignment]
        return jsonify({"success": True})

    @app.get("/api/get_led_color")
    @authenticated
    def get_led_color():  # type: ignore[no-untyped-def]
        with state.lock:
            red, green, blue = state.tail_light if state.mode == CALIBRATION else (0, 0, 0)
        return jsonify({"red": red, "green": green, "blue": blue, "success": True})

    # --- [webserver device_info_api.py] ---
    @app.get("/api/get_battery_level")
    @authenticated
    def get_battery_level():  # type: ignore[no-untyped-def]
        record()
        return jsonify({"battery_level": state.battery_level, "success": True})

    # --- [webserver models.py] ---
    @app.route("/api/uploadModels", methods=["POST", "PUT"])
    @authenticated
    def upload_models():  # type: ignore[no-untyped-def]
        file_obj = request.files["file"]
        file_name = file_obj.filename or ""
        record(file_name)
        if not file_name.endswith(".tar.gz"):
            return jsonify({"success": False, "message": "Failed to upload the model. Not a .tar.gz file"})
        folder, data = file_name[:-7], file_obj.read()
        with state.lock:  # the folder is always recreated, holding the uploaded file
            state.artifacts[folder] = {os.path.basename(file_name): data}
        state.install_upload(folder, file_name, data)  # [model_loader_node.py] console_model_action -> "done-upload"
        return jsonify({"success": True, "message": "Model uploaded successfully to your vehicle"})

    @app.route("/api/models/<model_folder_name>/<model_name>", methods=["PUT", "POST"])
    @authenticated
    def load_model(model_folder_name: str, model_name: str):  # type: ignore[no-untyped-def]
        record()
        with state.lock:
            files = dict(state.artifacts.get(model_folder_name, {}))
        # [model_loader_node.py] verify_model_ready: the folder must hold a non-empty checksum.txt
        if not files.get("checksum.txt", b"").strip():
            return jsonify({"success": False, "reason": "Model optimization failed!"})
        try:
            reason = metadata_refusal(files)
            if reason is not None:
                return jsonify({"success": False, "reason": reason})
        except Exception:  # noqa: BLE001 - the route's own catch-all
            return jsonify({"success": False, "reason": "Unable to reach model state server"})
        state.request_load(f"{model_folder_name}/{model_name}")
        return jsonify({"success": True})

    def metadata_refusal(files: dict[str, bytes]) -> str | None:
        """[webserver models.py] api_load_model's checks, in its order, with its messages."""
        if "model_metadata.json" not in files:
            return "No model_metadata_file for the model selected"
        try:
            data = json.loads(files["model_metadata.json"])
        except ValueError:
            return "Error while reading model_metadata.json"
        sensors = [SENSOR_KEYS["observation"]]  # [webserver models.py] get_sensors: no key means "observation"
        if "sensor" in data:
            try:
                names = set(data["sensor"])
            except TypeError:
                return "Error while getting sensor names from model_metadata.json"
            if not all(name in SENSOR_KEYS for name in names):
                return "The sensor configurations of your vehicle and trained model must match"
            sensors = [SENSOR_KEYS[name] for name in names]
        if data.get("training_algorithm", "clipped_ppo") not in TRAINING_ALGORITHMS:
            return "The training algorithm value is incorrect"
        kind = data.get("action_space_type", "discrete")
        if kind not in ACTION_SPACE_TYPES:
            return "The action space type value is incorrect"
        if "action_space" not in data:
            return "No action space value found in model_metadata.json"
        if not valid_action_space(data["action_space"], kind):
            return "Incorrect values in model_metadata.json"
        wanted = set(sensors)
        missing = []  # [webserver models.py] verify_sensor_connection; this car has one camera and no LiDAR
        if wanted & {2, 3}:
            missing.append("LiDAR")
        if 6 in wanted:
            missing.append("Stereo camera")
        if wanted & {1, 4, 5} and not state.camera_connected:
            missing.append("Front-facing camera")
        if missing:
            return f"Check the connections for the {', '.join(missing)} {'sensors' if len(missing) > 1 else 'sensor'}"
        return None

    def valid_action_space(space: Any, kind: str) -> bool:
        """[webserver models.py] validate_action_space, the same expressions."""
        if kind == "discrete":
            return all("steering_angle" in action and "speed" in action for action in space)
        if "steering_angle" not in space or "speed" not in space:
            return False
        steering, speed = space["steering_angle"], space["speed"]
        return not ("high" not in steering or "low" not in steering or "high" not in speed or "low" not in speed
                    or steering["high"] <= steering["low"] or speed["high"] <= speed["low"])

    @app.get("/api/isModelLoading")
    @authenticated
    def is_model_loading():  # type: ignore[no-untyped-def]
        return jsonify({"success": True, "isModelLoading": state.loading_status()})

    @app.get("/api/models")
    @authenticated
    def list_models():  # type: ignore[no-untyped-def]
        models = []
        with state.lock:
            folders = {name: dict(files) for name, files in state.artifacts.items()}
        for folder, files in sorted(folders.items()):
            if "model.pb" not in files:
                continue
            try:
                data = json.loads(files["model_metadata.json"])
            except (KeyError, ValueError):
                continue
            sensors = [SENSOR_KEYS.get(name, 1) for name in data.get("sensor", ["observation"])]
            models.append({"model_name": "model", "model_folder_name": folder,
                           "model_training_algorithm": TRAINING_ALGORITHMS.get(data.get("training_algorithm",
                                                                                        "clipped_ppo"), "--"),
                           "model_action_space_type": ACTION_SPACE_TYPES.get(data.get("action_space_type",
                                                                                      "discrete"), "--"),
                           "model_sensors": [SENSOR_NAMES[s] for s in sensors], "is_select_disabled": False})
        return jsonify({"models": models, "sensor_status": {"camera_status": "connected",
                                                            "stereo_status": "not_connected",
                                                            "lidar_status": "not_connected"}})

    @app.get("/api/uploaded_model_list")
    @authenticated
    def uploaded_model_list():  # type: ignore[no-untyped-def]
        """[webserver models.py] get_uploaded_models_list: one entry per folder of MODEL_DIRECTORY_PATH (whatever it
        holds, installed or not), from get_file_and_folder_info: name, size (`du -sh`), creation_time, status and the
        metadata's display names ("--" when unreadable)."""
        with state.lock:
            folders = {name: dict(files) for name, files in state.artifacts.items()}
        return jsonify([{"name": name, "size": f"{sum(len(v) for v in files.values()) // 1024}K",
                         "creation_time": state.clock.time(), "status": "Ready", "training_algorithm": "--",
                         "action_space_type": "--", "sensors": "--"} for name, files in sorted(folders.items())])

    @app.route("/api/deleteModels", methods=["POST", "PUT"])
    @authenticated
    def delete_models():  # type: ignore[no-untyped-def]
        filenames = body()["filenames"]
        deleted_all = True
        with state.lock:  # [model_loader_node.py] action 0: remove_dir_tree; a missing folder is "failure-on-delete"
            for name in filenames:
                deleted_all = state.artifacts.pop(name, None) is not None and deleted_all
        if deleted_all:
            return jsonify({"success": True, "message": "Models deleted successfully from your vehicle"})
        return jsonify({"success": False, "message": "Failed to delete the selected models"})

    @app.get("/api/is_model_installed")
    @authenticated
    def is_model_installed():  # type: ignore[no-untyped-def]
        with state.lock:
            installed = request.args.get("filename") in state.artifacts
        if installed:
            return jsonify({"success": True, "message": "Model is installed"})
        return jsonify({"success": False, "message": "Model is not installed"})

    # --- the camera: [camera_node.cpp] publishes /camera_pkg/display_mjpeg at the camera's rate; the console's
    # `/route?topic=…&width=&height=` hands it out as web_video_server's MJPEG ([multipart_stream.cpp]) ---
    @app.get("/route")
    @authenticated
    def video_route():  # type: ignore[no-untyped-def]
        record(request.query_string.decode())
        try:
            width, height = int(request.args.get("width", 640)), int(request.args.get("height", 480))
        except ValueError:
            return "width and height must be numbers", 400
        if request.args.get("topic") != DISPLAY_TOPIC or not (0 < width <= 1920 and 0 < height <= 1080):
            return "Unknown topic or size", 404
        return Response(stream_with_context(camera_parts(state, width, height)),
                        headers={"Connection": "close", "Server": "web_video_server", "Pragma": "no-cache",
                                 "Cache-Control": "no-cache, no-store, must-revalidate, pre-check=0, post-check=0, "
                                                  "max-age=0",
                                 "Content-type": f"multipart/x-mixed-replace;boundary={VIDEO_BOUNDARY}",
                                 "Access-Control-Allow-Origin": "*"})

    return app


def camera_frame(width: int, height: int, number: int) -> bytes:
    """A JPEG that differs frame to frame (a bar moving across, the frame number in its grey), as a camera's do."""
    import cv2
    import numpy as np

    image = np.full((height, width, 3), 40, np.uint8)
    x = (number * 7) % max(1, width - 20)
    image[:, x:x + 20] = (number * 13) % 200 + 55
    ok, encoded = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 80])
    assert ok
    return encoded.tobytes()


def camera_parts(state: CarState, width: int, height: int):  # type: ignore[no-untyped-def]
    """[multipart_stream.cpp] send_initial_header writes `--boundary\r\n`; each part is the headers Content-type,
    X-Timestamp (`%.06lf` seconds) and Content-Length, a blank line, the JPEG, then `\r\n--boundary\r\n`. Frames
    come at the camera's 15 fps ([camera_node.cpp] produceFrames publishes every captured frame)."""
    yield f"--{VIDEO_BOUNDARY}\r\n".encode()
    number = 0
    while not state.stopping.is_set() and state.camera_connected:
        number += 1
        jpeg = camera_frame(width, height, number)
        with state.lock:
            state.frames_served += 1
        yield (f"Content-type: image/jpeg\r\nX-Timestamp: {time.time():.06f}\r\n"
               f"Content-Length: {len(jpeg)}\r\n\r\n").encode() + jpeg + f"\r\n--{VIDEO_BOUNDARY}\r\n".encode()
        state.stopping.wait(1 / CAMERA_FPS)


class FakeConsole:
    def __init__(self, password: str = "car-password", *, load_seconds: float = 0.3, port: int = 0,
                 tls: ssl.SSLContext | None = None) -> None:
        """`tls`: serve HTTPS with this context, as the car does (through nginx, with its self-signed certificate)."""
        logging.getLogger("werkzeug").setLevel(logging.WARNING)  # no access log in test output
        self.clock = ConsoleClock()
        self.state = CarState(password=password, clock=self.clock, load_seconds=load_seconds)
        self.tls = tls
        # Below the kernel's ephemeral range, as a car's fixed port is: restart() binds it again, and a port the
        # kernel handed out could meanwhile be the local end of some test's outgoing connection (seen once in CI).
        self.port = port or free_port("127.0.0.1")
        self.server = make_server("127.0.0.1", self.port, create_app(self.state), threaded=True, ssl_context=tls)
        self.url = f"{'https' if tls else 'http'}://127.0.0.1:{self.port}"
        self.thread = self._serving_thread()
        self._real_clock = itsdangerous.timed.time

    def _serving_thread(self) -> threading.Thread:
        return threading.Thread(target=self.server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)

    def restart(self, tls: ssl.SSLContext | None = None, *, forget_logins: bool = False) -> None:
        """The car's console restarts (battery swap): a new web server process, the nodes at their power-on state,
        the model folders and (unless `forget_logins`) the login kept. Same address and port, as the car's. `tls`: a
        new certificate (a re-imaged car, or someone else answering at its address)."""
        self.power_off()
        self.power_on(tls, forget_logins=forget_logins)

    def power_off(self) -> None:
        self.server.shutdown()
        self.server.server_close()  # connection refused from here until the new process listens

    def power_on(self, tls: ssl.SSLContext | None = None, *, forget_logins: bool = False) -> None:
        self.state.boot(forget_logins=forget_logins)
        self.tls = tls or self.tls
        key = os.urandom(16).hex() if forget_logins else SECRET_KEY
        self.server = self._listen(create_app(self.state, key))
        self.thread = self._serving_thread()
        self.thread.start()

    def _listen(self, app: Flask, deadline_s: float = 10.0) -> Any:
        """The restarted web server on the car's port. Now and then (about one restart in ten when another test ran
        first in the process) the port is still taken for some microseconds as the old server lets it go (the bind
        succeeds 30 µs later; no socket on the port is left to see), and werkzeug then exits. What the tests check is
        the car after its restart, not this race in the test process, so the fake tries again until a deadline."""
        give_up = time.monotonic() + deadline_s
        while True:
            try:
                return make_server("127.0.0.1", self.port, app, threaded=True, ssl_context=self.tls)
            except SystemExit:  # werkzeug's answer to "Address already in use"
                if time.monotonic() > give_up:
                    raise
                time.sleep(0.01)

    def advance_clock(self, seconds: float) -> None:
        self.clock.offset += seconds

    def log_in_elsewhere(self) -> None:
        """Another client (a second agent, or someone on the car's web page) logs in: ours is logged out."""
        import requests

        other = requests.Session()
        page = other.get(f"{self.url}/login", timeout=5).text
        token = page.split('name="csrf-token" content="', 1)[1].split('"', 1)[0]
        for cookie in other.cookies:
            cookie.secure = False  # plain http here; the car is HTTPS
        reply = other.post(f"{self.url}/login", data={"password": self.state.password},
                           headers={"X-CSRFToken": token}, timeout=5)
        assert DEEPRACER_TOKEN in reply.cookies

    def __enter__(self) -> FakeConsole:
        itsdangerous.timed.time = self.clock  # type: ignore[assignment]  # the CSRF token's clock
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.state.stopping.set()
        self.server.shutdown()
        self.server.server_close()
        itsdangerous.timed.time = self._real_clock  # type: ignore[assignment]
