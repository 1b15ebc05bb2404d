"""The car's forward camera: 160x120 grayscale frames like the DeepRacer model input.

The track is drawn once, top-down, into a grayscale texture (dark road, white borders, a dashed
centre line, grass around). A pinhole camera looking at the flat ground plane is a homography,
so each frame is one `cv2.warpPerspective` of that texture at the model's input size. `supersample=2` renders
at twice the size and shrinks with INTER_AREA, which smooths the farthest centre-line dashes a little but costs
three times as much; frames differ from 1x ones by about one grey level on average (docs/sim.md, "1x frames").
Rows above the horizon get a constant sky value.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import cv2
import numpy as np

from drem_sim.tracks import Track

# Grey values of the printed mat in a grayscale (luma) camera.
ROAD = 38
BORDER = 235
CENTRE_DASH = 165  # orange centre line
GRASS = 105  # green off-track
SKY = 180


@dataclass(frozen=True)
class CameraConfig:
    width: int = 160
    height: int = 120
    hfov_rad: float = 1.13
    pitch_deg: float = 15.0  # down
    mount_forward: float = 0.092  # m ahead of the car origin
    mount_height: float = 0.115  # m above the ground: 0.08 above the chassis + chassis height
    supersample: int = 1  # 2 until 2026-11-26: the simulator's speed goal needed the camera's third back
    texture_px_per_m: float = 200.0
    border_width: float = 0.05  # m (2 in tape)
    dash_width: float = 0.05
    dash_length: float = 0.15
    noise_std: float = 0.0  # grey levels of Gaussian noise per frame (0 = off)
    brightness_jitter: float = 0.0  # relative gain range per frame, e.g. 0.1 = x[0.9, 1.1]

    @classmethod
    def for_track(cls, track: Track, **overrides: object) -> CameraConfig:
        base: dict[str, Any] = {"width": track.sim.camera_width, "height": track.sim.camera_height,
                                "hfov_rad": track.sim.camera_hfov_rad}
        base.update(overrides)
        return cls(**base)

    def as_dict(self) -> dict[str, float | int]:
        return dict(self.__dict__)


@dataclass(frozen=True, eq=False)
class TrackTexture:
    image: np.ndarray  # (H, W) uint8
    x_min: float
    y_max: float
    px_per_m: float

    def to_pixels(self, points: np.ndarray) -> np.ndarray:
        p = np.asarray(points, dtype=np.float64)
        return np.stack([(p[..., 0] - self.x_min) * self.px_per_m, (self.y_max - p[..., 1]) * self.px_per_m], -1)


def render_texture(track: Track, config: CameraConfig, margin: float = 2.0) -> TrackTexture:
    """Draw the mat top-down (north up) at `config.texture_px_per_m`."""
    x0, y0, x1, y1 = track.bounds
    scale = config.texture_px_per_m
    width = int(math.ceil((x1 - x0 + 2 * margin) * scale))
    height = int(math.ceil((y1 - y0 + 2 * margin) * scale))
    tex = TrackTexture(np.full((height, width), GRASS, np.uint8), x0 - margin, y1 + margin, scale)
    shift = 4  # sub-pixel drawing precision for cv2 (coordinates x16)
    fixed = lambda pts: np.round(tex.to_pixels(pts) * (1 << shift)).astype(np.int32)  # noqa: E731

    inner, outer = fixed(track.inner), fixed(track.outer)
    n = len(inner)
    last = n if track.is_closed else n - 1
    quads = [np.array([inner[i], inner[(i + 1) % n], outer[(i + 1) % n], outer[i]]) for i in range(last)]
    cv2.fillPoly(tex.image, quads, ROAD, lineType=cv2.LINE_AA, shift=shift)
    line_px = max(1, int(round(config.border_width * scale)))
    for border in (inner, outer):
        cv2.polylines(tex.image, [border], track.is_closed, BORDER, line_px, cv2.LINE_AA, shift)

    dash_px = max(1, int(round(config.dash_width * scale)))
    period = 2 * config.dash_length
    s = 0.0
    while s < track.length - config.dash_length:
        pts = [track.pose_at(s + k * config.dash_length / 4)[:2] for k in range(5)]
        cv2.polylines(tex.image, [fixed(np.array(pts))], False, CENTRE_DASH, dash_px, cv2.LINE_AA, shift)
        s += period
    return tex


class Camera:
    """Renders what the car's camera sees at a pose. Same pose (and same rng draws) -> same frame."""

    def __init__(self, track: Track, config: CameraConfig | None = None, texture: TrackTexture | None = None):
        self.config = config or CameraConfig.for_track(track)
        self.texture = texture or render_texture(track, self.config)
        cfg = self.config
        self._w = cfg.width * cfg.supersample
        self._h = cfg.height * cfg.supersample
        self._focal = (self._w / 2) / math.tan(cfg.hfov_rad / 2)
        self._cx, self._cy = (self._w - 1) / 2, (self._h - 1) / 2
        pitch = math.radians(cfg.pitch_deg)
        self._sin_p, self._cos_p = math.sin(pitch), math.cos(pitch)
        horizon = self._cy - self._focal * math.tan(pitch)
        # First row safely below the horizon; everything above is sky.
        self._row0 = min(self._h, max(0, int(math.floor(horizon)) + 2))
        # The warp reads the texture cropped to what is drawn: the grass margin round the mat is what the warp's
        # constant border gives anyway, and the smaller texture costs 13-18 % less per frame (docs/sim.md, issue
        # 33). Frames are the same to within float rounding (one grey level on a few pixels in ten thousand;
        # tests/sim/test_camera.py compares them with frames saved before).
        self._image, column0, row0 = _drawn_part(self.texture.image)
        t = self.texture
        self._tex_scale = 1 / t.px_per_m
        self._tex_x0, self._tex_y0 = t.x_min + column0 / t.px_per_m, t.y_max - row0 / t.px_per_m
        self._frame = np.full((self._h, self._w), SKY, np.uint8)
        self._ground = self._frame[self._row0:]

    def homography(self, x: float, y: float, heading: float) -> np.ndarray:
        """Pixel of the texture's drawn part (`_image`) -> (cropped, supersampled) image pixel for a car origin pose.

        K · [r1 r2 -R·c] · T with the camera's rows right, down (= forward × right) and forward, written out in
        scalars: the same matrix numpy's cross/stack/matmul built, at a tenth of the cost per frame."""
        cfg = self.config
        ch, sh = math.cos(heading), math.sin(heading)
        cp, sp = self._cos_p, self._sin_p
        cx, cy, cz = x + cfg.mount_forward * ch, y + cfg.mount_forward * sh, cfg.mount_height
        # Rows of R: right = (sh, -ch, 0); forward = (ch·cp, sh·cp, -sp); down = forward × right.
        rx, ry = sh, -ch
        fx, fy, fz = ch * cp, sh * cp, -sp
        dx, dy, dz = fy * 0.0 - fz * ry, fz * rx - fx * 0.0, fx * ry - fy * rx
        tr, td, tf = -(rx * cx + ry * cy), -(dx * cx + dy * cy + dz * cz), -(fx * cx + fy * cy + fz * cz)
        f, px, py = self._focal, self._cx, self._cy - self._row0
        # K · plane, where plane's columns are (R[:,0], R[:,1], -R·c).
        m = ((f * rx + px * fx, f * ry + px * fy, f * tr + px * tf),
             (f * dx + py * fx, f * dy + py * fy, f * td + py * tf),
             (fx, fy, tf))
        s, x0, y0 = self._tex_scale, self._tex_x0, self._tex_y0
        # · T, where T maps a texture pixel (u, v) to the world point (x0 + u·s, y0 - v·s).
        return np.array([(a * s, -b * s, a * x0 + b * y0 + c) for a, b, c in m])

    def render(self, x: float, y: float, heading: float, rng: np.random.Generator | None = None) -> np.ndarray:
        """The (height, width) uint8 frame for a car origin at (x, y) facing `heading` (radians)."""
        cfg = self.config
        cv2.warpPerspective(self._image, self.homography(x, y, heading), (self._w, self._h - self._row0),
                            dst=self._ground, flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_CONSTANT,
                            borderValue=GRASS)
        frame: np.ndarray
        if cfg.supersample == 1:
            frame = self._frame.copy()
        else:
            frame = cv2.resize(self._frame, (cfg.width, cfg.height), interpolation=cv2.INTER_AREA)
        if rng is not None and (cfg.noise_std > 0 or cfg.brightness_jitter > 0):
            gain = 1.0 + rng.uniform(-cfg.brightness_jitter, cfg.brightness_jitter)
            noisy = frame.astype(np.float32) * gain
            if cfg.noise_std > 0:
                noisy += rng.normal(0.0, cfg.noise_std, size=frame.shape).astype(np.float32)
            frame = np.clip(noisy, 0, 255).astype(np.uint8)
        return frame


def _drawn_part(image: np.ndarray, pad: int = 2) -> tuple[np.ndarray, int, int]:
    """The smallest block of `image` holding every pixel that is not plain grass, with `pad` pixels of grass round
    it (so bilinear samples at its edge see grass, as beyond it), and the block's first column and row."""
    drawn = image != GRASS
    rows, columns = np.flatnonzero(drawn.any(axis=1)), np.flatnonzero(drawn.any(axis=0))
    if len(rows) == 0:
        return image, 0, 0
    row0, column0 = max(0, int(rows[0]) - pad), max(0, int(columns[0]) - pad)
    row1, column1 = min(image.shape[0], int(rows[-1]) + 1 + pad), min(image.shape[1], int(columns[-1]) + 1 + pad)
    return np.ascontiguousarray(image[row0:row1, column0:column1]), column0, row0
