# Placeholder for the follow-line starter (examples/academy-followline.conf),
# so that the example conf checks; the starter program replaces this file.
from HAL import HAL

while True:
    HAL.setV(0.0)
    HAL.setW(0.0)
