"""From simulated episodes to models: the normal-episode split and the default Panda model.

Sits above ``sim`` and ``models`` and below the service, the experiments and the command
line, which all train, calibrate and test on the same split.
"""
