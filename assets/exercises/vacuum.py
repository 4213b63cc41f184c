# Exercise 1 - a bump-and-go cleaner.
#
# Drive forward until a bumper touches something; then back up a little, turn
# away from the side that touched (left bumper: turn right) by a random angle,
# and go on. Over time the robot should sweep the whole room.
#
#   HAL.getBumperData()  .state 1 while touching, .bumper 0 left, 1 centre, 2 right
#   HAL.getPose3d()      .x .y (m), .yaw (rad)
#   HAL.setV(v)          forward speed, m/s
#   HAL.setW(w)          turn speed, rad/s (positive turns left)
#
# The code before `while True:` runs once; the loop's body runs every cycle.
from HAL import HAL

print("vacuum: starting")

while True:
    bump = HAL.getBumperData()
    # TODO: a state machine: forward -> back up -> turn -> forward
    HAL.setV(0.0)
    HAL.setW(0.0)
