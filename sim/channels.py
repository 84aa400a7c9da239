"""The 25 observation channels, in order.

What "desired joint angle" (`joint1`..`joint7`) records: the MEASURED joint angle (rad) at the
observation instant, i.e. the set point the servo has actually reached. With velocity
feed-forward the servos track the 2 Hz plan to a fraction of a degree, so in normal operation
this channel is the desired angle of the paper; under a fault it records what the joint really
did. We chose it over the planned or commanded angle deliberately:

- a joint lock is a mismatch between intention and motion; the command a controller sends to a
  locked joint is unchanged on a real robot, only the encoder shows the lock, so only a measured
  channel lets a monitor isolate the faulty joint by its prediction error (as the paper does);
- collisions (a locked joint 2 driving the hand into the table, a falling box) push the other
  joints too, so their channels carry the physical consequences the paper describes;
- reactive correction minimises proprioceptive prediction errors, which needs proprioception.

`ee_*` is the measured tool-centre-point position (m), `finger_*` the finger openings (m, with
encoder noise), `gripper_closed` the commanded 0/1 toggle, and the last 12 the finger-pad
force (N) and torque (N m) sensors in each pad's frame, tared at rest (the fingers' own weight
reads ~0.13 N) and with Gaussian sensor noise.
"""

from __future__ import annotations

JOINT_NAMES: tuple[str, ...] = tuple(f"joint{i}" for i in range(1, 8))
_WRENCH = ("fx", "fy", "fz", "tx", "ty", "tz")
CHANNEL_NAMES: tuple[str, ...] = (
    *JOINT_NAMES,
    "ee_x", "ee_y", "ee_z",
    "finger_left", "finger_right",
    "gripper_closed",
    *(f"{side}_{axis}" for side in ("left", "right") for axis in _WRENCH),
)
N_CHANNELS = len(CHANNEL_NAMES)
JOINT_CHANNELS = slice(0, 7)
EE_CHANNELS = slice(7, 10)
FINGER_CHANNELS = slice(10, 12)
GRIPPER_CHANNEL = 12
WRENCH_CHANNELS = slice(13, 25)

assert N_CHANNELS == 25
