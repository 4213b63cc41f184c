# Exercise 2, a solution: keep away from obstacles with the laser.
import math

from HAL import HAL

SAFE = 0.9  # m: closer than this ahead, turn
laser = HAL.getLaserData()
n = len(laser.values)
step = (laser.maxAngle - laser.minAngle) / (n - 1)
angles = [laser.minAngle + i * step for i in range(n)]
print(f"laser: {n} readings from {math.degrees(laser.minAngle):.0f} to "
      f"{math.degrees(laser.maxAngle):.0f} deg, up to {laser.maxRange} m")
turning = 0.0

while True:
    values = HAL.getLaserData().values

    def sector(lo, hi):
        return min((d for a, d in zip(angles, values) if lo <= math.degrees(a) <= hi),
                   default=laser.maxRange)

    front = sector(-30, 30)
    left = sector(30, 90)
    right = sector(-90, -30)
    if front < SAFE or min(left, right) < 0.45:
        if turning == 0.0:
            turning = 1.0 if left >= right else -1.0  # keep one way until clear
        HAL.setV(0.0 if front < 0.5 else 0.1)
        HAL.setW(0.9 * turning)
    else:
        turning = 0.0
        HAL.setV(0.4)
        HAL.setW(0.0)
