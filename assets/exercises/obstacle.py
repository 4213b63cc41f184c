# Obstacle avoidance (VFF): reach the targets of the circuit in order, around
# the obstacles (examples/academy-obstacle.conf).
#
# Virtual force field: the target pulls the robot (car force), every obstacle
# the laser sees pushes it away (obstacle force); the robot follows their sum
# (average force).
#
#   target = GUI.map.getNextTarget()   the next target not yet reached
#   target.getPose().x, .y             its place in the world, m
#   target.setReached(True)            move on to the next one
#   HAL.getPose3d()                    .x .y (m), .yaw (rad), the robot's pose
#   HAL.getLaserData()                 .values in m, from .minAngle to .maxAngle
#                                      (rad, counter-clockwise from ahead)
#   GUI.showForces(car, obstacle, average)   [x, y] each, robot's frame: drawn
#   GUI.showLocalTarget([x, y])               in the panel
#   HAL.setV(v) m/s, HAL.setW(w) rad/s (positive turns left)
#
# The score (targets reached, time) is under the panel.
import math

from GUI import GUI
from HAL import HAL


def absolute2relative(x_abs, y_abs, robot_x, robot_y, robot_yaw):
    """A point of the world in the robot's frame (x ahead, y left)."""
    dx, dy = x_abs - robot_x, y_abs - robot_y
    c, s = math.cos(-robot_yaw), math.sin(-robot_yaw)
    return dx * c - dy * s, dx * s + dy * c


while True:
    target = GUI.map.getNextTarget()
    if target is None:
        HAL.setV(0)
        HAL.setW(0)
        break
    pose = HAL.getPose3d()
    local = absolute2relative(target.getPose().x, target.getPose().y, pose.x, pose.y, pose.yaw)
    GUI.showLocalTarget(local)
    # TODO: the car force toward `local`, the obstacle force from the laser,
    # their sum, and the speeds from it; setReached(True) when close.
    HAL.setV(0.0)
    HAL.setW(0.0)
