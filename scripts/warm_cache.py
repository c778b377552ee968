"""Compile the simulator's kernels into numba's cache at set-up, so that the README's first command
(a short PPO run on highway, kinematics and meta-actions: one world and a batch of worlds) starts
without the one-time compile. Other scenarios compile on their first use, once per version."""

import drivelab
from drivelab.envs.vector import VectorDriveEnv

for worlds in (1, 4):
    env = VectorDriveEnv(worlds, "highway", obs="kinematics", action="meta", reward="highway")
    env.reset(seed=0)
    for _ in range(3):
        env.step([1] * worlds)
    env.close()
one = drivelab.make("highway", obs="kinematics", action="meta", reward="highway")
one.reset(seed=0)
one.step(1)
