"""A segmentation model that is not a torch module, as a package outside uav-el-assurance would ship one.

It classifies each pixel by its nearest label colour (exact on label-coloured scenes) and reports no MC
dropout; registered as ``[project.entry-points."uav_el.models"] colour = "colour_model:build"``.
"""

from __future__ import annotations

import cv2
import numpy as np

from el.classes.labels import PALETTE


class ColourModel:
    def __init__(self, working_width: int = 1024, weights_sha256: str | None = None) -> None:
        self.working_width, self.weights_sha256 = working_width, weights_sha256

    def working_size(self, width: int, height: int) -> tuple[int, int]:
        return self.working_width, round(self.working_width * height / width)

    def _probs(self, rgb: np.ndarray) -> np.ndarray:
        d = ((rgb[..., None, :].astype(np.int32) - PALETTE.astype(np.int32)) ** 2).sum(-1)
        ids = d.argmin(-1)
        probs = np.zeros((len(PALETTE), *ids.shape), np.float32)
        np.put_along_axis(probs, ids[None], 1.0, axis=0)
        return probs

    def predict_frame(self, rgb: np.ndarray) -> np.ndarray:
        w, h = self.working_size(rgb.shape[1], rgb.shape[0])
        return self._probs(cv2.resize(rgb, (w, h), interpolation=cv2.INTER_NEAREST))

    def predict_patch(self, rgb_patch: np.ndarray) -> np.ndarray:
        return self._probs(rgb_patch)


def build(arg: str | None, *, threads: int | None = None, device: str = "cpu") -> ColourModel:
    """The factory the entry point names: ``colour`` or ``colour:WIDTH``."""
    return ColourModel(int(arg) if arg else 1024)
