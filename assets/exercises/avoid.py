# Exercise 2 - obstacle avoidance with the laser.
#
# Wander around the room without touching anything: go straight while the way
# ahead is clear, and turn toward the freer side when something is near.
#
#   laser = HAL.getLaserData()
#   laser.values          distances in m; index 0 is at laser.minAngle
#   laser.minAngle, laser.maxAngle   rad, counter-clockwise from straight ahead
#   laser.minRange, laser.maxRange   m
#   HAL.setV(v) m/s, HAL.setW(w) rad/s (positive turns left)
import math

from HAL import HAL

while True:
    laser = HAL.getLaserData()
    # TODO: the angle of reading i is laser.minAngle + i * step, where
    # step = (laser.maxAngle - laser.minAngle) / (len(laser.values) - 1)
    HAL.setV(0.0)
    HAL.setW(0.0)
