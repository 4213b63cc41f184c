# Obstacle avoidance (VFF), a solution: the target pulls with a force of at
# most 1, each laser reading nearer than 1.5 m pushes with 1/d² away from it,
# and the robot turns toward their sum and drives slower the more it has to
# turn.
import math

from GUI import GUI
from HAL import HAL

REACHED = 0.4      # m: close enough to a target to go on to the next
INFLUENCE = 1.5    # m: obstacles farther than this do not push
K_OBSTACLE = 0.12  # the obstacles' weight against the target's
V_MAX = 0.7        # m/s


def absolute2relative(x_abs, y_abs, robot_x, robot_y, robot_yaw):
    """A point of the world in the robot's frame (x ahead, y left)."""
    dx, dy = x_abs - robot_x, y_abs - robot_y
    c, s = math.cos(-robot_yaw), math.sin(-robot_yaw)
    return dx * c - dy * s, dx * s + dy * c


def obstacle_force(laser):
    n = len(laser.values)
    step = (laser.maxAngle - laser.minAngle) / (n - 1)
    fx = fy = 0.0
    for i, d in enumerate(laser.values):
        if 0.05 < d < INFLUENCE:
            a = laser.minAngle + i * step
            push = (1.0 / d - 1.0 / INFLUENCE) / (d * d)
            fx -= push * math.cos(a)
            fy -= push * math.sin(a)
    return fx * K_OBSTACLE / n * 30, fy * K_OBSTACLE / n * 30


while True:
    target = GUI.map.getNextTarget()
    if target is None:
        print("every target reached")
        HAL.setV(0)
        HAL.setW(0)
        break
    pose = HAL.getPose3d()
    tx, ty = absolute2relative(target.getPose().x, target.getPose().y, pose.x, pose.y, pose.yaw)
    distance = math.hypot(tx, ty)
    if distance < REACHED:
        print(f"target {target.getId()} reached")
        target.setReached(True)
        continue
    car = (tx / max(distance, 1.0), ty / max(distance, 1.0))
    obstacle = obstacle_force(HAL.getLaserData())
    average = (car[0] + obstacle[0], car[1] + obstacle[1])
    GUI.showLocalTarget([tx, ty])
    GUI.showForces(car, obstacle, average)
    heading = math.atan2(average[1], average[0])
    HAL.setW(max(-1.5, min(1.5, 1.8 * heading)))
    HAL.setV(V_MAX * max(0.0, math.cos(heading)) * min(1.0, distance + 0.3))
