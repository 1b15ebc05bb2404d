"""Console models bench: conversion time, per-frame inference of the converted graph vs OpenVINO on the .pb, agreement.

Side by side, on the shared real-structure console model (../shared/deepracer-models, a shallow clipped-PPO graph):
- conversion: `drem_sim.console.convert.convert` (OpenVINO reads the .pb, onnx writes it, both runtimes checked),
  in process, N times; and once the way an upload runs it (the contained worker subprocess, archive unpacked).
- inference: one frame at a time on 1 thread, onnxruntime on the converted file vs OpenVINO (f32, input fixed to
  [1,120,160,1] as the car's optimizer does) on the original .pb, interleaved over the same frames; p50 / p99.
- agreement: max |difference| between the two on those frames, and against the graph's own recorded outputs.

    .venv/bin/python bench/console_models.py [--frames 1000] [--conversions 3]
"""
from __future__ import annotations

import argparse
import json
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "functions"))
FIXTURE = ROOT.parent / "shared" / "deepracer-models" / "console-discrete-shallow-ppo"
ARCHIVE = FIXTURE / "console-discrete-shallow-ppo.tar.gz"
GOAL_CONVERT_S, GOAL_ORT_P99_MS, GOAL_RATIO, GOAL_DIFF = 5.0, 3.0, 1.2, 1e-4


def _percentiles(samples: list[float]) -> tuple[float, float]:
    values = np.asarray(samples) * 1000.0
    return float(np.percentile(values, 50)), float(np.percentile(values, 99))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=1000)
    parser.add_argument("--conversions", type=int, default=3)
    args = parser.parse_args()

    import openvino as ov

    from chalicelib.domain.model_conversion import ConsoleConverter
    from drem_sim.console.convert import check_frames, convert, onnx_session

    workdir = Path(tempfile.mkdtemp(prefix="bench-console-"))
    with tarfile.open(ARCHIVE, "r:gz") as archive:
        archive.extractall(workdir, filter="data")
    pb, metadata = workdir / "agent" / "model.pb", json.loads((workdir / "model_metadata.json").read_text())
    onnx_path = workdir / "model.onnx"

    in_process = []
    for _ in range(args.conversions):
        started = time.perf_counter()
        result = convert(pb, metadata, onnx_path)
        in_process.append(time.perf_counter() - started)
        assert result.outcome == "converted", result.reason
    started = time.perf_counter()
    with ARCHIVE.open("rb") as handle:
        contained = ConsoleConverter().convert(handle)
    worker_s = time.perf_counter() - started
    assert contained.scrutiny == "ready", contained.reason

    rng = np.random.default_rng(0)
    recorded = np.load(FIXTURE / "frames.npy").astype(np.float32)
    frames = np.concatenate([recorded, check_frames(),
                             rng.integers(0, 256, (max(args.frames - 11, 0), 120, 160, 1)).astype(np.float32)])
    frames = frames[: args.frames]
    session = onnx_session(onnx_path)
    input_name = session.get_inputs()[0].name
    graph = ov.Core().read_model(str(pb))
    graph.reshape([1, 120, 160, 1])  # static, as the car's model optimizer fixes it (dynamic shapes cost OpenVINO)
    compiled = ov.Core().compile_model(graph, "CPU",
                                       {"INFERENCE_NUM_THREADS": 1, "INFERENCE_PRECISION_HINT": "f32",
                                        "ENABLE_CPU_PINNING": False,
                                        "PERFORMANCE_HINT": "LATENCY"})
    request = compiled.create_infer_request()
    for frame in frames[:20]:  # warm both up
        session.run(None, {input_name: frame[None]})
        request.infer([frame[None]])
    ort_times, ov_times, ort_out, ov_out = [], [], [], []
    for frame in frames:  # interleaved, so machine load hits both alike
        batch = frame[None]
        started = time.perf_counter()
        ort_out.append(session.run(None, {input_name: batch})[0][0])
        ort_times.append(time.perf_counter() - started)
        started = time.perf_counter()
        ov_out.append(request.infer([batch])[0][0].copy())
        ov_times.append(time.perf_counter() - started)
    difference = float(np.max(np.abs(np.asarray(ort_out) - np.asarray(ov_out))))
    expected = np.load(FIXTURE / "expected_outputs.npy")
    versus_recorded = float(np.max(np.abs(np.asarray(ort_out[:5]) - expected)))
    ort_p50, ort_p99 = _percentiles(ort_times)
    ov_p50, ov_p99 = _percentiles(ov_times)
    convert_worst = max(max(in_process), worker_s)

    print(f"model: {ARCHIVE.name} ({pb.stat().st_size / 1e6:.1f} MB .pb), {len(frames)} frames, 1 thread")
    print(f"conversion in process      : {', '.join(f'{s:.2f}s' for s in in_process)}")
    print(f"conversion as an upload    : {worker_s:.2f}s (worker subprocess, archive unpacked, both runtimes checked)")
    print(f"{'per-frame inference':<27}: {'p50 ms':>8} {'p99 ms':>8}")
    print(f"{'  onnxruntime (converted)':<27}: {ort_p50:8.3f} {ort_p99:8.3f}")
    print(f"{'  OpenVINO (original .pb)':<27}: {ov_p50:8.3f} {ov_p99:8.3f}")
    print(f"onnxruntime / OpenVINO p99 : {ort_p99 / ov_p99:.2f}x")
    print(f"max |onnxruntime - OpenVINO| over {len(frames)} frames: {difference:.2e}; "
          f"vs the graph's recorded outputs (5 frames): {versus_recorded:.2e}")
    met = (convert_worst <= GOAL_CONVERT_S and ort_p99 <= GOAL_ORT_P99_MS and ort_p99 <= GOAL_RATIO * ov_p99
           and difference <= GOAL_DIFF)
    print(f"RESULT console_models: conversion worst {convert_worst:.2f}s, onnxruntime p99 {ort_p99:.2f} ms vs "
          f"OpenVINO p99 {ov_p99:.2f} ms ({ort_p99 / ov_p99:.2f}x), max diff {difference:.1e} | goal conversion "
          f"<= {GOAL_CONVERT_S:.0f}s, onnxruntime p99 <= {GOAL_ORT_P99_MS:.0f} ms and <= {GOAL_RATIO}x OpenVINO, "
          f"diff <= {GOAL_DIFF:.0e} | {'met' if met else 'not met'}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
