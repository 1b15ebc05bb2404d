"""Where a DeepRacer graph's camera input and policy output live, per training algorithm.

Names as the simapp freezes them and the car's model optimizer looks them up: simapp
`markov/boto/s3/constants.py` (FROZEN_HEAD_OUTPUT_GRAPH_FORMAT_MAPPING) and aws-deepracer-model-optimizer-pkg /
DREM `models_optimize/constants.py` (input `main_level/agent/<main|policy>/online/network_0/<SENSOR>/<SENSOR>`).
Clipped PPO's network is `main`, SAC's is `policy` (brief: "SAC head names differ").
"""
from __future__ import annotations

NETWORK_BY_ALGORITHM = {"clipped_ppo": "main", "sac": "policy"}
OUTPUT_BY_ALGORITHM = {
    "clipped_ppo": "main_level/agent/main/online/network_1/ppo_head_0/policy",
    "sac": "main_level/agent/policy/online/network_0/sac_policy_head_0/policy",
}
# Sensors the simulator can feed: one 160x120 grayscale camera.
SINGLE_CAMERAS = ("FRONT_FACING_CAMERA", "LEFT_CAMERA", "observation")
IMAGE_SHAPE = (120, 160, 1)  # H, W, C (NHWC, batch first)


def input_node(training_algorithm: str, camera: str) -> str:
    network = NETWORK_BY_ALGORITHM.get(training_algorithm, "main")
    return f"main_level/agent/{network}/online/network_0/{camera}/{camera}"


def output_node(training_algorithm: str) -> str:
    return OUTPUT_BY_ALGORITHM.get(training_algorithm, OUTPUT_BY_ALGORITHM["clipped_ppo"])
