"""What a cheap webcam does to the light it gets: exposure time, auto exposure and white balance, MJPEG.

The renderer (:mod:`tracking.sim.renderer`) gives what an ideal camera sees at one instant, with
sensor noise, lighting drift and a colour cast. A USB webcam adds, in this order:

- **motion blur**: the shutter is open for ``exposure_s``; the image is the mean of the scene over
  that time (:func:`exposure_offsets_s`, :func:`integrate_exposure`: the studio renders the
  instants and averages them, then adds the sensor noise once);
- **auto exposure and auto white balance** (:class:`AutoCamera`): a control loop that keeps the
  image's mean brightness and its grey-world colour balance where they were when the camera
  settled, reacting with a lag of a few frames; when the patient moves (or the light drifts) the
  mean changes, the loop corrects late and overshoots: it hunts;
- **MJPEG** (:func:`jpeg_roundtrip`): each image JPEG-compressed at a quality, its chroma at half
  resolution across (4:2:2, what UVC webcams' MJPEG streams mostly carry) or across and down
  (4:2:0), as the camera sends it over USB.

All functions are pure numpy/OpenCV on (H, W, 3) uint8 BGR images, seeded where random.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Sequence

import cv2
import numpy as np

#: BT.601 luma weights in B, G, R order
_LUMA_BGR = np.array([0.114, 0.587, 0.299])


@dataclass(frozen=True, slots=True)
class Webcam:
    """The webcam effects of a simulated recording (all off by default: an ideal camera).

    Attributes:
        jpeg_quality: MJPEG quality 1..100 (None: lossless).
        jpeg_chroma: chroma subsampling of the MJPEG, ``"422"``, ``"420"`` or ``"444"``.
        exposure_s: shutter time, seconds (0: an instant, no motion blur).
        auto_exposure: the brightness loop of :class:`AutoCamera`.
        auto_white_balance: the colour loop of :class:`AutoCamera`.
        lag_frames: frames between an image and the correction it causes.
        loop_gain: share of the measured error (log units) corrected per frame; with the lag it
            sets how much the loop overshoots (stable below ``2 sin(pi / (2 (2 lag + 1)))``).
    """

    jpeg_quality: int | None = None
    jpeg_chroma: str = "422"
    exposure_s: float = 0.0
    auto_exposure: bool = False
    auto_white_balance: bool = False
    lag_frames: int = 3
    loop_gain: float = 0.3

    def __post_init__(self) -> None:
        if self.jpeg_quality is not None and not 1 <= self.jpeg_quality <= 100:
            raise ValueError(f"jpeg_quality {self.jpeg_quality}: give 1..100")
        if self.jpeg_chroma not in CHROMA_SUBSAMPLING:
            raise ValueError(f"jpeg_chroma {self.jpeg_chroma!r}: give one of {', '.join(CHROMA_SUBSAMPLING)}")
        if not 0.0 <= self.exposure_s <= 1.0:
            raise ValueError(f"exposure_s {self.exposure_s}: give 0..1 s")
        if self.lag_frames < 0 or not 0.0 < self.loop_gain <= 1.0:
            raise ValueError(f"lag_frames {self.lag_frames}, loop_gain {self.loop_gain}: give lag >= 0, gain in (0, 1]")

    @property
    def ideal(self) -> bool:
        """True: no webcam effect at all (the images are the renderer's)."""
        return (self.jpeg_quality is None and self.exposure_s == 0.0 and not self.auto_exposure
                and not self.auto_white_balance)

    @property
    def auto(self) -> bool:
        return self.auto_exposure or self.auto_white_balance

    def as_meta(self) -> dict:
        """The parameters for meta.yaml."""
        out: dict = {"jpeg_quality": self.jpeg_quality, "exposure_s": self.exposure_s,
                     **({"jpeg_chroma": self.jpeg_chroma} if self.jpeg_quality is not None else {}),
                     "auto_exposure": self.auto_exposure, "auto_white_balance": self.auto_white_balance}
        if self.auto:
            out.update(lag_frames=self.lag_frames, loop_gain=self.loop_gain)
        return out


def drawn_webcam(rng: np.random.Generator) -> Webcam:
    """A random cheap webcam (the validation population's draws): MJPEG quality 50-95 in 80 % of
    draws (chroma 4:2:2, in a quarter of them 4:2:0), exposure 0-33 ms, auto exposure and white balance each on in half the draws with a lag of
    2-4 frames and a loop gain from well damped to hunting."""
    lag = int(rng.integers(2, 5))
    chroma = "420" if rng.random() < 0.25 else "422"
    limit = 2.0 * math.sin(math.pi / (2 * (2 * lag + 1)))
    return Webcam(
        jpeg_quality=int(rng.integers(50, 96)) if rng.random() < 0.8 else None,
        jpeg_chroma=chroma,
        exposure_s=float(rng.uniform(0.0, 1.0 / 30.0)),
        auto_exposure=bool(rng.random() < 0.5),
        auto_white_balance=bool(rng.random() < 0.5),
        lag_frames=lag,
        loop_gain=float(rng.uniform(0.3, 0.9) * limit),
    )


CHROMA_SUBSAMPLING = {"422": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_422, "420": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_420,
                      "444": cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444}
"""OpenCV's JPEG chroma sampling factors by their usual names."""


def jpeg_roundtrip(image: np.ndarray, quality: int, chroma: str = "422") -> np.ndarray:
    """``image`` (H, W, 3) uint8 BGR as a JPEG of ``quality`` (1..100) and ``chroma`` subsampling
    (:data:`CHROMA_SUBSAMPLING`) decodes."""
    ok, buf = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, int(quality),
                                           cv2.IMWRITE_JPEG_SAMPLING_FACTOR, CHROMA_SUBSAMPLING[chroma]])
    if not ok:  # pragma: no cover - OpenCV encodes every uint8 BGR image
        raise RuntimeError("OpenCV could not JPEG-encode an image")
    return cv2.imdecode(buf, cv2.IMREAD_COLOR)


def exposure_offsets_s(exposure_s: float, max_motion_px: float, *, step_px: float = 2.0, most: int = 15) -> np.ndarray:
    """Instants (relative to the exposure's middle) that sample a shutter open ``exposure_s``:
    an odd count (the middle is one of them), enough that the fastest ball moves at most
    ``step_px`` between two (``max_motion_px``: its image motion over the exposure), at most ``most``."""
    if exposure_s <= 0.0:
        return np.zeros(1)
    n = int(np.clip(math.ceil(max(max_motion_px, 0.0) / step_px) + 1, 3, most))
    n += 1 - n % 2
    return (np.arange(n) + 0.5) / n * exposure_s - exposure_s / 2.0


def integrate_exposure(images: Sequence[np.ndarray]) -> np.ndarray:
    """The mean of noise-free renders of the exposure's instants: (H, W, 3) float32, 8-bit units."""
    acc = np.zeros(images[0].shape, np.float32)
    for img in images:
        acc += img
    return acc / len(images)


def add_sensor_noise(image: np.ndarray, sigma: float, rng: np.random.Generator) -> np.ndarray:
    """Gaussian noise of ``sigma`` (8-bit units) added to a float image, rounded and clamped to uint8."""
    noisy = image + rng.normal(scale=sigma, size=image.shape).astype(np.float32) if sigma > 0 else image
    return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)


def mean_bgr(image: np.ndarray, stride: int = 4) -> np.ndarray:
    """(3,) mean B, G, R of an image on a ``stride`` grid (what the camera's statistics block sees)."""
    return image[::stride, ::stride].reshape(-1, 3).mean(axis=0) + 0.5


class AutoCamera:
    """Auto exposure and auto white balance of one camera: integral control loops in log units.

    The targets are the first image's mean brightness and grey-world balance (the camera settled on
    the scene it was switched on in). Each frame the loop corrects ``loop_gain`` of the error it
    measured ``lag_frames`` frames earlier on its own output, so a change of the scene is corrected
    late, and the correction keeps running after the error is gone: it overshoots and hunts.
    """

    def __init__(self, webcam: Webcam):
        self.webcam = webcam
        self.log_gain = np.zeros(3)  # B, G, R, applied to the incoming image
        self._target: np.ndarray | None = None
        self._measured: deque[np.ndarray] = deque()

    def _error(self, mean: np.ndarray) -> np.ndarray:
        log_mean = np.log(mean)
        luma = float(np.log(_LUMA_BGR @ mean))
        err = np.zeros(3)
        if self.webcam.auto_exposure:
            err += self._target[3] - luma
        if self.webcam.auto_white_balance:  # balance relative to green, as white balance does
            bal = log_mean - log_mean[1]
            err += (self._target[:3] - bal)
        return err

    def apply(self, image: np.ndarray) -> np.ndarray:
        """The image as the camera outputs it (its gains applied, clamped to uint8)."""
        if self._target is None:
            mean = mean_bgr(image)
            self._target = np.append(np.log(mean) - np.log(mean[1]), np.log(_LUMA_BGR @ mean))
        gain = np.exp(self.log_gain)
        if np.allclose(gain, 1.0):
            out = image.copy()
        else:
            out = cv2.convertScaleAbs(image.astype(np.float32) * gain.astype(np.float32).reshape(1, 1, 3))
        self._measured.append(self._error(mean_bgr(out)))
        if len(self._measured) > self.webcam.lag_frames:
            self.log_gain = np.clip(self.log_gain + self.webcam.loop_gain * self._measured.popleft(),
                                    math.log(0.25), math.log(4.0))
        return out

    @property
    def gains_rgb(self) -> np.ndarray:
        """(3,) the gains that the next image gets, R, G, B."""
        return np.exp(self.log_gain[::-1])


class WebcamPipeline:
    """Auto exposure / white balance and MJPEG of every camera, frame set after frame set."""

    def __init__(self, webcam: Webcam, n_cameras: int):
        self.webcam = webcam
        self.cameras = [AutoCamera(webcam) for _ in range(n_cameras)] if webcam.auto else []

    def apply(self, images: Sequence[np.ndarray]) -> tuple[tuple[np.ndarray, ...], np.ndarray | None]:
        """(the output images, (C, 3) R, G, B gains applied to them, None without auto loops)."""
        gains = None
        if self.cameras:
            gains = np.stack([cam.gains_rgb for cam in self.cameras])
            images = [cam.apply(img) for cam, img in zip(self.cameras, images)]
        if self.webcam.jpeg_quality is not None:
            images = [jpeg_roundtrip(img, self.webcam.jpeg_quality, self.webcam.jpeg_chroma) for img in images]
        return tuple(images), gains
