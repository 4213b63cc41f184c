# Exercise 3 - follow the red ball with the camera.
#
# Find the red pixels in the camera's image, turn so that they are in the middle
# of the image, and drive toward the ball until it looks big.
#
#   img = HAL.getImage()   a numpy array H x W x 3, uint8, BGR (as OpenCV reads it)
#   GUI.showImage(img)     shows an image (grey or BGR) in the panel
#   HAL.setV(v) m/s, HAL.setW(w) rad/s (positive turns left)
import numpy as np

from GUI import GUI
from HAL import HAL

while True:
    img = HAL.getImage()
    # TODO: a mask of the red pixels (B, G low; R high), their mean column, ...
    GUI.showImage(img)
    HAL.setV(0.0)
    HAL.setW(0.0)
