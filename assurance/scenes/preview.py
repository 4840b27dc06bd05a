"""Preview sheets: image | colour labels side by side, one row per sample, with a class legend."""

from __future__ import annotations

import cv2
import numpy as np

from el.classes.labels import LabelSet


def _legend(width: int, labels: LabelSet) -> np.ndarray:
    """A strip (h, width, 3) RGB naming each class of ``labels`` next to its label colour."""
    n = labels.num_classes
    per_row = max(1, min(n, width // 170))
    rows = -(-n // per_row)
    strip = np.full((rows * 26 + 8, width, 3), 255, np.uint8)
    for i, name in enumerate(labels.names):
        r, c = divmod(i, per_row)
        x, y = 8 + c * (width // per_row), 8 + r * 26
        colour = tuple(int(v) for v in labels.palette[i])
        cv2.rectangle(strip, (x, y), (x + 18, y + 18), colour, -1)
        cv2.rectangle(strip, (x, y), (x + 18, y + 18), (90, 90, 90), 1)
        cv2.putText(strip, name, (x + 24, y + 14), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (20, 20, 20), 1, cv2.LINE_AA)
    return strip


def make_preview(pairs: list[tuple[np.ndarray, np.ndarray]], *, labels: LabelSet, panel_width: int = 800) -> np.ndarray:
    """RGB sheet: for each (image RGB (H, W, 3), class ids (H, W) of ``labels``) a row [image | labels], then the
    legend of ``labels``."""
    if not pairs:
        raise ValueError("nothing to preview")
    rows = []
    for image, ids in pairs:
        h, w = ids.shape
        ph = max(1, round(panel_width * h / w))
        img = cv2.resize(image, (panel_width, ph), interpolation=cv2.INTER_AREA)
        lab = cv2.resize(labels.ids_to_colors(ids), (panel_width, ph), interpolation=cv2.INTER_NEAREST)
        gap = np.full((ph, 6, 3), 255, np.uint8)
        rows.append(np.concatenate([img, gap, lab], axis=1))
        rows.append(np.full((6, rows[-1].shape[1], 3), 255, np.uint8))
    sheet = np.concatenate(rows[:-1], axis=0)
    return np.concatenate([sheet, _legend(sheet.shape[1], labels)], axis=0)
