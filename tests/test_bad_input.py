"""Issue 15, part 3: every bad input is one ``error:`` line, exit code 2, no traceback, and the
filesystem exactly as it was (no run directory, no empty ``runs/`` root, no report debris).

Each case runs the CLI in-process through typer's CliRunner, inside a temporary folder whose whole
tree (paths, sizes, bytes) is compared before and after.
"""

from __future__ import annotations

import hashlib
import os
import shutil
from pathlib import Path

import pytest
import torch
from typer.testing import CliRunner

from drivelab.cli import app

runner = CliRunner()
AS_ROOT = hasattr(os, "geteuid") and os.geteuid() == 0  # root writes through chmod 0o555


def snapshot(root: Path) -> dict[str, str]:
    """Every path under ``root`` → "dir", or its bytes' SHA-256 (and mode, for chmod cases)."""
    tree = {}
    for path in sorted(root.rglob("*")):
        key = str(path.relative_to(root))
        mode = oct(path.stat().st_mode & 0o777)
        tree[key] = f"dir {mode}" if path.is_dir() else hashlib.sha256(path.read_bytes()).hexdigest() + mode
    return tree


def assert_refused(root: Path, args: list[str], message: str) -> None:
    """Run ``drivelab ARGS`` in ``root``: exit 2, one line ``error: ...message...``, no change."""
    before = snapshot(root)
    result = runner.invoke(app, args)
    lines = result.output.strip().splitlines()
    assert result.exit_code == 2, result.output
    assert len(lines) == 1 and lines[0].startswith("error: "), result.output
    assert message in lines[0]
    assert "Traceback" not in result.output
    assert snapshot(root) == before


def train_args(work: Path, *args: str) -> list[str]:
    return ["train", *args, "--runs-dir", str(work / "runs"), "--steps", "20"]


RANDOM_BYTES = bytes(range(256)) * 8  # neither a torch file nor UTF-8 text
# issue 47: 332 bytes of YAML whose anchors expand to 10^9 sensor names (the 10^8 of the probe took
# 85 s and 1.2 GB before its error), and brackets nested 20,000 deep (a RecursionError before)
ALIAS_BOMB = (
    "algo: ppo\nx0: &a0 [lidar,lidar,lidar,lidar,lidar,lidar,lidar,lidar,lidar,lidar]\n"
    + "".join(f"x{i}: &a{i} [{','.join([f'*a{i - 1}'] * 10)}]\n" for i in range(1, 9))
    + "obs: *a8\n"
).encode()
DEEP_YAML = b"algo: ppo\nobs: " + b"[" * 20_000 + b"]" * 20_000 + b"\n"

EXPERT_ON_HIGHWAY = "--algo expert --env highway --obs waypoints,affordances --action target_speed".split()
# (CLI options after `train`, files to create in the working folder, expected part of the message)
TRAIN_CASES = {
    # tracebacks before
    "dqn gamma=abc": (
        ["--algo", "dqn", "-H", "gamma=abc"],
        {},
        "'gamma' of 'dqn' must be a number in [0, 1]",
    ),
    "topdown stack=abc": (
        ["--algo", "ppo", "--obs", "topdown:stack=abc"],
        {},
        "'stack' of 'topdown' must be an",
    ),
    "seed -1": (["--algo", "ppo", "--seed", "-1"], {}, "'seed' must be between 0 and"),
    # click's own parsing errors, in click's box before
    "seed abc": (["--algo", "ppo", "--seed", "abc"], {}, "invalid value for '--seed'"),
    "unknown option": (["--algo", "ppo", "--bogus", "1"], {}, "no such option: --bogus"),
    # a traceback after a partly written run directory before
    "reward weight nan": (["--algo", "ppo", "--reward", "crash=nan"], {}, "'crash' needs a finite weight"),
    "reward weight inf": (
        ["--algo", "ppo", "--reward", "highway,collision=-inf"],
        {},
        "'collision' needs a finite weight",
    ),
    # torch's RuntimeError when the agent was built, before the widths were checked
    "net_arch -1": (
        ["--algo", "ppo", "-H", "policy_kwargs={net_arch: [-1]}"],
        {},
        "policy_kwargs net_arch of 'ppo' must be a list of layer widths >= 1",
    ),
    "eval-maps without a count": (
        ["--algo", "ppo", "--env", "blocks", "--eval-maps", "5"],
        {},
        "eval_maps must be START:COUNT",
    ),
    "eval-maps count 0": (
        ["--algo", "ppo", "--env", "blocks", "--eval-maps", "3:0"],
        {},
        "eval_maps must be START:COUNT",
    ),
    "eval-maps on one road": (
        ["--algo", "ppo", "--env", "highway", "--eval-maps", "0:5"],
        {},
        "eval_maps is for procedural maps",
    ),
    "env_options bogus": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\nenv_options: {bogus_option: 1}\n"},
        "unknown env_options key 'bogus_option' (known: duration_s, offroad_terminal",
    ),
    "non-UTF-8 config": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\n# caf\xe9\n"},
        "is not UTF-8 text",
    ),
    "name ../..": (
        ["--algo", "ppo", "--name", "../.."],
        {},
        "run name '../..' must be a single directory name",
    ),
    "name a/b": (["--algo", "ppo", "--name", "a/b"], {}, "run name 'a/b' must be a single"),
    "name absolute": (
        ["--algo", "ppo", "--name", "/tmp/escape"],
        {},
        "run name '/tmp/escape' must be a single",
    ),
    "name .": (["--algo", "ppo", "--name", "."], {}, "run name '.' must be a single"),
    "name ..": (["--algo", "ppo", "--name", ".."], {}, "run name '..' must be a single"),
    "name empty": (["--algo", "ppo", "--name", ""], {}, "run name '' must be a single"),
    "lane weights random": (
        [
            "--algo",
            "qlearning",
            "--env",
            "follow-lane",
            "--obs",
            "lane:weights=noise.pt",
            "--action",
            "seed_lane",
        ],
        {"noise.pt": RANDOM_BYTES},
        "'noise.pt' is not lane CNN weights",
    ),
    # an empty runs/ before
    "ppo learning_rate=-1": (
        ["--algo", "ppo", "-H", "learning_rate=-1"],
        {},
        "'learning_rate' of 'ppo' must be a number in (0, 1.0]",
    ),
    "ppo nonexistent=3": (
        ["--algo", "ppo", "-H", "nonexistent=3"],
        {},
        "unknown hyperparameter 'nonexistent' for 'ppo'",
    ),
    "ppo --no-alix": (["--algo", "ppo", "--no-alix"], {}, "unknown hyperparameter 'alix' for 'ppo'"),
    "qlearning camera": (
        ["--algo", "qlearning", "--env", "follow-line", "--obs", "camera"],
        {},
        "'qlearning' needs a discrete observation (--obs line on follow-line",
    ),
    "qlearning on the default sensor": (  # said "cannot read 'vector' observations (it reads other)"
        ["--algo", "qlearning", "--env", "follow-line"],
        {},
        "'qlearning' needs a discrete observation (--obs line on follow-line, lane on follow-lane, or "
        "ttc_grid), got Box",
    ),
    "expert without affordances": (
        ["--algo", "expert", "--env", "town", "--obs", "waypoints", "--action", "target_speed"],
        {},
        "expert needs --obs waypoints,affordances",
    ),
    "dueling_ddqn alpha=abc": (
        ["--algo", "dueling_ddqn", "-H", "alpha=abc"],
        {},
        "'alpha' of 'dueling_ddqn' must be a number, got 'abc'",
    ),
    "dueling_ddqn exploration 2": (
        ["--algo", "dueling_ddqn", "-H", "exploration_fraction=2"],
        {},
        "_fraction in [0, 1]",
    ),
    "qlearning learning_rate=abc": (
        ["--algo", "qlearning", "--env", "follow-line", "--obs", "line", "-H", "learning_rate=abc"],
        {},
        "'learning_rate' of 'qlearning' must be a number, got 'abc'",
    ),
    "qlearning gamma=2": (
        ["--algo", "qlearning", "--env", "follow-line", "--obs", "line", "-H", "gamma=2"],
        {},
        "0 <= gamma <= 1",
    ),
    "lidar beams=abc": (
        ["--algo", "ppo", "--obs", "lidar:beams=abc"],
        {},
        "'beams' of 'lidar' must be an integer, got 'abc'",
    ),
    "ppo_own entropy_coef=-1": (
        ["--algo", "ppo_own", "--action", "continuous", "--obs", "kinematics", "-H", "entropy_coef=-1"],
        {},
        "'ppo_own' needs entropy_coef, value_coef, critic_warmup_steps and prior_kl_coef >= 0",
    ),
    "ppo_own prior_kl_coef=-1": (
        ["--algo", "ppo_own", "--action", "continuous", "--obs", "kinematics", "-H", "prior_kl_coef=-1"],
        {},
        "'ppo_own' needs entropy_coef, value_coef, critic_warmup_steps and prior_kl_coef >= 0",
    ),
    "a2c_own critic_warmup_steps=-5": (
        ["--algo", "a2c_own", "--action", "meta", "--obs", "kinematics", "-H", "critic_warmup_steps=-5"],
        {},
        "'a2c_own' needs entropy_coef, value_coef, critic_warmup_steps and prior_kl_coef >= 0",
    ),
    "dqn init_from": (
        ["--algo", "dqn", "--obs", "kinematics", "--init-from", "merge-dqn"],
        {},
        "init_from starts ppo_own or a2c_own runs, not 'dqn'",
    ),
    "ppo_own target_kl=-1": (
        ["--algo", "ppo_own", "--action", "meta", "--obs", "kinematics", "-H", "target_kl=-1"],
        {},
        "'ppo_own' needs clip_range > 0, clip_range_value >= 0 and target_kl >= 0",
    ),
    "a2c_own distribution=beta on meta": (
        ["--algo", "a2c_own", "--action", "meta", "--obs", "kinematics", "-H", "distribution=beta"],
        {},
        "'a2c_own': discrete actions take the categorical distribution, not 'beta'",
    ),
    "ppo_own beta_action=median": (
        ["--algo", "ppo_own", "--action", "continuous", "--obs", "kinematics", "-H", "beta_action=median"],
        {},
        "'ppo_own' beta_action must be one of mode, mean, got 'median'",
    ),
    "ppo_own attention_output without attention": (
        ["--algo", "ppo_own", "--action", "meta", "--obs", "kinematics", "-H", "attention_output=64,64"],
        {},
        "'ppo_own' attention_output needs encoder=attention",
    ),
    "ppo_own attention_output=0": (
        [
            "--algo",
            "ppo_own",
            "--obs",
            "kinematics:flatten=false",
            "-H",
            "encoder=attention",
            "-H",
            "attention_output=64,0",
        ],
        {},
        "'ppo_own' attention_output must be layer widths between 1 and 65536 separated by commas "
        "(e.g. 256,256), got '64,0'",
    ),
    "ppo_own encoder=transformer": (
        ["--algo", "ppo_own", "--action", "meta", "--obs", "kinematics", "-H", "encoder=transformer"],
        {},
        "'ppo_own' encoder must be one of auto, attention, got 'transformer'",
    ),
    "ppo_own attention on flat kinematics": (
        ["--algo", "ppo_own", "--action", "meta", "--obs", "kinematics", "-H", "encoder=attention"],
        {},
        "encoder attention needs the vehicles as rows: kinematics with flatten=false",
    ),
    "ppo_own net_arch=0": (
        ["--algo", "ppo_own", "--action", "meta", "--obs", "kinematics", "-H", "net_arch=0,64"],
        {},
        "'ppo_own' net_arch must be layer widths between 1 and 65536",
    ),
    "sac ent_coef=fast": (
        ["--algo", "sac", "--action", "continuous", "-H", "ent_coef=fast"],
        {},
        "'ent_coef' of 'sac'",
    ),
    "dqn tensorboard_log": (["--algo", "dqn", "-H", "tensorboard_log=tb"], {}, "cannot be set with -H"),
    "device=tpu": (
        ["--algo", "ppo", "-H", "device=tpu"],
        {},
        "'device' of 'ppo' must be one of cpu, cuda, auto",
    ),
    # fake results before
    "duration_s -5": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\nenv_options: {duration_s: -5}\n"},
        "duration_s must be",
    ),
    "ppo batch_size=0": (
        ["--algo", "ppo", "-H", "batch_size=0"],
        {},
        "'batch_size' of 'ppo' must be an integer >= 1, got 0",
    ),
    "dqn batch_size=0": (
        ["--algo", "dqn", "-H", "batch_size=0"],
        {},
        "'batch_size' of 'dqn' must be an integer >= 1",
    ),
    "dqn gamma=nan": (
        ["--algo", "dqn", "-H", "gamma=.nan"],
        {},
        "'gamma' of 'dqn' must be a number in [0, 1]",
    ),
    "dueling_ddqn gamma=nan": (
        ["--algo", "dueling_ddqn", "-H", "gamma=.nan"],
        {},
        "'gamma' of 'dueling_ddqn' must be a number, got nan",
    ),
    "topdown stack=0": (
        ["--algo", "ppo", "--obs", "topdown:stack=0"],
        {},
        "'stack' of 'topdown' must be >= 1, got 0",
    ),
    "topdown stack=-2": (
        ["--algo", "ppo", "--obs", "topdown:stack=-2"],
        {},
        "'stack' of 'topdown' must be >= 1, got -2",
    ),
    "bc on highway": (
        ["--algo", "bc", "--env", "highway", "--obs", "kinematics", "--action", "target_speed"],
        {},
        "bc: the rule-based expert drives only in the town, racetrack and blocks scenarios",
    ),
    "bc meta actions": (
        ["--algo", "bc", "--env", "town", "--action", "meta"],
        {},
        "algorithm 'bc' cannot take 'meta' actions",
    ),
    "bc loss=huber": (
        [
            "--algo",
            "bc",
            "--env",
            "town",
            "--obs",
            "waypoints",
            "--action",
            "target_speed",
            "-H",
            "loss=huber",
        ],
        {},
        "'bc' loss must be one of mse, nll, got 'huber'",
    ),
    "bc validation_fraction=1": (
        [
            "--algo",
            "bc",
            "--env",
            "town",
            "--obs",
            "waypoints",
            "--action",
            "target_speed",
            "-H",
            "validation_fraction=1",
        ],
        {},
        "'bc' needs 0 <= validation_fraction < 1",
    ),
    "bc birdeye": (
        ["--algo", "bc", "--env", "town", "--obs", "birdeye", "--action", "target_speed"],
        {},
        "algorithm 'bc' cannot read the observation Box(0, 255, (128, 128, 3), uint8); it reads vectors "
        "(--obs kinematics, lidar, ego_state, waypoints,measurements, ...), one channels-first image (--obs "
        "topdown) or one channels-first image with vectors (--obs topdown,measurements)",
    ),
    "dagger beta_decay=1.5": (
        [
            "--algo",
            "dagger",
            "--env",
            "town",
            "--obs",
            "waypoints",
            "--action",
            "target_speed",
            "-H",
            "beta_decay=1.5",
        ],
        {},
        "'dagger' needs 0 <= beta_decay <= 1, got 1.5",
    ),
    "dagger round_steps=0": (
        [
            "--algo",
            "dagger",
            "--env",
            "town",
            "--obs",
            "waypoints",
            "--action",
            "target_speed",
            "-H",
            "round_steps=0",
        ],
        {},
        "'dagger' needs batch_size, epochs and round_steps >= 1",
    ),
    "expert on highway": (
        EXPERT_ON_HIGHWAY,
        {},
        "expert: the rule-based expert drives only in the town, racetrack and blocks scenarios",
    ),
    "expert on highway in 2 worlds": (
        [*EXPERT_ON_HIGHWAY, "--n-envs", "2"],
        {},
        "expert: the rule-based expert drives only in the town, racetrack and blocks scenarios",
    ),
    "expert's speed unlike the action's": (
        [*EXPERT_ON_HIGHWAY[:2], "--env", "racetrack", *EXPERT_ON_HIGHWAY[4:], "-H", "max_speed_mps=9"],
        {},
        "the target_speed action's max_speed_mps is 6 but the expert's is 9",
    ),
    "bc with a still expert": (
        "--algo bc --env racetrack --obs lidar --action target_speed -H expert_cruise_speed_mps=0".split(),
        {},
        "'bc' needs a positive expert_cruise_speed_mps and expert_lateral_accel_mps2",
    ),
    "eval-every above steps": (
        ["--algo", "ppo", "--eval-every", "21"],
        {},
        "config field 'eval_every' (21) is larger than 'steps' (20): no periodic evaluation would run; "
        "give at most 20, or 0 for five over the run",
    ),
    "config file's eval_every above steps": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\neval_every: 1000\n"},
        "config field 'eval_every' (1000) is larger than 'steps' (20)",
    ),
    "config file's hyperparams a list, with -H": (
        ["--config", "h.yaml", "-H", "gamma=0.9"],
        {"h.yaml": b"algo: ppo\nhyperparams: [gamma]\n"},
        "config field 'hyperparams' must be a mapping, got list",
    ),
    # issue 47: resource exhaustion and tracebacks before
    "YAML aliases expanding to 10^9 values": (
        ["--config", "run.yaml"],
        {"run.yaml": ALIAS_BOMB},
        "malformed YAML in 'run.yaml' at line 6: holds more than 100000 values once its aliases are expanded",
    ),
    "YAML nested 20,000 deep": (
        ["--config", "run.yaml"],
        {"run.yaml": DEEP_YAML},
        "at line 2: nested more than 64 levels deep",
    ),
    "YAML alias inside its own anchor": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\nobs: &loop [kinematics, *loop]\n"},
        "alias *loop is inside the node it names (a recursive structure)",
    ),
    "YAML of int and str unknown keys": (  # sorting the unknown keys raised TypeError
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\n1: one\nbogus: two\n"},
        "at line 2: key '1' is not a string (quote it)",
    ),
    "YAML file over 1 MiB": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\n" + b"#" * (1 << 20) + b"\n"},
        "config file 'run.yaml' is larger than 1 MiB",
    ),
    # issue 47: nonsense accepted, results written before
    "ppo rollout of 64 worlds above the steps": (
        ["--algo", "ppo", "--n-envs", "64"],
        {},
        "config field 'steps' (20) is fewer than 'ppo' trains at once, one rollout of n_steps 256 x "
        "n_envs 64 = 16384 steps: give steps >= 16384, or fewer worlds (n_envs) or a shorter rollout "
        "(n_steps)",
    ),
    "a2c_own rollout above the steps": (
        ["--algo", "a2c_own", "--action", "continuous", "-H", "n_steps=32"],
        {},
        "'steps' (20) is fewer than 'a2c_own' trains at once, one rollout of n_steps 32 x n_envs 1 = 32",
    ),
    "lidar range_m=1e-300": (
        ["--algo", "ppo", "--obs", "lidar:range_m=1e-300"],
        {},
        "sensor option 'range_m' of 'lidar' must lie in [1, 1000], got 1e-300",
    ),
    "lidar noise_std=1e300": (
        ["--algo", "ppo", "--obs", "lidar:noise_std=1e300"],
        {},
        "sensor option 'noise_std' of 'lidar' must lie in [0, 1], got 1e+300",
    ),
    "topdown pixels_per_meter=1e-9": (
        ["--algo", "ppo", "--obs", "topdown:pixels_per_meter=1e-9"],
        {},
        "sensor option 'pixels_per_meter' of 'topdown' must lie in [0.05, 100]",
    ),
    "eval-maps of 10^14 maps": (
        ["--algo", "ppo", "--env", "blocks", "--eval-maps", "0:100000000000000"],
        {},
        "eval_maps '0:100000000000000' names map seeds up to 99999999999999: map seeds, as run seeds, are at "
        "most 2147483647",
    ),
    "n-envs 100000": (
        ["--algo", "ppo", "--n-envs", "100000"],
        {},
        "config field 'n_envs' must be at most 65,536, got 100,000",
    ),
    "name with a right-to-left override": (
        ["--algo", "ppo", "--name", "run\u202egpj.exe"],
        {},
        "not U+202E (RIGHT-TO-LEFT OVERRIDE): a control, format (bidirectional, zero-width)",
    ),
    "name with a zero-width space": (
        ["--algo", "ppo", "--name", "ppo\u200b-s0"],
        {},
        "must hold only visible characters, not U+200B (ZERO WIDTH SPACE)",
    ),
    "name with a line separator": (
        ["--algo", "ppo", "--name", "a\u2028b"],
        {},
        "not U+2028 (LINE SEPARATOR)",
    ),
}


@pytest.mark.parametrize("case", list(TRAIN_CASES))
def test_train_refuses(work, case):
    args, files, message = TRAIN_CASES[case]
    for name, content in files.items():
        (work / name).write_bytes(content)
    assert_refused(work, train_args(work, *args), message)
    assert not (work / "runs").exists()


# (the whole `drivelab train` command after `train`, files, expected part of the message): the step
# budget, which train_args fixes at 20
STEPS_CASES = {
    "--steps 100 --n-envs 64 (16,384 steps trained before)": (
        ["--algo", "ppo", "--steps", "100", "--n-envs", "64"],
        {},
        "config field 'steps' (100) is fewer than 'ppo' trains at once, one rollout of n_steps 256 x "
        "n_envs 64 = 16384 steps",
    ),
    "--steps 10^23": (
        ["--algo", "ppo", "--steps", str(10**23)],
        {},
        "config field 'steps' must be at most 1,000,000,000,000, got 100,000,000,000,000,000,000,000",
    ),
    "YAML steps: .inf": (
        ["--config", "run.yaml"],
        {"run.yaml": b"algo: ppo\nsteps: .inf\n"},
        "'steps' must be an integer",
    ),
    "--n-envs 100000 with steps for its rollout": (
        ["--algo", "ppo", "--n-envs", "100000", "--steps", str(256 * 100_000)],
        {},
        "config field 'n_envs' must be at most 65,536",
    ),
}


@pytest.mark.parametrize("case", list(STEPS_CASES))
def test_train_refuses_step_budgets(work, case):
    args, files, message = STEPS_CASES[case]
    for name, content in files.items():
        (work / name).write_bytes(content)
    assert_refused(work, ["train", *args, "--runs-dir", str(work / "runs")], message)
    assert not (work / "runs").exists()


def test_build_config_names_unknown_keys_of_any_type():
    """The Python API's dict may mix int and str keys (sorting them raised TypeError)."""
    from drivelab.config import build_config
    from drivelab.errors import UsageError

    with pytest.raises(UsageError, match="unknown config field 1 "):
        build_config({"algo": "ppo", 1: "one", "bogus": 2})


@pytest.mark.skipif(torch.cuda.is_available(), reason="this machine has CUDA: device=cuda is valid here")
def test_device_cuda_without_gpu(work):
    assert_refused(work, train_args(work, "--algo", "ppo", "-H", "device=cuda"), "torch sees no CUDA GPU")


def test_runs_dir_is_a_file(work):
    (work / "runs").write_text("not a folder")
    assert_refused(
        work, ["train", "--algo", "ppo", "--runs-dir", "runs", "--steps", "20"], "is not a directory"
    )
    (work / "below").write_text("not a folder")
    assert_refused(
        work, ["train", "--algo", "ppo", "--runs-dir", "below/runs", "--steps", "20"], "is not a directory"
    )


@pytest.mark.skipif(
    AS_ROOT, reason="root writes into a chmod 0o555 folder; test_runs_dir_denied covers the logic"
)
def test_runs_dir_read_only(work):
    locked = work / "locked"
    locked.mkdir()
    locked.chmod(0o555)
    try:
        assert_refused(
            work, train_args(work, "--algo", "ppo") + ["--runs-dir", str(locked / "runs")], "permission"
        )
    finally:
        locked.chmod(0o755)


def test_runs_dir_denied(work, monkeypatch):
    """What a read-only ``--runs-dir`` gives, for any user (root included): the permission check
    (``os.access`` answering no), and a mkdir that the file system refuses."""
    real_access = os.access
    monkeypatch.setattr(
        os, "access", lambda path, mode, **kw: False if Path(path) == work else real_access(path, mode)
    )
    assert_refused(
        work, ["train", "--algo", "ppo", "--runs-dir", "runs", "--steps", "20"], "no permission to write"
    )
    monkeypatch.setattr(os, "access", real_access)

    def refuse(self, *args, **kwargs):
        raise PermissionError(13, "Permission denied", str(self))

    monkeypatch.setattr(Path, "mkdir", refuse)
    assert_refused(  # PPO's shipped rollout, 256 steps: the run passes every check but the folder's
        work, ["train", "--algo", "ppo", "--runs-dir", "runs", "--steps", "256"], "Permission denied"
    )


def test_unknown_command_and_missing_argument(work):
    assert_refused(work, ["bogus"], "no such command 'bogus' (see `")
    assert_refused(work, ["evaluate"], "missing argument 'RUN_DIR|NAME'")
    assert_refused(work, ["perception", "train-lane", "--bogus"], "no such option: --bogus")


TINY_SWEEP = """
base: {algo: ppo, env: highway, traffic: empty, steps: 32, hyperparams: {n_steps: 16, batch_size: 16}}
grid: {seed: 1}
eval_episodes: 0
"""


def test_sweep_and_ablate_check_hyperparameters_before_writing(work):
    (work / "sweep.yaml").write_text(
        TINY_SWEEP.replace("batch_size: 16", "batch_size: 16, learning_rate: -1")
    )
    assert_refused(work, ["sweep", "sweep.yaml", "--workers", "1"], "learning_rate")
    ablate = ["ablate", "--algo", "ppo", "--drop-terms", "right_lane", "--seeds", "1", "--steps", "32"]
    assert_refused(work, [*ablate, "-H", "learning_rate=-1"], "learning_rate")


def test_sweep_and_tune_folders_that_cannot_be_created(work):
    (work / "sweep.yaml").write_text(TINY_SWEEP)
    (work / "file").write_text("a file, not a folder")
    args = ["sweep", "sweep.yaml", "--workers", "1", "--runs-dir", "file/runs"]
    assert_refused(work, args, "cannot create runs folder")
    (work / "study.yaml").write_text(TUNE_BASE + GAMMA)
    args = ["tune", "study.yaml", "--workers", "1", "--study-dir", "file/below/study"]
    assert_refused(work, args, "cannot create study folder")
    assert_refused(work, ["sweep", "."], "config file '.' is a folder, not a YAML file")


def test_sweep_cells_with_eval_every_above_their_steps_are_refused(work):
    """Every cell is checked, also one whose config differs from a checked one only in ``steps``
    (the agent check runs once per config but for name, seed and steps); ``--dry-run`` too."""
    text = TINY_SWEEP.replace("steps: 32,", "eval_every: 32,")
    (work / "sweep.yaml").write_text(text.replace("grid: {seed: 1}", "grid: {steps: [32, 16]}"))
    message = "config field 'eval_every' (32) is larger than 'steps' (16)"
    assert_refused(work, ["sweep", "sweep.yaml", "--workers", "1"], message)
    assert_refused(work, ["sweep", "sweep.yaml", "--dry-run"], message)


def test_sweep_file_errors_of_issue_47(work):
    (work / "sweep.yaml").write_text(TINY_SWEEP + "runs_dir: 123\n")
    assert_refused(
        work, ["sweep", "sweep.yaml", "--dry-run"], "sweep 'runs_dir' must be a folder path, got 123"
    )
    (work / "sweep.yaml").write_text(TINY_SWEEP + "1: one\nbogus: two\n")
    assert_refused(work, ["sweep", "sweep.yaml", "--dry-run"], "key '1' is not a string")


def test_a_ray_head_that_requires_a_token_is_one_error_line(work, monkeypatch):
    """Ray's AuthenticationError (RAY_AUTH_MODE=token without a token) at ``ray.init``: one line,
    and whatever the failed start left is shut down."""
    ray = pytest.importorskip("ray")
    from ray.exceptions import AuthenticationError

    def refuse(*args, **kwargs):
        raise AuthenticationError(
            "Token authentication is enabled but no token was found.\nSet RAY_AUTH_TOKEN"
        )

    shutdowns = []
    monkeypatch.setattr(ray, "init", refuse)
    monkeypatch.setattr(ray, "shutdown", lambda: shutdowns.append(1))
    (work / "sweep.yaml").write_text(TINY_SWEEP)
    assert_refused(
        work,
        ["sweep", "sweep.yaml", "--executor", "ray", "--workers", "1"],
        "cannot start a local Ray cluster: Token authentication is enabled but no token was found.",
    )
    assert shutdowns


def test_ablate_refuses_zero_evaluation_episodes(work):
    ablate = ["ablate", "--algo", "ppo", "--drop-terms", "right_lane", "--seeds", "1", "--steps", "32"]
    assert_refused(
        work, [*ablate, "--eval-episodes", "0"], "--eval-episodes must be >= 1 (the report compares"
    )


def test_zero_workers(work):
    (work / "sweep.yaml").write_text(TINY_SWEEP)
    assert_refused(work, ["sweep", "sweep.yaml", "--workers", "0"], "--workers must be >= 1, got 0")


def test_maps_output_must_be_a_writable_png(work):
    maps = ["maps", "--map", "3", "--seeds", "0:1"]
    assert_refused(work, [*maps, "-o", "gallery"], "--out 'gallery' must name a .png file")
    (work / "folder.png").mkdir()
    assert_refused(work, [*maps, "-o", "folder.png"], "--out 'folder.png' must name a .png file")
    (work / "file").write_text("a file, not a folder")
    assert_refused(work, [*maps, "-o", "file/gallery.png"], "cannot write 'file/gallery.png'")
    assert_refused(work, [*maps, "-o", "file/new/gallery.png"], "cannot write")  # mkdir refused


# --- evaluate and compare: one tiny run, copied into each test ---------------------------------
@pytest.fixture(scope="module")
def trained(tmp_path_factory) -> Path:
    """A 20-step DQN run (no gradient step: learning starts at 200) with one evaluation."""
    runs = tmp_path_factory.mktemp("trained")
    args = ["train", "--algo", "dqn", "--traffic", "empty", "--steps", "20", "--eval-every", "20",
            "--eval-episodes", "1", "--runs-dir", str(runs), "--name", "tiny"]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    return runs / "tiny"


@pytest.fixture
def run_dir(work, trained) -> Path:
    return Path(shutil.copytree(trained, work / "tiny"))


def test_resume_takes_only_steps(work, run_dir):
    for option in (["--eval-every", "7"], ["--eval-episodes", "2"], ["--checkpoint-every", "5"], ["--video"]):
        args = ["train", "--resume", str(run_dir), "--steps", "40", *option]
        assert_refused(work, args, "only --steps may be given with it")


def test_evaluate_after_obs_edited(work, run_dir):
    config = run_dir / "config.yaml"
    config.write_text(config.read_text().replace("- kinematics", "- lidar"))
    assert_refused(
        work,
        ["evaluate", str(run_dir), "--episodes", "1"],
        "but its environment gives Box(0.0, 1.0, (240,), float32) and Discrete(5) (was config.yaml edited",
    )


def test_evaluate_where_eval_json_cannot_be_written(work, run_dir, monkeypatch):
    """The check comes before any episode: run_episodes must not be reached."""
    import drivelab.training.evaluate as evaluate

    monkeypatch.setattr(evaluate, "run_episodes", lambda *a, **k: pytest.fail("episodes ran"))
    (run_dir / "eval.json").mkdir()
    assert_refused(work, ["evaluate", str(run_dir), "--episodes", "1"], "cannot write eval.json")


def test_evaluate_read_only_run_directory(work, run_dir, monkeypatch):
    """chmod 0o555 where it binds; as root (which writes through it) the same refusal of the
    file system is simulated, as a read-only mount gives it."""
    import tempfile

    import drivelab.training.evaluate as evaluate

    monkeypatch.setattr(evaluate, "run_episodes", lambda *a, **k: pytest.fail("episodes ran"))
    if AS_ROOT:

        def refuse(*args, **kwargs):
            raise OSError(30, "Read-only file system")

        monkeypatch.setattr(tempfile, "TemporaryFile", refuse)
    run_dir.chmod(0o555)
    try:
        assert_refused(work, ["evaluate", str(run_dir), "--episodes", "1"], "cannot write eval.json")
    finally:
        run_dir.chmod(0o755)


def _with_member(path: Path, member: str, data: bytes) -> None:
    """Rewrite the zip ``path`` with ``member`` replaced by ``data`` (deflated)."""
    import zipfile

    with zipfile.ZipFile(path) as archive:
        members = {name: archive.read(name) for name in archive.namelist()}
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as archive:
        for name, value in {**members, member: data}.items():
            archive.writestr(name, value)


@pytest.mark.parametrize(
    ("member", "data"),
    [("parameters.pt", b"\0" * (64 << 20)), ("sb3.json", b" " * (17 << 20))],
    ids=["parameters.pt", "sb3.json"],
)
def test_evaluate_refuses_a_model_member_that_inflates_past_what_the_model_takes(work, run_dir, member, data):
    """A zip bomb (the probe's: 3.1 MB inflating to 3 GiB, 4.6 GB resident before a MemoryError),
    here 64 KiB inflating to 64 MiB: refused from the member's declared size, before it is read.
    The tensor file's bound is the model's own (its fresh weights, four times, plus a MiB)."""
    _with_member(run_dir / "model.zip", member, data)
    assert (run_dir / "model.zip").stat().st_size < 1 << 20
    assert_refused(
        work, ["evaluate", str(run_dir), "--episodes", "1"], f"{member} declares {len(data)} bytes, more"
    )


def test_a_model_member_whose_header_lies_is_read_no_further(work, run_dir):
    """The same member with its declared size patched to 1000 bytes: the reader stops there, and
    the truncated member fails its checksum."""
    import struct
    import zipfile

    path = run_dir / "model.zip"
    _with_member(path, "parameters.pt", b"\0" * (64 << 20))
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as archive:
        info = archive.getinfo("parameters.pt")
    data[info.header_offset + 22 : info.header_offset + 26] = struct.pack("<I", 1000)  # local header
    central = data.index(b"PK\x01\x02")  # the central directory's entries, until this member's
    while not data[central + 46 :].startswith(b"parameters.pt"):
        central = data.index(b"PK\x01\x02", central + 4)
    data[central + 24 : central + 28] = struct.pack("<I", 1000)  # central directory
    path.write_bytes(bytes(data))
    assert_refused(work, ["evaluate", str(run_dir), "--episodes", "1"], "Bad CRC-32 for file 'parameters.pt'")


@pytest.mark.parametrize(
    "content",
    [RANDOM_BYTES, b"step,mean_return\n20,abc\n", b"hello\nworld\n", b"step,mean_return\n20\n"],
    ids=["binary", "text-number", "no-header", "short-row"],
)
def test_compare_garbage_evaluations(work, run_dir, content):
    (run_dir / "evaluations.csv").write_bytes(content)
    assert_refused(work, ["compare", str(run_dir), "-o", str(work / "report")], "is not an evaluations.csv")


def test_compare_garbage_eval_json(work, run_dir):
    (run_dir / "eval.json").write_text('{"mean_return": "fast"}')
    assert_refused(
        work, ["compare", str(run_dir), "-o", "report"], "metric 'mean_return' is not a number: 'fast'"
    )
    (run_dir / "eval.json").write_text("[1, 2]")
    assert_refused(work, ["compare", str(run_dir), "-o", "report"], "is not an eval.json")


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ('{"mean_return": NaN}', "metric 'mean_return' is not a finite number: nan"),
        ('{"mean_return": 1.0, "crash_rate": Infinity}', "metric 'crash_rate' is not a finite number: inf"),
        (
            '{"mean_return": 1.0, "success_rate": 1.5}',
            "metric 'success_rate' is a rate, which lies in [0, 1], not 1.5",
        ),
        ('{"mean_return": 1.0, "route_completion": -0.25}', "metric 'route_completion' is a rate"),
        ('{"mean_return": 1.0, "mean_length": -3}', "metric 'mean_length' cannot be negative: -3"),
    ],
)
def test_compare_refuses_impossible_eval_json_values(work, run_dir, text, message):
    (run_dir / "eval.json").write_text(text)
    assert_refused(
        work, ["compare", str(run_dir), "-o", "report"], f"{str(run_dir / 'eval.json')!r}: {message}"
    )


@pytest.mark.parametrize("value", ["inf", "-inf", "nan"])
def test_compare_refuses_a_non_finite_evaluation_return(work, run_dir, value):
    path = run_dir / "evaluations.csv"
    header, row = path.read_text().splitlines()[:2]
    columns = header.split(",")
    cells = row.split(",")
    cells[columns.index("mean_return")] = value
    path.write_text(f"{header}\n{','.join(cells)}\n")
    assert_refused(
        work,
        ["compare", str(run_dir), "-o", "report"],
        "(row 1): 'mean_return' is not a finite number of an evaluation",
    )


@pytest.mark.parametrize(
    ("old", "new", "field"), [("algo: dqn", "algo: bogus", "algo"), ("env: highway", "env: moon", "env")]
)
def test_compare_refuses_a_config_of_unknown_names(work, run_dir, old, new, field):
    config = run_dir / "config.yaml"
    config.write_text(config.read_text().replace(old, new))
    what = "algorithm" if field == "algo" else "scenario"
    message = f"{str(config)!r}: field {field!r} names no drivelab {what}"
    assert_refused(work, ["compare", str(run_dir), "-o", "report"], message)


def test_compare_into_a_folder_that_is_not_a_report(work, run_dir):
    """``-o .`` (the working folder holds the run) and a folder of someone's files: refused."""
    assert_refused(work, ["compare", str(run_dir), "-o", "."], "is not empty and holds no drivelab report")
    notes = work / "notes"
    notes.mkdir()
    (notes / "thesis.tex").write_text("mine")
    assert_refused(work, ["compare", str(run_dir), "-o", str(notes)], "holds no drivelab report")
    (work / "file").write_text("x")
    assert_refused(work, ["compare", str(run_dir), "-o", "file"], "is a file, not a directory")


def test_compare_rewrites_only_its_own_files(work, run_dir):
    """A report folder that also holds the user's files: a new report replaces the files the
    manifest lists, and leaves the others (even beside a pre-manifest report.md)."""
    out = work / "report"
    out.mkdir()
    (out / "report.md").write_text("an old report, from before the manifest")
    (out / "mine.txt").write_text("keep me")
    assert runner.invoke(app, ["compare", str(run_dir), "-o", str(out)]).exit_code == 0
    assert (out / "mine.txt").read_text() == "keep me"
    assert (out / "report.md").read_text().startswith("# drivelab comparison")
    import json

    listed = json.loads((out / "report-manifest.json").read_text())["files"]
    assert set(listed) == {p.name for p in out.iterdir()} - {"mine.txt", "report-manifest.json"}
    (out / "summary.csv").unlink()  # the user removed one; a second report writes it again
    assert runner.invoke(app, ["compare", str(run_dir), "-o", str(out)]).exit_code == 0
    assert sorted(p.name for p in out.iterdir()) == sorted([*listed, "mine.txt", "report-manifest.json"])
    assert not [p for p in out.iterdir() if p.name.startswith(".")]  # no temporary folder left


# --- the declared SB3 hyper-parameters -----------------------------------------------------------
def test_sb3_table_matches_installed_sb3():
    """Every declared key is a keyword of the installed SB3 constructor (a renamed one would be
    silently unsettable), and the shipped per-scenario values all pass the checks."""
    import inspect

    import yaml

    from drivelab.agents.registry import agent_classes
    from drivelab.agents.sb3_params import PARAMS, check_sb3_hyperparams
    from drivelab.hyperparams import shipped_hyperparams

    classes = agent_classes("sb3")
    assert set(PARAMS) == set(classes)
    for algo, params in PARAMS.items():
        accepted = inspect.signature(classes[algo].__init__).parameters
        assert set(params) <= set(accepted), algo
        shipped = Path(__file__).parents[1] / "drivelab" / "hyperparams" / f"{algo}.yaml"
        for scenario in yaml.safe_load(shipped.read_text()):
            values = shipped_hyperparams(algo, scenario)
            assert check_sb3_hyperparams(algo, values) == values


def test_sb3_values_are_coerced_and_special_forms_accepted():
    from drivelab.agents.sb3_params import check_sb3_hyperparams

    checked = check_sb3_hyperparams("dqn", {"batch_size": 32.0, "gamma": 1, "train_freq": [4, "episode"]})
    assert checked == {"batch_size": 32, "gamma": 1.0, "train_freq": (4, "episode")}
    assert type(checked["batch_size"]) is int and type(checked["gamma"]) is float
    sac = {"ent_coef": "auto_0.1", "target_entropy": "auto", "device": "auto"}
    assert check_sb3_hyperparams("sac", sac) == sac
    assert check_sb3_hyperparams("ppo", {"target_kl": None, "clip_range_vf": None}) == {
        "target_kl": None,
        "clip_range_vf": None,
    }


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a CUDA GPU")
def test_device_cuda_trains_sb3_on_the_gpu():
    from drivelab.agents.sb3 import build_sb3
    from drivelab.envs.core import DriveEnv

    model = build_sb3(
        "ppo", DriveEnv(traffic="empty"), 0, {"device": "cuda", "n_steps": 16, "batch_size": 8}, None
    )
    assert model.device.type == "cuda"
    model.learn(16)
    assert model.num_timesteps == 16


# --- drivelab tune: the study file ------------------------------------------------------------------
TUNE_BASE = (
    "algo: ppo\nenv: highway\ntraffic: empty\nbackend: fast\nsteps: 64\nn_trials: 3\n"
    "hyperparams: {n_steps: 16, batch_size: 16}\n"
)
GAMMA = "space: {gamma: {type: float, low: 0.8, high: 0.99}}\n"
# (study file text, extra options, expected part of the message)
TUNE_CASES = {
    "unknown param type": (
        TUNE_BASE + "space: {gamma: {type: uniform, low: 0.8, high: 0.99}}\n",
        [],
        "tune space 'gamma' has unknown type 'uniform' (choose from float, int, log, categorical)",
    ),
    "empty space": (TUNE_BASE + "space: {}\n", [], "needs a non-empty 'space'"),
    "no space": (TUNE_BASE, [], "needs a non-empty 'space'"),
    "n_trials 0": (
        TUNE_BASE.replace("n_trials: 3", "n_trials: 0") + GAMMA,
        [],
        "'n_trials' must be an integer >= 1, got 0",
    ),
    "--n-trials -2": (TUNE_BASE + GAMMA, ["--n-trials", "-2"], "'n_trials' must be an integer >= 1, got -2"),
    "unknown algo": (TUNE_BASE.replace("algo: ppo", "algo: bogus") + GAMMA, [], "unknown algorithm 'bogus'"),
    "unknown metric": (TUNE_BASE + GAMMA + "metric: fun\n", [], "unknown tune metric 'fun'"),
    "unknown key": (TUNE_BASE + GAMMA + "trials: 4\n", [], "unknown tune key 'trials'"),
    "no steps": (TUNE_BASE.replace("steps: 64\n", "") + GAMMA, [], "needs 'steps', the training budget"),
    "low above high": (
        TUNE_BASE + "space: {gamma: {type: float, low: 0.99, high: 0.8}}\n",
        [],
        "needs low < high",
    ),
    "log from 0": (
        TUNE_BASE + "space: {learning_rate: {type: log, low: 0, high: 0.1}}\n",
        [],
        "low must be > 0, got 0",
    ),
    "no choices": (
        TUNE_BASE + "space: {batch_size: {type: categorical, choices: []}}\n",
        [],
        "needs 'choices'",
    ),
    "not a hyper-parameter": (
        TUNE_BASE + "space: {bogus: {type: int, low: 1, high: 4}}\n",
        [],
        "unknown hyperparameter 'bogus' for 'ppo'",
    ),
    "value out of range": (
        TUNE_BASE + "space: {gamma: {type: float, low: 0.9, high: 2}}\n",
        [],
        "'gamma' of 'ppo' must be a number in [0, 1]",
    ),
    "bad choice": (
        TUNE_BASE + "space: {batch_size: {type: categorical, choices: [16, 0]}}\n",
        [],
        "'batch_size' of 'ppo' must be an integer >= 1, got 0",
    ),
    "bad fixed value": (
        TUNE_BASE.replace("batch_size: 16", "batch_size: -1") + GAMMA,
        [],
        "'batch_size' of 'ppo'",
    ),
    "eval_every above steps": (
        TUNE_BASE + GAMMA + "eval_every: 128\n",
        [],
        "config field 'eval_every' (128) is larger than 'steps' (64)",
    ),
    "n_envs for a one-world algorithm": (
        "algo: rlad\naction: continuous\nn_envs: 2\nenv: highway\nbackend: fast\nsteps: 64\nn_trials: 3\n"
        "space: {learning_rate: {type: log, low: 0.0001, high: 0.01}}\n",
        [],
        "algorithm 'rlad' trains in one world: n_envs must be 1 (got 2)",
    ),
    "bad executor": (TUNE_BASE + GAMMA, ["--executor", "slurm"], "unknown executor 'slurm'"),
    "write-best not YAML": (
        TUNE_BASE + GAMMA,
        ["--write-best", "notes.txt"],
        "is not a YAML hyper-parameter file",
    ),
    "write-best /dev/null": (TUNE_BASE + GAMMA, ["--write-best", "/dev/null"], "is not a regular file"),
    "write-best of aliases expanding to 10^9 values": (
        TUNE_BASE + GAMMA,
        ["--write-best", "bomb.yml"],
        "--write-best 'bomb.yml' is not a YAML hyper-parameter file",
    ),
    "n_steps searched above the steps": (
        TUNE_BASE + "space: {n_steps: {type: int, low: 16, high: 128}}\n",
        [],
        "config field 'steps' (64) is fewer than 'ppo' trains at once, one rollout of n_steps 128 x n_envs 1",
    ),
}


@pytest.mark.parametrize("case", list(TUNE_CASES))
def test_tune_refuses(work, case):
    text, options, message = TUNE_CASES[case]
    (work / "study.yaml").write_text(text)
    (work / "notes.txt").write_text("a: [b\n")
    (work / "bomb.yml").write_bytes(ALIAS_BOMB)
    assert_refused(work, ["tune", "study.yaml", "--study-dir", "study", "--workers", "1", *options], message)
    assert not (work / "study").exists()


def test_tune_refuses_a_folder_of_another_study(work):
    (work / "study.yaml").write_text(TUNE_BASE + GAMMA)
    other = work / "study"
    other.mkdir()
    (other / "study.yaml").write_text("algo: dqn\n")
    assert_refused(work, ["tune", "study.yaml", "--study-dir", "study"], "holds another study")
    (other / "study.yaml").unlink()
    (other / "thesis.tex").write_text("mine")
    assert_refused(work, ["tune", "study.yaml", "--study-dir", "study"], "holds no drivelab study")
