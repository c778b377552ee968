"""Shipped agents: packing, listing, loading without unpickling, ``enjoy`` and zoo names elsewhere."""

import fnmatch
import importlib.util
import json
import pickle
import shlex
import sys
import tomllib
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch
import yaml
from typer.testing import CliRunner

from drivelab.agents.storage import PICKLED_MEMBERS
from drivelab.cli import app
from drivelab.config import build_config
from drivelab.envs.core import DriveEnv
from drivelab.errors import UsageError
from drivelab.training import run as run_module
from drivelab.training import zoo
from drivelab.training.checkpoints import load_agent
from drivelab.training.evaluate import aggregate, evaluate_run, load_run_config
from drivelab.training.nocrash import nocrash

runner = CliRunner()
ROOT = Path(__file__).resolve().parents[2]
SHIPPED = zoo.shipped_agents()


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> Path:
    """A town run of 16 PPO steps with one-second episodes (one Adam step: the optimizer has moments)."""
    config = build_config(
        {"algo": "ppo", "env": "town", "obs": "waypoints", "action": "target_speed", "traffic": "empty",
         "steps": 16, "seed": 0, "name": "town", "eval_every": 16, "eval_episodes": 1,
         "hyperparams": {"n_steps": 16, "batch_size": 16, "n_epochs": 1}, "env_options": {"duration_s": 1}}
    )  # fmt: skip
    return run_module.train(config, tmp_path_factory.mktemp("runs"))


@pytest.fixture
def tiny_zoo(tiny_run, tmp_path, monkeypatch) -> Path:
    """A zoo of one agent, ``tiny``, packed from ``tiny_run``; the package's zoo is out of reach."""
    zoo_dir = tmp_path / "zoo"
    monkeypatch.setattr(zoo, "ZOO_DIR", zoo_dir)
    zoo.pack(tiny_run, "tiny", "a test agent", "drivelab train ...", {"train_wall_s": 1.0})
    return zoo_dir


def _files(folder: Path) -> set[str]:
    return {str(p.relative_to(folder)) for p in folder.rglob("*")}


def _observations(env, count: int = 5) -> list:
    obs, _ = env.reset(options={"episode_seed": 7})
    observations = [obs]
    for _ in range(count - 1):
        obs, *_ = env.step(env.action_space.sample())
        observations.append(obs)
    return observations


def test_pack_copies_config_and_model_without_optimizer_moments_and_writes_a_card(tiny_run, tiny_zoo):
    folder = tiny_zoo / "tiny"
    assert _files(folder) == {"card.json", "config.yaml", "model.zip"}
    card = json.loads((folder / "card.json").read_text())
    assert card["format"] == zoo.CARD_FORMAT and card["name"] == "tiny"
    assert (card["algo"], card["env"], card["obs"], card["action"]) == (
        "ppo",
        "town",
        ["waypoints"],
        "target_speed",
    )
    assert card["training"]["steps"] == 16 and card["training"]["command"] == "drivelab train ..."
    assert card["training"]["train_wall_s"] == 1.0 and card["evaluations"] == []
    assert card["model"]["bytes"] == (folder / "model.zip").stat().st_size
    # no Adam moments, float16 weights: a quarter of the bytes, the run's weights rounded, its actions
    assert (folder / "model.zip").stat().st_size < (tiny_run / "model.zip").stat().st_size / 2
    original = load_agent(tiny_run, load_run_config(tiny_run))
    shipped = load_agent(folder, load_run_config(folder))
    assert original.policy.optimizer.state and not shipped.policy.optimizer.state
    weights = original.policy.state_dict()
    for key, value in shipped.policy.state_dict().items():
        assert value.dtype == torch.float32 and torch.equal(value, weights[key].half().float()), key
    env = DriveEnv(**load_run_config(folder).eval_env_kwargs())
    for obs in _observations(env):
        run_action = original.predict(obs, deterministic=True)[0]
        assert np.allclose(shipped.predict(obs, deterministic=True)[0], run_action, atol=1e-2)
    # packing again replaces the folder and leaves no staging folder behind
    zoo.pack(tiny_run, "tiny", "again", "drivelab train ...")
    assert [p.name for p in tiny_zoo.iterdir()] == ["tiny"]
    assert json.loads((folder / "card.json").read_text())["description"] == "again"


def test_listing_and_resolving(tiny_run, tiny_zoo):
    zoo.add_evaluation(
        "tiny", {"protocol": "evaluation set", "metrics": {"crash_rate": 0.25, "success_rate": 0.5,
                                                          "mean_speed_mps": 21.04, "episodes": 4}}
    )  # fmt: skip
    assert [agent.name for agent in zoo.shipped_agents()] == ["tiny"]
    result = runner.invoke(app, ["zoo"])
    assert result.exit_code == 0, result.output
    assert result.output.split()[:4] == ["tiny", "town", "ppo", "obs"]
    assert "evaluation set: crash 25 %, success 50 %, 21.0 m/s (4 episodes)" in result.output
    assert zoo.resolve("tiny") == (tiny_zoo / "tiny", "tiny")
    assert zoo.resolve(tiny_run) == (tiny_run, None)  # a directory is a run directory
    with pytest.raises(UsageError, match="shipped agent 'no-such-agent' does not exist.*lists: tiny"):
        zoo.resolve("no-such-agent")


def test_an_empty_zoo_says_so(tmp_path, monkeypatch):
    monkeypatch.setattr(zoo, "ZOO_DIR", tmp_path / "nothing")
    result = runner.invoke(app, ["zoo"])
    assert result.exit_code == 0 and result.output.startswith("no shipped agents")


def test_enjoy_plays_the_evaluation_episodes_of_drivelab_evaluate(tiny_zoo, tmp_path):
    seen = []
    report = zoo.enjoy("tiny", episodes=3, on_episode=lambda i, metrics: seen.append(i))
    assert seen == [0, 1, 2] and report["agent"] == "tiny" and report["episodes"] == 3
    evaluated = evaluate_run(tiny_zoo / "tiny", episodes=3, out_dir=tmp_path / "reports")
    assert {key: report[key] for key in evaluated if key != "run"} == {
        key: value for key, value in evaluated.items() if key != "run"
    }
    assert aggregate(report["per_episode"]) == {key: report[key] for key in aggregate(report["per_episode"])}
    # another seed plays other episodes, reproducibly
    other = zoo.enjoy("tiny", episodes=3, seed=5)
    assert other["per_episode"] == zoo.enjoy("tiny", episodes=3, seed=5)["per_episode"]
    assert other["per_episode"] != report["per_episode"]


@pytest.mark.parametrize("suffix", [".gif", ".mp4"])
def test_enjoy_writes_every_frame_of_every_episode(tiny_zoo, tmp_path, suffix):
    import imageio.v3 as iio

    path = tmp_path / f"drive{suffix}"
    report = zoo.enjoy("tiny", episodes=2, video=path)
    per_step = DriveEnv(scenario="town").simulator.frames  # one frame per simulation frame
    expected = sum(1 + per_step * episode["length"] for episode in report["per_episode"])  # + reset
    assert report["video"] == str(path) and report["video_frames"] == expected
    assert len(iio.imread(path, index=None)) == expected
    assert _files(tmp_path) == {
        path.name,
        "zoo",
        "zoo/tiny",
        *[f"zoo/tiny/{n}" for n in _files(tiny_zoo / "tiny")],
    }


def test_cli_enjoy_prints_progress_and_metrics(tiny_zoo, tmp_path):
    result = runner.invoke(app, ["enjoy", "tiny", "--episodes", "2", "--video", str(tmp_path / "v.gif")])
    assert result.exit_code == 0, result.output
    assert "episode 1/2:" in result.output and "episode 2/2:" in result.output
    assert "crash rate" in result.output and f"video: {tmp_path / 'v.gif'}" in result.output
    result = runner.invoke(app, ["enjoy", str(tiny_zoo / "tiny"), "--episodes", "1", "--seed", "3"])
    assert result.exit_code == 0 and "episode 1/1:" in result.output, result.output  # a run directory


def test_evaluate_and_nocrash_take_a_zoo_name_and_write_outside_the_package(tiny_zoo, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    before = _files(tiny_zoo)
    result = runner.invoke(app, ["evaluate", "tiny", "--episodes", "2"])
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "runs" / "zoo-tiny" / "eval.json").read_text())["episodes"] == 2
    result = runner.invoke(app, ["benchmark", "nocrash", "tiny", "--episodes", "1", "--out", "nc"])
    assert result.exit_code == 0, result.output
    assert json.loads((tmp_path / "nc" / "nocrash.json").read_text())["episodes_per_level"] == 1
    assert _files(tiny_zoo) == before  # the shipped agent is never written to
    assert nocrash(tiny_zoo / "tiny", episodes=1, out_dir=tmp_path / "again")["episodes_per_level"] == 1


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["enjoy", "no-such-agent"], "shipped agent 'no-such-agent' does not exist"),
        (["enjoy", "tiny", "--episodes", "0"], "--episodes must be >= 1"),
        (["enjoy", "tiny", "--seed", "-1"], "--seed must be in"),
        (["enjoy", "tiny", "--video", "out.avi"], "must end in .mp4 or .gif"),
        (["enjoy", "tiny", "--video", "missing/out.mp4"], "folder 'missing' does not exist"),
        (["enjoy", "tiny", "--video", "folder.mp4"], "is a directory"),
        (["evaluate", "no-such-agent"], "shipped agent 'no-such-agent' does not exist"),
        (["benchmark", "nocrash", "no-such-agent"], "shipped agent 'no-such-agent' does not exist"),
    ],
)
def test_bad_input_is_one_error_line_and_writes_nothing(tiny_zoo, tmp_path, monkeypatch, arguments, message):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "folder.mp4").mkdir()
    before = _files(tmp_path)
    result = runner.invoke(app, arguments)
    assert result.exit_code == 2, result.output
    lines = result.output.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and message in lines[0], result.output
    assert _files(tmp_path) == before


def test_an_unwritable_video_folder_is_refused_before_driving(tiny_zoo, tmp_path, monkeypatch):
    monkeypatch.setattr(zoo.tempfile, "TemporaryFile", _raise_read_only)
    monkeypatch.setattr("drivelab.training.evaluate.run_episodes", lambda *a, **k: pytest.fail("drove"))
    with pytest.raises(UsageError, match="cannot write --video .*Read-only file system"):
        zoo.enjoy("tiny", video=tmp_path / "out.gif")
    assert not (tmp_path / "out.gif").exists()


def _raise_read_only(*args, **kwargs):
    raise OSError(30, "Read-only file system")


# --- the agents shipped in the package ---------------------------------------------------------
def test_the_zoo_ships_agents_with_complete_cards():
    assert {agent.card["env"] for agent in SHIPPED} >= {"town"}
    for agent in SHIPPED:
        card = agent.card
        assert _files(agent.path) == {"card.json", "config.yaml", "model.zip"}, agent.name
        assert card["model"]["bytes"] == (agent.path / "model.zip").stat().st_size < 2 * 2**20
        config = load_run_config(agent.path)
        assert (card["algo"], card["env"], card["obs"]) == (config.algo, config.env, list(config.obs))
        assert card["training"]["command"].startswith("drivelab train ") and card["training"]["steps"] > 0
        assert card["evaluations"] and card["check"]["episodes"] == 3
        for evaluation in card["evaluations"]:
            assert evaluation["command"].startswith("drivelab ") and evaluation["episodes"] >= 10


def test_every_shipped_file_is_package_data():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    for agent in SHIPPED:
        for name in _files(agent.path):
            relative = f"zoo/{agent.name}/{name}"
            assert any(fnmatch.fnmatch(relative, pattern) for pattern in patterns["drivelab"]), relative


@pytest.mark.parametrize("agent", SHIPPED, ids=[agent.name for agent in SHIPPED])
def test_shipped_agents_load_without_unpickling(agent, monkeypatch):
    """No pickled member; tensors only through ``torch.load(weights_only=True)`` (its restricted
    unpickler of tensors and plain containers), arrays (a Q-table) only through
    ``np.load(allow_pickle=False)``; ``pickle.load(s)`` never called."""
    with zipfile.ZipFile(agent.path / "model.zip") as archive:
        names = set(archive.namelist())
    assert not names & set(PICKLED_MEMBERS)
    config = load_run_config(agent.path)
    load_agent(agent.path, config)  # first: torch's lazy imports, which may use pickle themselves
    loads, array_loads = [], []
    real_load, real_np_load = torch.load, np.load

    def checked_load(*args, **kwargs):
        assert kwargs.get("weights_only") is True
        loads.append(args)
        return real_load(*args, **kwargs)

    def checked_np_load(*args, **kwargs):
        assert kwargs.get("allow_pickle") is False
        array_loads.append(args)
        return real_np_load(*args, **kwargs)

    def refuse(*args, **kwargs):
        raise AssertionError("unpickled")

    monkeypatch.setattr(torch, "load", checked_load)
    monkeypatch.setattr(np, "load", checked_np_load)
    monkeypatch.setattr(pickle, "load", refuse)
    monkeypatch.setattr(pickle, "loads", refuse)
    assert load_agent(agent.path, config) is not None
    # every member holding numbers was read through one of the two checked loaders
    assert len(loads) >= sum(name.endswith(".pt") for name in names)
    assert len(array_loads) >= sum(name.endswith((".npy", ".npz")) for name in names)
    assert loads or array_loads


@pytest.mark.parametrize("agent", SHIPPED, ids=[agent.name for agent in SHIPPED])
def test_shipped_agents_reproduce_their_recorded_check(agent):
    """``drivelab enjoy NAME --episodes 3`` (its episodes cut at the check's ``duration_s`` where
    it has one) gives exactly the numbers recorded when the agent was packed.

    Recorded and checked under one pinned instruction set (``drivelab.isa.PINNED_ISA``: AVX2 code
    paths in numpy, OpenBLAS, oneDNN, MKL, torch and numba, one thread each), in a fresh process,
    rather than compared within a tolerance: an agent's actions feed back into its episodes, so an
    ulp of difference between AVX-512 and AVX2 kernels grows to ~1e-3 in a 3-episode mean
    (town-dagger's std_return: 32.9196 natively on AVX-512, 32.9626 on an AVX2 EPYC), the size of
    a real change of behaviour. Under the pin an AVX-512 EPYC gives the AVX2 EPYC's 32.96262951516252
    bit for bit, so every number, counts and floats alike, is compared exactly."""
    assert agent.card["check"]["isa"].startswith("drivelab.isa.PINNED_ISA")
    assert zoo.pinned_check_metrics(agent.name) == agent.card["check"]["metrics"]


def test_every_cards_training_command_is_its_build_recipe():
    """A card's command trains its agent today: benchmarks/zoo_build.py's recipe, with the values
    pinned that drivelab's shipped hyper-parameters no longer give (the PPO cards once left out
    highway-env's values, which the tuned merge and roundabout entries have since replaced). The
    pinned values are the card's own hyper-parameters (or SB3's defaults where it has none)."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("zoo_build", ROOT / "benchmarks" / "zoo_build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    sb3_ppo_defaults = {"gae_lambda": 0.95, "ent_coef": 0.0, "clip_range": 0.2}
    assert set(build.AGENTS) == {agent.name for agent in SHIPPED}
    for name, recipe in build.AGENTS.items():
        card = json.loads((zoo.ZOO_DIR / name / "card.json").read_text())
        arguments = ["train", *recipe["train"], "--runs-dir", str(build.RUNS), "--name", name]
        assert card["training"]["command"] == "drivelab " + shlex.join(arguments), name
        pins = recipe["train"]
        for flag, value in zip(pins, pins[1:], strict=False):
            if flag == "-H" and name.endswith("-ppo"):
                key, text = value.split("=", 1)
                pinned = yaml.safe_load(text)
                assert card["hyperparams"].get(key, sb3_ppo_defaults.get(key)) == pinned, (name, key)


def _rewrite_member(path: Path, member: str, change) -> None:
    """Replace ``member`` of the zip ``path`` by ``change(its bytes)`` (None: drop it)."""
    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    members[member] = change(members[member])
    with zipfile.ZipFile(path, "w") as archive:
        for name, data in members.items():
            if data is not None:
                archive.writestr(name, data)


def test_model_differences_compares_values_member_by_member(tiny_zoo, tmp_path):
    from drivelab.agents.storage import tensors_from_bytes, tensors_to_bytes

    shipped = tiny_zoo / "tiny" / "model.zip"
    copy = tmp_path / "copy.zip"
    copy.write_bytes(shipped.read_bytes())

    def reclock(data: bytes) -> bytes:  # the same values in other bytes, the episodes' clock moved
        state = json.loads(data)
        state["ep_info_buffer"] = [{**e, "t": e["t"] + 1.0} for e in state["ep_info_buffer"]]
        return json.dumps(state, indent=1).encode()

    assert json.loads(zipfile.ZipFile(shipped).read("sb3.json"))["ep_info_buffer"]  # the clock is there
    _rewrite_member(copy, "sb3.json", reclock)
    assert copy.read_bytes() != shipped.read_bytes() and zoo.model_differences(shipped, copy) == {}

    def nudge(data: bytes) -> bytes:
        state = tensors_from_bytes(data)
        policy = state["state_dicts"]["policy"]
        key = next(k for k, v in policy.items() if v.dtype == torch.float16)
        policy[key] = policy[key].clone()
        policy[key].view(-1)[0] += 0.5
        return tensors_to_bytes(state)

    _rewrite_member(copy, "parameters.pt", nudge)
    (member, how), *others = zoo.model_differences(shipped, copy).items()
    assert member == "parameters.pt" and not others
    assert (
        how.startswith("max |difference| ") and abs(float(how.split()[-1]) - 0.5) < 0.01
    )  # float16's rounding

    copy.write_bytes(shipped.read_bytes())
    _rewrite_member(
        copy, "sb3.json", lambda data: json.dumps({**json.loads(data), "num_timesteps": 1}).encode()
    )
    assert zoo.model_differences(shipped, copy) == {"sb3.json": "other values of num_timesteps"}
    _rewrite_member(copy, "sb3.json", lambda data: None)
    assert zoo.model_differences(shipped, copy) == {"sb3.json": f"only in {str(shipped)!r}"}


def test_verify_retrains_a_recipe_and_finds_the_shipped_model(tmp_path, monkeypatch):
    """zoo_build --verify: a recipe trained again packs the model a zoo holds, bit for bit, and
    one trained otherwise (another seed) is told apart; the zoo is left as it was."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("zoo_build", ROOT / "benchmarks" / "zoo_build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    monkeypatch.setattr(build, "VERIFY_RUNS", tmp_path / "verify")
    recipe = shlex.split(
        "--algo ppo --env highway --obs kinematics --action meta --traffic empty --steps 32 --n-envs 1 "
        "-H n_steps=32 -H batch_size=16 -H n_epochs=1 --eval-every 32 --eval-episodes 1 --seed 0"
    )
    build.drivelab(["train", *recipe, "--runs-dir", str(tmp_path / "runs"), "--name", "tiny"])
    zoo_dir = tmp_path / "zoo"
    zoo.pack(tmp_path / "runs" / "tiny", "tiny", "a test agent", "drivelab train ...", zoo_dir=zoo_dir)
    before = (zoo_dir / "tiny" / "model.zip").read_bytes()
    record = build.verify("tiny", {"train": recipe, "description": "a test agent"}, zoo_dir)
    assert record["identical"] and record["differences"] == {} and record["pinned_defaults"] is None
    pinned = build.verify(
        "tiny", {"train": [*recipe, "-H", "clip_range=0.2"], "description": "SB3's own"}, zoo_dir
    )
    assert pinned["differences"] == {"sb3.json": "other values of hyperparams"}  # the record names it
    assert pinned["identical"] and pinned["pinned_defaults"] == {"clip_range": 0.2}  # the same model
    assert record["command"].endswith(f"--runs-dir {tmp_path / 'verify'} --name tiny")
    other = build.verify("tiny", {"train": [*recipe[:-1], "1"], "description": "another seed"}, zoo_dir)
    assert (
        not other["identical"]
        and "parameters.pt" in other["differences"]
        and other["pinned_defaults"] is None
    )
    assert (zoo_dir / "tiny" / "model.zip").read_bytes() == before
    assert sorted(p.name for p in (tmp_path / "verify").iterdir()) == ["tiny"]
    records = [record, {**other, "name": "other"}, {**pinned, "name": "pinned"}]
    written = build.write_verification(records, "python zoo_build.py --verify", tmp_path / "v")
    table = (tmp_path / "v.md").read_text()
    assert "| tiny | yes | nothing |" in table and "| other | no | parameters.pt: max |difference|" in table
    assert written == tmp_path / "v.md"
    assert "| pinned | yes | the SB3 record of one lists clip_range 0.2, the algorithm's defaults" in table
    assert set(json.loads((tmp_path / "v.json").read_text())["agents"]) == {"other", "pinned", "tiny"}


def test_model_differences_sees_nans_and_whole_numbers_exactly(tmp_path):
    import io

    def model(name: str, table) -> Path:
        buffer = io.BytesIO()
        np.save(buffer, np.asarray(table))
        with zipfile.ZipFile(tmp_path / name, "w") as archive:
            archive.writestr("q_table.npy", buffer.getvalue())
        return tmp_path / name

    nan, other = model("nan.zip", [1.0, np.nan]), model("number.zip", [3.0, 2.0])
    assert zoo.model_differences(nan, other) == {
        "q_table.npy": "nan against a number; max |difference| elsewhere 2"
    }
    assert zoo.model_differences(nan, model("nan2.zip", [1.0, np.nan])) == {}
    big, bigger = model("big.zip", [2**60, 1]), model("bigger.zip", [2**60 + 1, 1])  # equal as float64
    assert zoo.model_differences(big, bigger) == {"q_table.npy": "max |difference| 1"}


def test_a_weight_beyond_float16_is_refused_when_packing(tmp_path):
    from drivelab.agents.storage import tensors_to_bytes

    path = tmp_path / "model.zip"
    with zipfile.ZipFile(path, "w") as archive:
        archive.writestr("parameters.pt", tensors_to_bytes({"policy": {"w": torch.tensor([1.0, -1e6])}}))
    with pytest.raises(UsageError, match="a weight of magnitude 1e\\+06 does not fit float16"):
        zoo._store_half_precision(path)


def test_zoo_build_finishes_a_run_a_kill_left_without_its_model(tmp_path, monkeypatch):
    """A build killed after the run's last checkpoint, before its model: building again resumes
    the run (no "already exists") and packs the model the run would have had."""
    sys.path.insert(0, str(ROOT / "benchmarks"))
    spec = importlib.util.spec_from_file_location("zoo_build", ROOT / "benchmarks" / "zoo_build.py")
    build = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(build)
    monkeypatch.setattr(build, "RUNS", tmp_path / "runs")
    monkeypatch.setattr(zoo, "ZOO_DIR", tmp_path / "zoo")
    recipe = shlex.split(
        "--algo ppo --env highway --obs kinematics --action meta --traffic empty --steps 32 --n-envs 1 "
        "-H n_steps=32 -H batch_size=16 -H n_epochs=1 --eval-every 32 --eval-episodes 1 --seed 0"
    )
    build.drivelab(["train", *recipe, "--runs-dir", str(tmp_path / "whole"), "--name", "tiny"])
    build.drivelab(["train", *recipe, "--runs-dir", str(tmp_path / "runs"), "--name", "tiny"])
    (tmp_path / "runs" / "tiny" / "model.zip").unlink()  # killed between its checkpoint and its model
    build.train_and_pack("tiny", {"train": recipe, "description": "a test agent"}, retrain=False)
    assert (tmp_path / "runs" / "tiny" / "model.zip").is_file()
    assert "train_wall_s" not in json.loads((tmp_path / "zoo" / "tiny" / "card.json").read_text())["training"]
    differences = zoo.model_differences(
        tmp_path / "whole" / "tiny" / "model.zip", tmp_path / "runs" / "tiny" / "model.zip"
    )
    assert differences == {}  # the model an uninterrupted run packs


def test_model_differences_leaves_out_when_sb3_learned(tiny_zoo, tmp_path):
    """A resumed SB3 run records where its last learn() began (_num_timesteps_at_start, for the
    steps-per-second log), one never stopped 0: the same model."""
    shipped = tiny_zoo / "tiny" / "model.zip"
    copy = tmp_path / "copy.zip"
    copy.write_bytes(shipped.read_bytes())

    def resumed_at(step: int):
        def change(data: bytes) -> bytes:
            state = json.loads(data)
            return json.dumps(
                {**state, "counters": {**state["counters"], "_num_timesteps_at_start": step}}
            ).encode()

        return change

    _rewrite_member(copy, "sb3.json", resumed_at(8))
    assert zoo.model_differences(shipped, copy) == {}
    _rewrite_member(copy, "sb3.json", lambda data: json.dumps({**json.loads(data), "counters": {}}).encode())
    assert zoo.model_differences(shipped, copy) == {"sb3.json": "other values of counters"}
