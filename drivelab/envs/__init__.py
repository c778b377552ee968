"""Driving environments: every scenario is registered as ``drivelab/<Scenario>-v0``, with
``gymnasium.make`` giving its DriveEnv and ``gymnasium.make_vec`` its vector env (the id's
``vector_entry_point``: a VectorDriveEnv on the compiled core)."""

from __future__ import annotations

import gymnasium

from drivelab.scenarios import SCENARIOS, gym_id

for _name in SCENARIOS:
    if gym_id(_name) not in gymnasium.registry:
        gymnasium.register(
            gym_id(_name),
            entry_point="drivelab.envs.core:DriveEnv",
            vector_entry_point="drivelab.envs.core:make_vec",
            kwargs={"scenario": _name},
        )
