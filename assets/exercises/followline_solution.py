# Follow line, a solution: the red line's centre in a band of rows ahead of the
# robot, and a PD controller on its distance from the image's middle.
import cv2
import numpy as np

import Frequency
import GUI
import HAL

V_FAST, V_CURVE = 0.8, 0.45   # m/s on the straights and in the curves
KP, KD = 0.006, 0.004         # rad/s per pixel of error, and per pixel of change

last_error = 0.0
while True:
    image = HAL.getImage()
    hsv = cv2.cvtColor(image, cv2.COLOR_BGR2HSV)
    # Red wraps around hue 0.
    mask = cv2.inRange(hsv, (0, 100, 60), (10, 255, 255)) | cv2.inRange(
        hsv, (170, 100, 60), (180, 255, 255)
    )
    height, width = mask.shape
    band = mask[int(height * 0.55) : int(height * 0.85), :]
    m = cv2.moments(band, binaryImage=True)
    if m["m00"] > 0:
        cx = m["m10"] / m["m00"]
        error = width / 2 - cx  # > 0: the line is to the left
        w = KP * error + KD * (error - last_error)
        last_error = error
        HAL.setV(V_FAST if abs(error) < width * 0.08 else V_CURVE)
        HAL.setW(w)
    else:
        # Lost it: turn slowly toward where it was last seen.
        HAL.setV(0.1)
        HAL.setW(0.6 if last_error > 0 else -0.6)
    GUI.showImage(mask)
    Frequency.tick()
