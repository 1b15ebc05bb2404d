"""The behaviour-cloning policy network and the tensor contract it shares with DeepRacer models.

Input follows the DeepRacer camera contract: NHWC ``[N, 120, 160, 1]`` float32 holding raw 0..255
grayscale pixels; the network rescales by 1/255 itself so every consumer feeds plain pixels.
Output is ``[N, 2]`` tanh means (steering, speed) in [-1, 1], the continuous-action head layout.
"""
from __future__ import annotations

import torch
from torch import nn

from drem_sim.learn.contract import IMAGE_HEIGHT, IMAGE_WIDTH, INPUT_NAME, NETWORK_NAME, OUTPUT_NAME  # noqa: F401


class BehaviourCloningCNN(nn.Module):
    """Five strided convolutions and one small dense layer (146,098 parameters).

    Narrow early layers (8 and 16 channels, the second convolution 3x3) keep inference cheap: 4.6 M multiply-adds
    per frame against 20 M of the first version (16@5x5, 32@5x5, ~190k parameters), whose second convolution alone
    cost more than half the network's time (issue 17, see docs/sim.md "Speed work of issue 17"). Strides and
    the dense head are unchanged, so the 4x6 feature map and the input/output contract are the same.
    """

    def __init__(self, dropout: float = 0.1) -> None:
        super().__init__()
        self.features = nn.Sequential(
            nn.Conv2d(1, 8, kernel_size=5, stride=2), nn.ReLU(),
            nn.Conv2d(8, 16, kernel_size=3, stride=2), nn.ReLU(),
            nn.Conv2d(16, 32, kernel_size=3, stride=2), nn.ReLU(),
            nn.Conv2d(32, 48, kernel_size=3, stride=2), nn.ReLU(),
            nn.Conv2d(48, 64, kernel_size=3, stride=1), nn.ReLU(),
        )
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.Dropout(dropout),
            nn.Linear(64 * 4 * 6, 64), nn.ReLU(),
            nn.Linear(64, 2),
            nn.Tanh(),
        )

    def forward(self, observation: torch.Tensor) -> torch.Tensor:
        # NHWC raw pixels in, as the DeepRacer graphs expect; convolutions want NCHW in [0, 1].
        pixels = observation.permute(0, 3, 1, 2) * (1.0 / 255.0)
        return self.head(self.features(pixels))


def parameter_count(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
