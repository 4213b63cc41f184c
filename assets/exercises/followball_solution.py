# Exercise 3, a solution: turn toward the red ball and approach it.
import numpy as np

from GUI import GUI
from HAL import HAL

# The camera looks level from 0.5 m up: close to the robot the ball leaves the
# image at the bottom. Lost there, it is right in front: stay.
lost_below = False

while True:
    img = HAL.getImage()
    b = img[:, :, 0].astype(np.int16)
    g = img[:, :, 1].astype(np.int16)
    r = img[:, :, 2].astype(np.int16)
    mask = (r > 100) & (r - g > 60) & (r - b > 60)
    rows, cols = np.nonzero(mask)
    if len(cols) < 20:
        HAL.setV(0.0)
        # Not seen: turn on the spot to look for it (unless it is just below).
        HAL.setW(0.0 if lost_below else 0.5)
    else:
        half = img.shape[1] / 2
        error = (cols.mean() - half) / half  # -1 left .. 1 right
        lost_below = rows.max() >= img.shape[0] - 3
        HAL.setW(-1.2 * error)
        HAL.setV(0.0 if abs(error) > 0.3 else 0.2)
    GUI.showImage(mask.astype(np.uint8) * 255)
