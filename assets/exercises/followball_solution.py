# Exercise 3, a solution: turn toward the red ball and approach it.
import numpy as np

from GUI import GUI
from HAL import HAL

while True:
    img = HAL.getImage()
    b = img[:, :, 0].astype(np.int16)
    g = img[:, :, 1].astype(np.int16)
    r = img[:, :, 2].astype(np.int16)
    mask = (r > 100) & (r - g > 60) & (r - b > 60)
    cols = np.nonzero(mask)[1]
    if len(cols) < 20:
        # Not seen: turn on the spot to look for it.
        HAL.setV(0.0)
        HAL.setW(0.5)
    else:
        half = img.shape[1] / 2
        error = (cols.mean() - half) / half  # -1 left .. 1 right
        HAL.setW(-1.2 * error)
        near = len(cols) > 0.08 * mask.size
        HAL.setV(0.0 if near or abs(error) > 0.3 else 0.25)
    GUI.showImage(mask.astype(np.uint8) * 255)
