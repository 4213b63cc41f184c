# Follow line: drive round the circuit along the red line painted on the floor,
# as fast as you can without losing it (examples/academy-followline.conf).
#
# The Academy 5 shape: your own loop, paced by Frequency.tick().
#
#   HAL.getImage()       the forward camera: a numpy array H x W x 3, BGR
#   GUI.showImage(img)   shows an image (BGR, or a grey mask) in the panel
#   HAL.setV(v)          forward speed, m/s
#   HAL.setW(w)          turn speed, rad/s (positive turns left)
#
# OpenCV is here: `import cv2` (cv2.cvtColor, cv2.inRange, cv2.moments, ...).
# The score (lap time, how far from the line) is under the panel.
import cv2
import numpy as np

import Frequency
import GUI
import HAL

while True:
    image = HAL.getImage()
    # TODO: find the red line (HSV threshold), its centre in a band of rows
    # ahead, and steer to keep it in the middle of the image.
    GUI.showImage(image)
    HAL.setV(0.0)
    HAL.setW(0.0)
    Frequency.tick()
