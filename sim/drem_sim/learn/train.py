"""Behaviour cloning: fit the policy CNN to demonstrator actions, reproducibly, on a CPU."""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TextIO

import cv2
import numpy as np
import torch
from torch import nn

from drem_sim.learn.dataset import ActionScale, Augmentation, DatasetSnapshot, augment_batch
from drem_sim.learn.model import BehaviourCloningCNN

STEERING_LOSS_WEIGHT = 2.0  # steering errors crash the car; speed errors only cost time
STEERING_BIN_DEG = 3.0  # --balance-steering counts frames per 3 degrees of |steering| (mirroring makes sign moot)


@dataclass(frozen=True)
class TrainConfig:
    epochs: int = 10
    seed: int = 0
    batch_size: int = 64
    learning_rate: float = 1e-3
    weight_decay: float = 1e-4
    validation_fraction: float = 0.15
    num_threads: int = 1
    augment: bool = True
    flip: bool = True
    augmentation: Augmentation | None = None  # None: brightness, noise and (if flip) mirroring, as before
    max_seconds: float | None = None  # stop early (after a whole batch) when a time budget is spent
    balance_steering: bool = False  # draw each epoch's frames so sharp-steer frames are not drowned by straights
    balance_cap: float = 8.0  # a frame is drawn at most this many times as often as one of the commonest bin

    @property
    def effective_augmentation(self) -> Augmentation | None:
        """What training really applies (None when augmentation is off); recorded in the lineage."""
        if not self.augment:
            return None
        return self.augmentation or Augmentation(flip=self.flip)


@dataclass
class TrainResult:
    model: BehaviourCloningCNN
    train_losses: list[float] = field(default_factory=list)
    validation_losses: list[float] = field(default_factory=list)
    epochs_run: int = 0
    seconds: float = 0.0
    train_frames: int = 0
    validation_frames: int = 0

    @property
    def final_validation_loss(self) -> float | None:
        return self.validation_losses[-1] if self.validation_losses else None


def warm_up(num_threads: int = 1) -> None:
    """Train once on a few blank frames, so this process has loaded what a first training loads on the way: PyTorch
    imports its compiler (~800 modules: 4-5 s of CPU on a 2-core machine) when determinism is switched on, and more
    on the first optimiser step. A long-lived trainer calls this at start, so no visitor waits for it."""
    blank = DatasetSnapshot(np.zeros((2, 120, 160), np.uint8), np.zeros(2, np.float32), np.ones(2, np.float32),
                            ActionScale())
    train_behaviour_cloning(blank, TrainConfig(epochs=1, num_threads=num_threads), progress=None)


def seed_everything(seed: int, num_threads: int) -> None:
    torch.manual_seed(seed)
    torch.set_num_threads(max(1, num_threads))
    # CPU kernels used here are deterministic; this turns any future non-deterministic op into a warning.
    torch.use_deterministic_algorithms(True, warn_only=True)


def split_indices(count: int, fraction: float, seed: int) -> tuple[np.ndarray, np.ndarray]:
    order = np.random.default_rng(seed).permutation(count)
    validation_count = int(round(count * fraction)) if count >= 10 else 0
    return np.sort(order[validation_count:]), np.sort(order[:validation_count])


def train_behaviour_cloning(snapshot: DatasetSnapshot, config: TrainConfig,
                            progress: TextIO | None = sys.stderr,
                            initial_state: dict[str, torch.Tensor] | None = None) -> TrainResult:
    """Fit from scratch, or go on from `initial_state` (a previous round's weights, as DAgger rounds do)."""
    seed_everything(config.seed, config.num_threads)
    rng = np.random.default_rng(config.seed)
    model = BehaviourCloningCNN()
    if initial_state is not None:
        model.load_state_dict(initial_state)
    optimiser = torch.optim.AdamW(model.parameters(), lr=config.learning_rate, weight_decay=config.weight_decay)
    schedule = torch.optim.lr_scheduler.CosineAnnealingLR(optimiser, T_max=max(1, config.epochs))
    targets = snapshot.targets
    train_idx, val_idx = split_indices(len(snapshot), config.validation_fraction, config.seed)
    result = TrainResult(model=model, train_frames=len(train_idx), validation_frames=len(val_idx))
    weights = torch.tensor([STEERING_LOSS_WEIGHT, 1.0])
    started = time.monotonic()
    batches_per_epoch = max(1, int(np.ceil(len(train_idx) / config.batch_size)))
    draw = steering_balance(snapshot.steering[train_idx], config.balance_cap) if config.balance_steering else None
    for epoch in range(1, config.epochs + 1):
        model.train()
        # Balanced: as many draws as frames (an epoch costs the same), with replacement, rare bins drawn more often.
        order = rng.choice(train_idx, size=len(train_idx), p=draw) if draw is not None else rng.permutation(train_idx)
        total, seen = 0.0, 0
        for batch_number, start in enumerate(range(0, len(order), config.batch_size), 1):
            batch = order[start:start + config.batch_size]
            images, batch_targets = snapshot.images[batch], targets[batch]
            if config.augment:
                images, batch_targets = augment_batch(images, batch_targets, rng,
                                                      augmentation=config.effective_augmentation)
            inputs = torch.from_numpy(np.ascontiguousarray(images, dtype=np.float32))[..., None]
            loss = _weighted_mse(model(inputs), torch.from_numpy(batch_targets), weights)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(batch)
            seen += len(batch)
            _report(progress, epoch, config.epochs, batch_number, batches_per_epoch, total / seen, started)
        schedule.step()
        result.train_losses.append(total / max(seen, 1))
        if len(val_idx):
            result.validation_losses.append(evaluate_loss(model, snapshot, val_idx, weights))
        result.epochs_run = epoch
        if progress is not None:
            val = f" val {result.validation_losses[-1]:.4f}" if result.validation_losses else ""
            line = (f"epoch {epoch}/{config.epochs} train {result.train_losses[-1]:.4f}{val} "
                    f"{time.monotonic() - started:6.1f}s")
            progress.write(f"\r{line:<64}\n")
            progress.flush()
        if config.max_seconds is not None and time.monotonic() - started > config.max_seconds:
            break
    model.eval()
    result.seconds = time.monotonic() - started
    return result


def steering_balance(steering_deg: np.ndarray, cap: float) -> np.ndarray:
    """Per-frame draw probabilities that even out |steering| bins: a long track is mostly straights, so the few
    frames of a hairpin's full lock would otherwise be a rounding error in the loss. A frame's weight is the most
    common bin's count over its own bin's count, at most `cap` (a bin of three frames must not be learned by heart)."""
    if cap < 1.0:
        raise ValueError("the balance cap is a multiple of the commonest bin's weight: at least 1")
    bins = np.floor(np.abs(np.asarray(steering_deg, dtype=np.float64)) / STEERING_BIN_DEG).astype(np.int64)
    counts = np.bincount(bins)
    weights = np.minimum(counts.max() / counts[bins], cap)
    return weights / weights.sum()


def evaluate_loss(model: nn.Module, snapshot: DatasetSnapshot, indices: np.ndarray,
                  weights: torch.Tensor, batch_size: int = 256) -> float:
    model.eval()
    targets = snapshot.targets
    total = 0.0
    with torch.no_grad():
        for start in range(0, len(indices), batch_size):
            batch = indices[start:start + batch_size]
            inputs = torch.from_numpy(snapshot.images[batch].astype(np.float32))[..., None]
            total += float(_weighted_mse(model(inputs), torch.from_numpy(targets[batch]), weights)) * len(batch)
    return total / max(len(indices), 1)


def _weighted_mse(prediction: torch.Tensor, target: torch.Tensor, weights: torch.Tensor) -> torch.Tensor:
    return (((prediction - target) ** 2) * weights).sum(dim=1).mean() / weights.sum()


def _report(stream: TextIO | None, epoch: int, epochs: int, batch: int, batches: int,
            loss: float, started: float) -> None:
    if stream is None:
        return
    filled = int(20 * batch / batches)
    if batch not in (1, batches) and filled == int(20 * (batch - 1) / batches):
        return  # redraw only when the bar grows: a few writes per epoch, not one per batch
    stream.write(f"\repoch {epoch}/{epochs} [{'#' * filled}{'.' * (20 - filled)}] "
                 f"loss {loss:.4f} {time.monotonic() - started:6.1f}s")
    stream.flush()


def plot_loss_curve(result: TrainResult, path: Path, width: int = 640, height: int = 360) -> Path:
    """Draw train/validation loss per epoch with plain OpenCV lines (no plotting library needed)."""
    canvas = np.full((height, width, 3), 255, np.uint8)
    left, right, top, bottom = 60, width - 20, 30, height - 40
    cv2.rectangle(canvas, (left, top), (right, bottom), (0, 0, 0), 1)
    series = [(result.train_losses, (200, 80, 0), "train"), (result.validation_losses, (0, 120, 230), "validation")]
    values = [v for losses, _, _ in series for v in losses]
    if values:
        peak = max(values) * 1.05 or 1.0
        epochs = max(len(result.train_losses), 2)
        for losses, colour, _label in series:
            points = [(int(left + (right - left) * i / (epochs - 1)),
                       int(bottom - (bottom - top) * v / peak)) for i, v in enumerate(losses)]
            for a, b in zip(points, points[1:], strict=False):
                cv2.line(canvas, a, b, colour, 2, cv2.LINE_AA)
            for point in points:
                cv2.circle(canvas, point, 3, colour, -1)
        cv2.putText(canvas, f"{peak:.3f}", (5, top + 5), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
        cv2.putText(canvas, "0", (40, bottom), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 1)
        for offset, (_, colour, label) in enumerate(series):
            cv2.putText(canvas, label, (right - 110, top + 20 + 18 * offset), cv2.FONT_HERSHEY_SIMPLEX, 0.5, colour, 1)
    cv2.putText(canvas, "behaviour cloning loss per epoch", (left, 20), cv2.FONT_HERSHEY_SIMPLEX, 0.5, (0, 0, 0), 1)
    cv2.putText(canvas, f"epochs: {result.epochs_run}", (left, height - 12), cv2.FONT_HERSHEY_SIMPLEX, 0.45,
                (0, 0, 0), 1)
    if not cv2.imwrite(str(path), canvas):
        raise OSError(f"could not write {path}")
    return path
