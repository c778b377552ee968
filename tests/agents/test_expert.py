"""The rule-based town expert: its decisions on hand-built observations, a whole episode, bad input."""

import numpy as np
import pytest
from gymnasium import spaces

from drivelab.agents.expert import RuleBasedExpert
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.perception.affordances import FIELDS

STRAIGHT = np.column_stack([2.0 * np.arange(1, 11), np.zeros(10)]).astype(np.float32)
SPACE = spaces.Dict(
    {
        "waypoints": spaces.Box(-40, 40, (10, 2), np.float32),
        "affordances": spaces.Box(-50, 50, (len(FIELDS),), np.float32),
    }
)
ACTIONS = spaces.Box(np.array([0.0, -1.0], np.float32), np.array([1.0, 1.0], np.float32))


def _act(waypoints=STRAIGHT, **facts):
    values = {field: 40.0 for field in FIELDS}
    values.update(speed_mps=6.0, light_red=0.0, light_yellow=0.0, leader_speed_mps=0.0)
    values.update(facts)
    expert = RuleBasedExpert(SPACE, ACTIONS, seed=0)
    obs = {"waypoints": waypoints, "affordances": np.array([values[f] for f in FIELDS], np.float32)}
    action, _ = expert.predict(obs)
    assert ACTIONS.contains(action)
    return action


def test_cruises_straight_on_a_free_road():
    speed, steer = _act()
    assert speed == pytest.approx(1.0) and steer == pytest.approx(0.0)


def test_steers_towards_a_bend_and_slows_for_it():
    # a 10 m-radius bend to the right (+y): 2 m apart along the arc
    angles = 2.0 * np.arange(1, 11) / 10.0
    bend = np.column_stack([10 * np.sin(angles), 10 * (1 - np.cos(angles))]).astype(np.float32)
    speed, steer = _act(waypoints=bend)
    assert steer > 0.1  # right
    assert speed * 6.0 <= np.sqrt(2.0 * 10.0) + 1e-6  # lateral acceleration ≤ 2 m/s² on a 10 m radius


def test_stops_for_red_leaders_and_pedestrians():
    # at its stop point (3.5 m from the line) a red light asks for 0 m/s; far away, full speed
    assert _act(stop_line_m=3.5, light_red=1.0)[0] == pytest.approx(0.0)
    assert _act(stop_line_m=30.0, light_red=1.0)[0] == pytest.approx(1.0)
    assert _act(stop_line_m=3.5)[0] == pytest.approx(1.0)  # green: drive on
    assert _act(leader_m=8.0, leader_speed_mps=0.0)[0] == pytest.approx(0.0)  # the gap to a stopped car
    assert _act(leader_m=8.0, leader_speed_mps=3.0)[0] == pytest.approx(0.5)  # match its 3 m/s
    assert _act(leader_m=6.0, leader_speed_mps=3.0)[0] == pytest.approx(1.0 / 6.0)  # 2 m inside: 1 m/s
    assert _act(pedestrian_m=6.0)[0] == pytest.approx(0.0)


def test_yellow_lights_and_left_turns():
    # yellow, 10 m from the line at 6 m/s: it can stop (needs 4.5 m at 4 m/s²), so it brakes
    assert _act(stop_line_m=10.0, light_yellow=1.0)[0] < 1.0
    # yellow with the bumper 1 m from the line at 6 m/s: too late to stop, it goes on
    assert _act(stop_line_m=3.5, light_yellow=1.0)[0] == pytest.approx(1.0)
    # a green light with a left turn behind it: it waits at the line while an oncoming car comes
    assert _act(stop_line_m=3.5, oncoming_m=20.0)[0] == pytest.approx(0.0)
    assert _act(stop_line_m=3.5, oncoming_m=40.0)[0] == pytest.approx(1.0)


def test_drives_a_fixed_test_town_route_to_its_end():
    env = DriveEnv(
        "town",
        obs="waypoints,affordances",
        action="target_speed",
        traffic="empty",
        backend_options={"layout": "test", "fixed_routes": True, "retarget": False},
    )
    expert = RuleBasedExpert(env.observation_space, env.action_space, seed=0)
    obs, _ = env.reset(seed=20_000)
    for _ in range(400):
        obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
        if terminated or truncated:
            break
    assert env.world.events.arrived and info["episode_metrics"]["success"] == 1.0
    assert info["episode_metrics"]["red_lights"] == 0 and info["episode_metrics"]["collisions"] == 0


def test_refuses_observations_it_cannot_read():
    with pytest.raises(UsageError, match="waypoints,affordances"):
        RuleBasedExpert(spaces.Dict({"waypoints": SPACE["waypoints"]}), ACTIONS)
    with pytest.raises(UsageError, match="target_speed"):
        RuleBasedExpert(SPACE, spaces.Discrete(5))


def test_drives_k_worlds_each_from_its_own_observation():
    """``--n-envs K``: every step, the rules act in each of K worlds on that world's observation."""
    from stable_baselines3.common.vec_env import VecEnvWrapper

    from drivelab.agents.sb3_env import SB3VecEnv
    from drivelab.envs.vector import VectorDriveEnv

    class Record(VecEnvWrapper):
        def __init__(self, venv):
            super().__init__(venv)
            self.observations, self.actions = [], []

        def reset(self):
            self.observations.append(self.venv.reset())
            return self.observations[-1]

        def step_async(self, actions):
            self.actions.append(np.array(actions, copy=True))
            self.venv.step_async(actions)

        def step_wait(self):
            obs, rewards, dones, infos = self.venv.step_wait()
            self.observations.append(obs)
            return obs, rewards, dones, infos

    vector = VectorDriveEnv(
        4, scenario="town", obs="waypoints,affordances", action="target_speed", autoreset_mode="same_step"
    )
    env = Record(SB3VecEnv(vector))
    env.seed(2)
    expert = RuleBasedExpert(env.observation_space, env.action_space, 0, env=env)
    expert.learn(4 * 30)
    assert expert.num_timesteps == 120 and len(env.actions) == 30
    single = RuleBasedExpert(env.observation_space, env.action_space, 0)
    for obs, actions in zip(env.observations, env.actions, strict=False):  # the obs each action saw
        for k in range(4):
            view = {name: value[k] for name, value in obs.items()}
            np.testing.assert_array_equal(actions[k], single.predict(view)[0])
    assert len({tuple(a[0]) for a in env.actions}) > 1  # the worlds' actions vary: not one constant


def test_laps_the_racetrack_behind_the_other_car():
    """The racetrack's rules (faster cruise and bends, the action's speed range widened to match):
    30 s of the regular-traffic racetrack (one other car, slower in the bends) without a collision
    or leaving the road, faster than the town's 6 m/s cap allows."""
    env = DriveEnv("racetrack", obs="waypoints,affordances", action="target_speed", traffic="regular",
                   action_options={"max_speed_mps": 20.0}, duration_s=30)  # fmt: skip
    rules = {"cruise_speed_mps": 15.0, "lateral_accel_mps2": 6.0, "max_speed_mps": 20.0}
    expert = RuleBasedExpert(env.observation_space, env.action_space, 0, rules, env=env)
    obs, _ = env.reset(seed=4)
    leaders = []
    for _ in range(150):
        obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
        leaders.append(obs["affordances"][FIELDS.index("leader_m")])
        if terminated or truncated:
            break
    metrics = info["episode_metrics"]
    assert truncated and metrics["collisions"] == 0 and metrics["off_road_events"] == 0
    assert metrics["mean_speed_mps"] > 6.0
    assert min(leaders) < 20.0  # it met the other car on the way


@pytest.mark.parametrize("slip_aware", [False, True])
def test_slip_aware_pursuit_holds_the_lane_centre_through_a_bend(slip_aware):
    """highway-env's bicycle moves along heading + β: pure pursuit in the heading's frame cuts a
    12 m-radius bend of a block map by over a metre and crosses its solid line (MetaDrive's out of
    road); pursuit in the velocity's frame stays inside the lines."""
    from drivelab.agents.worlds import vector_env_of

    env = DriveEnv("blocks", obs="waypoints,affordances", action="target_speed",
                   action_options={"max_speed_mps": 20.0})  # fmt: skip
    rules = {"cruise_speed_mps": 15.0, "max_speed_mps": 20.0, "slip_aware": slip_aware}
    expert = RuleBasedExpert(env.observation_space, env.action_space, 0, rules, env=env)
    obs, _ = env.reset(seed=1000)
    lateral, curvature = [], []
    for _ in range(120):
        obs, _, terminated, truncated, info = env.step(expert.predict(obs)[0])
        ego = vector_env_of(env).batch.ego
        lateral.append(abs(ego.lateral_offset_m[0]))
        curvature.append(abs(ego.lane_curvature[0]))
        if terminated or truncated:
            break
    assert max(curvature) > 0.08  # the route takes a bend of radius < 12.5 m
    if slip_aware:
        # 0.7 m at most, on entering the bend (its curvature starts in a step), then back to the
        # centre: a 2 m body crosses a 3.5 m lane's line beyond 0.75 m
        assert not terminated and max(lateral) < 0.7 and lateral[-1] < 0.2
    else:
        assert terminated and info["episode_metrics"]["off_road_events"] == 1 and max(lateral) > 1.0
