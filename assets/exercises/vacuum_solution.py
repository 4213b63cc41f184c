# Exercise 1, a solution: bump and go.
import math
import random

from HAL import HAL

rng = random.Random(1)  # the same run every time
state = "forward"
start = None  # pose where the current manoeuvre began
turn = 0.0  # signed angle to turn, rad
CORNERED = 0.4  # m: a bump this soon after the last turn means a corner
print("vacuum: starting")


def angle_diff(a, b):
    return math.atan2(math.sin(a - b), math.cos(a - b))


while True:
    bump = HAL.getBumperData()
    pose = HAL.getPose3d()
    if state == "forward":
        HAL.setV(0.3)
        HAL.setW(0.0)
        if bump.state == 1:
            side = "left" if bump.bumper == 0 else "right" if bump.bumper == 2 else "centre"
            print(f"bump on the {side} at ({pose.x:.2f}, {pose.y:.2f})")
            # Away from the side that touched; from the centre, either way.
            sign = -1.0 if bump.bumper == 0 else 1.0 if bump.bumper == 2 else rng.choice([-1.0, 1.0])
            # In a corner (bumped again soon after turning) turn further, or it
            # can bounce between the two walls for a long time.
            gone = math.inf if start is None else math.hypot(pose.x - start.x, pose.y - start.y)
            least = 120 if gone < CORNERED else 60
            turn = sign * rng.uniform(math.radians(least), math.radians(170))
            state, start = "back", pose
    elif state == "back":
        HAL.setV(-0.2)
        HAL.setW(0.0)
        if math.hypot(pose.x - start.x, pose.y - start.y) > 0.15:
            state, start = "turn", pose
    elif state == "turn":
        HAL.setV(0.0)
        HAL.setW(0.8 if turn > 0 else -0.8)
        if abs(angle_diff(pose.yaw, start.yaw)) >= abs(turn):
            state, start = "forward", pose
