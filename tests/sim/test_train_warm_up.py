"""The booth trainer warms up when it starts, so a visitor's first training does no loading of its own: PyTorch loads
its compiler (~800 modules, 4-5 s of CPU on the 2-core machine) the first time a process switches determinism on,
which used to land in the first visitor's wait after pressing Train."""
from __future__ import annotations

import json
import subprocess
import sys

import pytest

pytestmark = pytest.mark.sim

FIRST_TRAINING = """
import json, sys
import numpy as np
from drem_sim.learn.dataset import ActionScale, DatasetSnapshot
from drem_sim.learn.train import TrainConfig, train_behaviour_cloning, warm_up

warm_up()  # what the trainer does at start
loaded = set(sys.modules)
drive = DatasetSnapshot(np.full((40, 120, 160), 90, np.uint8), np.linspace(-20, 20, 40, dtype=np.float32),
                        np.full(40, 0.5, np.float32), ActionScale())
train_behaviour_cloning(drive, TrainConfig(epochs=2, batch_size=32, num_threads=1), progress=None)
print(json.dumps(sorted(set(sys.modules) - loaded)))
"""


def test_after_the_warm_up_a_first_training_loads_nothing() -> None:
    # A process of its own: this test process may have loaded everything already for other tests.
    done = subprocess.run([sys.executable, "-c", FIRST_TRAINING], capture_output=True, text=True, timeout=300,
                          check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    assert json.loads(done.stdout.strip().splitlines()[-1]) == []
