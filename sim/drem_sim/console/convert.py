"""Convert a DeepRacer console model (`agent/model.pb`, TensorFlow 1 frozen graph) to ONNX, and prove it.

1. OpenVINO's TensorFlow frontend reads the `.pb` (no TensorFlow needed; it is what the car itself runs).
2. `graph_to_onnx` writes the same operations as ONNX.
3. The same frames go through OpenVINO (on the original graph) and onnxruntime (on the converted file); the
   conversion counts only if they agree to `TOLERANCE`.

Outcomes are plain data (`Conversion`): `converted`; `cannot_scrutineer` with a reason a racer can read (a
stereo or lidar network the simulator cannot feed, an unknown operation, a mismatch: the car itself can still run
it); or `not_raceable`, a model a stock car cannot load or would drive wrongly (a `.pb` OpenVINO, the car's own
model optimizer, cannot read; a network whose outputs disagree with the metadata's action space), with the reason in
plain words and OpenVINO's own message as `detail` for staff. Run as a module it is the
worker the upload runs in a subprocess with time and memory limits (`python -m drem_sim.console.convert`): a
hostile or enormous graph can crash or exhaust only that process.
"""
from __future__ import annotations

import argparse
import functools
import json
import re
import sys
import time
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import BaseModel

from drem_sim.console.heads import IMAGE_SHAPE, SINGLE_CAMERAS, input_node, output_node

TOLERANCE = 1e-4
CHECK_FRAME_COUNT = 6
Outcome = Literal["converted", "cannot_scrutineer", "not_raceable"]


class Conversion(BaseModel):
    outcome: Outcome
    reason: str | None = None
    max_abs_diff: float | None = None
    frames_checked: int = 0
    seconds: float = 0.0
    input_name: str | None = None
    output_name: str | None = None
    detail: str | None = None  # for staff: the runtime's own words behind `reason`


class CannotScrutineer(ValueError):
    """The graph is fine for a car but not for the simulator (or the converter); the message says why."""


class NotRaceable(ValueError):
    """A stock car cannot load this model, or would drive it wrongly: the message says why in plain words."""

    def __init__(self, reason: str, detail: str | None = None) -> None:
        super().__init__(reason)
        self.detail = detail


@functools.cache
def openvino_core() -> Any:
    """One OpenVINO Core per process (it loads its frontends and the CPU plugin once, on first use)."""
    import openvino as ov

    return ov.Core()


def warm_openvino() -> None:
    """What a spare worker does before its request: the Core, its TensorFlow frontend and its CPU plugin loaded."""
    from openvino.frontend import FrontEndManager

    FrontEndManager().load_by_framework("tf")
    openvino_core().get_property("CPU", "FULL_DEVICE_NAME")


def check_frames(count: int = CHECK_FRAME_COUNT, seed: int = 0) -> np.ndarray:
    """Frames that exercise the whole input range: black, white, a gradient and seeded noise (uint8 pixels)."""
    height, width, _ = IMAGE_SHAPE
    frames = [np.zeros((height, width), np.uint8), np.full((height, width), 255, np.uint8),
              np.tile(np.linspace(0, 255, width, dtype=np.uint8), (height, 1))]
    rng = np.random.default_rng(seed)
    while len(frames) < count:
        frames.append(rng.integers(0, 256, (height, width), dtype=np.uint8))
    return np.stack(frames[:count]).reshape(count, height, width, 1)


def sim_can_feed(metadata: dict[str, Any]) -> None:
    """Raise CannotScrutineer for sensors the simulator has no twin of (it renders one grayscale camera)."""
    sensors = metadata.get("sensor") or ["observation"]
    extra = [s for s in sensors if s not in SINGLE_CAMERAS]
    if extra:
        raise CannotScrutineer(f"the model reads {', '.join(extra)}; the simulator feeds one front camera only")


def read_graph(pb_path: Path, metadata: dict[str, Any]) -> Any:
    """The OpenVINO model of the `.pb`, narrowed to the camera input and the policy output."""
    import openvino as ov

    sim_can_feed(metadata)
    try:
        model = openvino_core().read_model(str(pb_path))
    except Exception as error:  # OpenVINO raises its own types for a graph it cannot read
        raise NotRaceable("a stock car cannot load this model: its agent/model.pb is damaged or incomplete "
                          "(OpenVINO, the model optimizer the car runs, cannot read it); download the model again "
                          "and upload the whole archive",
                          f"OpenVINO cannot read agent/model.pb: {openvino_message(error, pb_path)}") from None
    if len(model.inputs) != 1:
        names = ", ".join(p.get_any_name() for p in model.inputs)
        raise CannotScrutineer(f"the graph has {len(model.inputs)} inputs ({names}); the simulator feeds one camera")
    shape = model.inputs[0].get_partial_shape()
    if shape.rank.is_dynamic or shape.rank.get_length() != 4 or [
            d.get_length() if d.is_static else -1 for d in list(shape)[1:]] != list(IMAGE_SHAPE):
        raise CannotScrutineer(f"the graph's input is {shape}, not a 120x160 grayscale camera [?,120,160,1]")
    if len(model.outputs) > 1:
        wanted = output_node(str(metadata.get("training_algorithm", "clipped_ppo")))
        heads = [o for o in model.outputs if any(n.split(":")[0] == wanted for n in o.get_names())]
        if not heads:
            raise CannotScrutineer(f"the graph has {len(model.outputs)} outputs and none is {wanted}")
        model = ov.Model([heads[0]], model.get_parameters(), "policy")
    return model


def convert(pb_path: Path, metadata: dict[str, Any], onnx_path: Path) -> Conversion:
    """Convert and verify; write `onnx_path` only for a conversion that passed."""
    import onnx

    from drem_sim.console.graph_to_onnx import UnsupportedGraph, openvino_to_onnx

    started = time.perf_counter()
    algorithm = str(metadata.get("training_algorithm", "clipped_ppo"))
    camera = next((s for s in metadata.get("sensor") or ["observation"] if s in SINGLE_CAMERAS), "observation")
    names = {"input_name": input_node(algorithm, camera), "output_name": output_node(algorithm)}
    try:
        model = read_graph(pb_path, metadata)
        actions_match(model, metadata)
        translated = openvino_to_onnx(model, names["input_name"], names["output_name"])
    except NotRaceable as error:
        return Conversion(outcome="not_raceable", reason=str(error), detail=error.detail,
                          seconds=time.perf_counter() - started)
    except (CannotScrutineer, UnsupportedGraph) as error:
        return Conversion(outcome="cannot_scrutineer", reason=str(error), seconds=time.perf_counter() - started)
    frames = check_frames().astype(np.float32)
    compiled = openvino_core().compile_model(model, "CPU", {"INFERENCE_NUM_THREADS": 1,
                                                            "INFERENCE_PRECISION_HINT": "f32"})
    expected = np.stack([compiled(frame[None])[0][0] for frame in frames])
    data = translated.SerializeToString()
    session = onnx_session(data)
    actual = np.stack([session.run(None, {names["input_name"]: frame[None]})[0][0] for frame in frames])
    if expected.shape != actual.shape:
        return Conversion(outcome="cannot_scrutineer", seconds=time.perf_counter() - started,
                          reason=f"the converted graph outputs {actual.shape[1:]} but OpenVINO {expected.shape[1:]}")
    difference = float(np.max(np.abs(expected.astype(np.float64) - actual)))
    result = Conversion(outcome="converted", max_abs_diff=difference, frames_checked=len(frames),
                        seconds=time.perf_counter() - started, **names)
    if not difference <= TOLERANCE:  # also catches NaN
        return result.model_copy(update={
            "outcome": "cannot_scrutineer",
            "reason": f"the converted graph disagrees with OpenVINO by {difference:.1e} (more than {TOLERANCE:.0e})"})
    onnx.save(translated, str(onnx_path))
    return result


def actions_match(model: Any, metadata: dict[str, Any]) -> None:
    """The network must output what the metadata's action space says the car will read: one probability per
    discrete action (the car maps the highest to action_space[index]), or the two continuous means. Otherwise the
    car refuses the model or drives other actions than the racer trained."""
    wanted = _output_size(metadata)
    shape = model.outputs[0].get_partial_shape()
    last = shape[shape.rank.get_length() - 1] if shape.rank.is_static and shape.rank.get_length() else None
    if wanted is None or last is None or not last.is_static or last.get_length() == wanted:
        return
    outputs = last.get_length()
    if metadata.get("action_space_type", "discrete") == "continuous":
        said = (f"a continuous action space (the car reads 2 values: steering and speed) but its network outputs "
                f"{outputs}")
    else:
        said = f"{wanted} actions in model_metadata.json but its network chooses among {outputs}"
    raise NotRaceable(f"a stock car would drive this model wrongly: it has {said}. The model_metadata.json does not "
                      "belong to this agent/model.pb; upload the archive the console gave you, unchanged",
                      f"policy output shape {shape}, action space of {wanted}")


def openvino_message(error: BaseException, pb_path: Path) -> str:
    """OpenVINO's message without its source locations ("Exception from src/...cpp:84:") and with our temporary
    path replaced by the archive's name: the lines that say what is wrong."""
    lines = [line.strip() for line in str(error).splitlines()]
    meaningful = [line for line in lines if line and not _SOURCE_LOCATION.match(line)]
    text = " ".join(meaningful) or type(error).__name__
    return text.replace(f'"{pb_path}"', "agent/model.pb").replace(str(pb_path), "agent/model.pb")[:600]


_SOURCE_LOCATION = re.compile(r"^(Exception from |Check '.*' failed at )?\S+\.(cpp|hpp|h|cc):\d+:?$")


def _output_size(metadata: dict[str, Any]) -> int | None:
    """One probability per discrete action, or two means (steering, speed) for a continuous space."""
    space = metadata.get("action_space")
    if metadata.get("action_space_type", "discrete") == "continuous":
        return 2
    return len(space) if isinstance(space, list) else None


def onnx_session(model: bytes | Path) -> Any:
    """onnxruntime on one thread, as the car and the simulator run it (torch-free, unlike learn.export)."""
    import onnxruntime

    options = onnxruntime.SessionOptions()
    options.intra_op_num_threads = 1
    options.inter_op_num_threads = 1
    options.log_severity_level = 3
    return onnxruntime.InferenceSession(model if isinstance(model, bytes) else str(model), options,
                                        providers=["CPUExecutionProvider"])


def main(argv: list[str] | None = None) -> int:
    """Worker: convert PB (with METADATA) into OUT; print one JSON line (the Conversion) on stdout.

    `--wait`: a spare worker. It loads OpenVINO, onnx and onnxruntime first (seconds of imports), then waits for
    one request on stdin, a JSON list [pb, metadata, out], converts it and exits; no request (stdin closed): it
    exits quietly. The server keeps one spare ready, so a racer's upload does not wait for the imports."""
    parser = argparse.ArgumentParser(prog="python -m drem_sim.console.convert")
    parser.add_argument("--wait", action="store_true", help="load the converter, then read [pb, metadata, out]")
    parser.add_argument("pb", type=Path, nargs="?")
    parser.add_argument("metadata", type=Path, nargs="?")
    parser.add_argument("out", type=Path, nargs="?")
    args = parser.parse_args(argv)
    if args.wait:
        import onnx  # noqa: F401 - loaded now, before the request: that is the point of a spare
        import onnxruntime  # noqa: F401
        import openvino  # noqa: F401

        import drem_sim.console.graph_to_onnx  # noqa: F401

        warm_openvino()
        line = sys.stdin.readline()
        if not line.strip():
            return 0
        pb, metadata_path, out = (Path(part) for part in json.loads(line))
    elif args.pb and args.metadata and args.out:
        pb, metadata_path, out = args.pb, args.metadata, args.out
    else:
        parser.error("give PB METADATA OUT, or --wait")
    metadata = json.loads(metadata_path.read_text())
    result = convert(pb, metadata if isinstance(metadata, dict) else {}, out)
    sys.stdout.write(result.model_dump_json() + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
