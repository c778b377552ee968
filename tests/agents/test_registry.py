"""agents/registry.py: the one table of algorithms, and what derives from it."""

import pytest

from drivelab.agents.registry import (
    ALGO_NAMES,
    ALGORITHMS,
    FAMILIES,
    agent_classes,
    algo_of,
    check_combination,
    get_algo,
    load_entry_point,
)
from drivelab.errors import UsageError


def test_every_entry_resolves_and_names_itself():
    assert ALGO_NAMES == tuple(ALGORITHMS) and len(ALGO_NAMES) == 13
    for name, spec in ALGORITHMS.items():
        assert spec.name == name and spec.family in FAMILIES
        cls = spec.agent_class()
        assert isinstance(cls, type) and algo_of(cls) == name
        builder, loader = (load_entry_point(point) for point in FAMILIES[spec.family])
        assert callable(builder) and callable(loader)
        if spec.observation_check is not None:
            assert callable(load_entry_point(spec.observation_check))


def test_families_and_the_names_agents_save_under():
    assert sorted(agent_classes("sb3")) == ["a2c", "dqn", "ppo", "sac"]
    own = agent_classes("own")
    assert sorted(own) == ["a2c_own", "bc", "dagger", "drq", "dueling_ddqn", "expert", "ppo_own", "rlad"]
    assert {cls.algo for cls in own.values()} == set(own)  # OwnAgent.algo reads the registry
    assert issubclass(own["drq"], own["rlad"]) and own["drq"].algo == "drq"
    assert issubclass(own["dagger"], own["bc"]) and own["dagger"].algo == "dagger"
    with pytest.raises(LookupError, match="no registered algorithm"):
        algo_of(UsageError)


def test_unknown_names_and_combinations_are_usage_errors():
    with pytest.raises(UsageError, match="unknown algorithm 'ddpg' \\(choose from dqn, ppo"):
        get_algo("ddpg")
    with pytest.raises(UsageError, match="cannot take 'continuous' actions"):
        check_combination("dqn", "continuous")
    assert check_combination("ppo_own", "continuous") is ALGORITHMS["ppo_own"]
