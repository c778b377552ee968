"""RLAD: SAC from pixels with A-LIX, DrQ augmentation, WayConv1D and the traffic-light
auxiliary loss; and the DrQ baseline as a preset of it.

Observation: ``--obs camera:stack=3,waypoints,measurements:stack=3`` (the paper's K = 3 frames
and 3 measurement frames); any camera size from 21 px, any stack. Action: ``target_speed``
([target speed, steer] through the town's PID), each held for two 10 Hz simulation steps by the
environment, as the paper's CARLA runs.
"""

from __future__ import annotations

import functools
import math
import warnings
import weakref
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.callbacks import BaseCallback
from torch import nn

from drivelab.agents.base import MAX_LEARNING_RATE, OwnAgent, gradient_step
from drivelab.agents.buffer_memory import check_buffer_memory, observation_bytes
from drivelab.agents.rlad.augmentation import default_pad, random_shift
from drivelab.agents.rlad.fast import COMPILE_MODES, compile_unavailable, draw_update_noise
from drivelab.agents.rlad.memory import DeviceMemoryLedger, cuda_free_bytes, device_key
from drivelab.agents.rlad.networks import Actor, StateEncoder, TrafficLightHead, TwinCritic
from drivelab.agents.rlad.replay import RECORD_SLACK, UNKNOWN_LABEL, FrameReplayBuffer, label_index
from drivelab.agents.rlad.waypoints import WAYPOINT_ENCODERS
from drivelab.agents.worlds import Worlds, row
from drivelab.errors import UsageError

OBSERVATION_KEYS = ("camera", "waypoints", "measurements")
REPLAY_FRAMES = ("auto", "host", "device")


@dataclass(frozen=True)
class RLADConfig:
    """Hyper-parameters (``-H key=value``), Table II's values by default.

    :param buffer_size: replay capacity (transitions).
    :param batch_size: transitions per update.
    :param learning_starts: warm-up steps of uniformly random actions before the first update.
    :param gamma: discount.
    :param learning_rate: Adam step size of encoder, critics, auxiliary head, actor, temperature.
    :param tau: EMA rate of the target critics.
    :param hidden_size: width of the actor's and critics' two hidden layers.
    :param log_std_min: lower bound of the actor's log σ.
    :param log_std_max: upper bound of the actor's log σ.
    :param init_temperature: initial α (the target entropy is −|A|).
    :param alix: A-LIX after every conv + ReLU (``--no-alix`` turns it off).
    :param alix_init: initial A-LIX strength S.
    :param alix_target: β, the target normalised discontinuity.
    :param alix_learning_rate: Adam step size of S (betas 0.5, 0.999).
    :param aux: the traffic-light auxiliary loss (``--no-aux``).
    :param aux_weight: weight of the auxiliary cross-entropy beside the critic loss.
    :param waypoint_encoder: "wayconv1d" or "mlp" (``--waypoint-encoder``).
    :param augment: DrQ random shift of obs and next_obs at every update (``--no-augment``).
    :param augment_pad: shift in pixels; 0 picks 4 below 192 px (DrQ at 84), 8 above (RLAD at 256).
    :param train_freq: environment steps between updates.
    :param log_interval: environment steps between logger dumps.
    :param device: "auto" (CUDA when available, else CPU), "cpu", "cuda" or "cuda:N".
    :param replay_frames: where the replay keeps its frames: "host", "device" or "auto" (the
        device when it is a GPU with room for them in half its free memory, ``memory.py``).
    :param fast_update: the update without host round trips (``fast.py``: the same update to
        float32 rounding).
    :param compile: with ``fast_update``, ``torch.compile`` mode of its pure-tensor parts: "none",
        "default", "reduce-overhead" (CUDA graphs on a GPU) or "max-autotune".
    :param bf16: with ``fast_update``, bfloat16 autocast of the forward passes (changes the result
        at ~1e-2 relative; off by default).
    :param channels_last: with ``fast_update``, the image encoder's convolutions in NHWC.
    """

    buffer_size: int = 100_000
    batch_size: int = 256
    learning_starts: int = 1000
    gamma: float = 0.99
    learning_rate: float = 1e-3
    tau: float = 0.01
    hidden_size: int = 1024
    log_std_min: float = -10.0
    log_std_max: float = 2.0
    init_temperature: float = 0.1
    alix: bool = True
    alix_init: float = 0.5
    alix_target: float = 0.535
    alix_learning_rate: float = 2e-3
    aux: bool = True
    aux_weight: float = 1.0
    waypoint_encoder: str = "wayconv1d"
    augment: bool = True
    augment_pad: int = 0
    train_freq: int = 1
    log_interval: int = 500
    device: str = "auto"
    replay_frames: str = "auto"
    fast_update: bool = False
    compile: str = "none"
    bf16: bool = False
    channels_last: bool = False

    def check(self, algo: str) -> None:
        if min(self.buffer_size, self.train_freq, self.log_interval) < 1 or self.batch_size < 2:
            raise UsageError(f"{algo!r} needs buffer_size, train_freq, log_interval >= 1 and batch_size >= 2")
        if self.learning_starts < 0 or self.augment_pad < 0 or self.hidden_size < 1:
            raise UsageError(f"{algo!r} needs learning_starts >= 0, augment_pad >= 0 and hidden_size >= 1")
        if not 0 < self.gamma <= 1 or not 0 < self.tau <= 1 or not 0 <= self.alix_init <= 1:
            raise UsageError(f"{algo!r} needs 0 < gamma <= 1, 0 < tau <= 1 and 0 <= alix_init <= 1")
        if not all(0 < rate <= MAX_LEARNING_RATE for rate in (self.learning_rate, self.alix_learning_rate)):
            raise UsageError(
                f"{algo!r} needs learning_rate and alix_learning_rate in (0, {MAX_LEARNING_RATE:g}]"
            )
        if self.init_temperature <= 0:
            raise UsageError(f"{algo!r} needs a positive init_temperature")
        if self.log_std_min >= self.log_std_max:
            raise UsageError(f"{algo!r} needs log_std_min < log_std_max")
        if self.aux_weight < 0 or self.alix_target <= 0:
            raise UsageError(f"{algo!r} needs aux_weight >= 0 and alix_target > 0")
        if self.device not in ("auto", "cpu", "cuda") and not self.device.startswith("cuda:"):
            raise UsageError(f"{algo!r}: device must be auto, cpu, cuda or cuda:N, got {self.device!r}")
        for key, allowed in (("replay_frames", REPLAY_FRAMES), ("compile", COMPILE_MODES)):
            value = getattr(self, key)
            if value not in allowed:
                raise UsageError(f"{algo!r}: {key} must be one of {', '.join(allowed)}, got {value!r}")
        if not self.fast_update and (self.compile != "none" or self.bf16 or self.channels_last):
            raise UsageError(f"{algo!r}: compile, bf16 and channels_last need fast_update=true")
        if self.waypoint_encoder not in WAYPOINT_ENCODERS:
            raise UsageError(
                f"{algo!r}: waypoint_encoder must be one of {', '.join(WAYPOINT_ENCODERS)}, "
                f"got {self.waypoint_encoder!r}"
            )


@dataclass(frozen=True)
class DrQConfig(RLADConfig):
    """The DrQ baseline of the paper's comparison: RLAD without A-LIX and the auxiliary loss, with
    an MLP waypoint encoder (SAC, augmentation and the other encoders as RLAD)."""

    alix: bool = False
    aux: bool = False
    waypoint_encoder: str = "mlp"


def observation_error(space: spaces.Space) -> str | None:
    """Why RLAD cannot read ``space`` (None when it can): it needs a Dict of an RGB ``camera``
    (H, W, 3K) uint8, ``waypoints`` (N, 2) and ``measurements`` (M,)."""
    needed = "a camera, waypoints and measurements (--obs camera:stack=3,waypoints,measurements:stack=3)"
    if not isinstance(space, spaces.Dict) or any(key not in space.spaces for key in OBSERVATION_KEYS):
        return f"needs {needed}"
    camera, waypoints, measurements = (space[key] for key in OBSERVATION_KEYS)
    if camera.dtype != np.uint8 or len(camera.shape) != 3 or camera.shape[-1] % 3:
        return f"needs an RGB camera stack (H, W, 3K) uint8, got {camera.shape}"
    if len(waypoints.shape) != 2 or waypoints.shape[1] != 2 or len(measurements.shape) != 1:
        return f"needs waypoints (N, 2) and measurements (M,), got {waypoints.shape} and {measurements.shape}"
    return None


# --- the agent ----------------------------------------------------------------------------------
class RLAD(OwnAgent):
    """SAC from pixels as RLAD; ``config`` switches its parts off for the ablations."""

    config_class = RLADConfig
    # checkpoints keep the replay up to this size (run.py's default is 512 MiB; 84x84 takes 2.2 GB)
    replay_checkpoint_limit_bytes = 16 * 2**30

    def _build(self) -> None:
        error = observation_error(self.observation_space)
        if error is not None:
            raise UsageError(f"{self.algo} {error}")
        if not isinstance(self.action_space, spaces.Box) or len(self.action_space.shape) != 1:
            raise UsageError(f"{self.algo} needs a continuous action space")
        config, space = self.config, self.observation_space
        self._check_memory()
        actions = self.action_space.shape[0]
        automatic = "cuda" if torch.cuda.is_available() else "cpu"
        self.device = torch.device(automatic if config.device == "auto" else config.device)
        self.encoder = StateEncoder(space, config)
        self.encoder.image.generator = self.generator
        self.actor = Actor(
            self.encoder.features, actions, config.hidden_size, config.log_std_min, config.log_std_max
        )
        self.critic = TwinCritic(self.encoder.features, actions, config.hidden_size)
        self.critic_target = TwinCritic(self.encoder.features, actions, config.hidden_size)
        self.critic_target.load_state_dict(self.critic.state_dict())
        self.traffic_light_head = TrafficLightHead()
        for module in (self.encoder, self.actor, self.critic, self.critic_target, self.traffic_light_head):
            module.to(self.device)
        log_alpha = math.log(config.init_temperature)
        self.log_alpha = torch.tensor(log_alpha, device=self.device, requires_grad=True)
        self.target_entropy = -float(actions)
        strength = [self.encoder.image.strength] if config.alix else []
        learned = [p for p in self.encoder.parameters() if all(p is not s for s in strength)]
        learned += [*self.critic.parameters(), *self.traffic_light_head.parameters()]
        groups = [{"params": learned}]
        if strength:  # S: its own Adam group (A-LIX's dual step)
            groups.append({"params": strength, "lr": config.alix_learning_rate, "betas": (0.5, 0.999)})
        fused = {"fused": True} if config.fast_update else {}
        self.critic_optimizer = torch.optim.Adam(groups, lr=config.learning_rate, **fused)
        self.actor_optimizer = torch.optim.Adam(self.actor.parameters(), lr=config.learning_rate, **fused)
        self.alpha_optimizer = torch.optim.Adam([self.log_alpha], lr=config.learning_rate, **fused)
        self._build_fast_update()
        height, width, channels = space["camera"].shape
        self.pad = config.augment_pad or default_pad(min(height, width))
        frame_shape = (3, height, width)
        self._frames_reservation: weakref.finalize | None = None
        self.replay_buffer = FrameReplayBuffer(
            config.buffer_size, frame_shape, channels // 3, space["waypoints"].shape,
            space["measurements"].shape[0], actions, self._frame_device(frame_shape),
        )  # fmt: skip
        self.replay_buffer.on_allocate = self._frames_allocated
        self.low, self.high = self.action_space.low, self.action_space.high
        self.episode_returns: deque[float] = deque(maxlen=100)

    def _check_memory(self) -> None:
        """Refuse a replay (one RGB frame a transition, its records' slack, waypoints, measurements and
        the stack's record numbers) or a batch (both observations as float32) this machine cannot hold."""
        camera, waypoints, measurements = (self.observation_space[key] for key in OBSERVATION_KEYS)
        height, width, channels = camera.shape
        frame = 3 * height * width * (1 + RECORD_SLACK) + 8 * (channels // 3)
        stored = frame + observation_bytes(waypoints) + observation_bytes(measurements)
        check_buffer_memory(self.algo, "buffer_size", self.config.buffer_size, stored, "replay buffer")
        batch = 2 * observation_bytes(self.observation_space, 4)
        check_buffer_memory(self.algo, "batch_size", self.config.batch_size, batch, "training batch")

    def _frame_device(self, frame_shape: tuple[int, ...]) -> torch.device | None:
        """Where the replay keeps its frames (``replay_frames``); None for the host."""
        choice = self.config.replay_frames
        if choice == "device":
            return self.device
        if choice == "host" or self.device.type != "cuda":
            return None
        if self._frames_reservation is not None:  # deciding again (a loaded replay): release the last
            self._frames_reservation()
        records = self.config.buffer_size * (1 + RECORD_SLACK) + 1
        ledger = DeviceMemoryLedger()
        free = functools.partial(cuda_free_bytes, self.device)
        token = ledger.reserve(device_key(self.device), int(records * math.prod(frame_shape)), free)
        if token is None:
            self._frames_reservation = None
            return None
        self._frames_reservation = weakref.finalize(self, ledger.release, token)  # also at exit
        self._frames_claim = (ledger, token)
        return self.device

    def _frames_allocated(self) -> None:
        """The replay allocated its device frames: the ledger counts them as taken, not pending."""
        if self._frames_reservation is not None and self._frames_reservation.alive:
            ledger, token = self._frames_claim
            ledger.allocated(token)

    def _build_fast_update(self) -> None:
        """The fast update's objectives, compiled when ``compile`` asks and inductor can
        (``fast.py``); the encoder in NHWC when ``channels_last``."""
        config = self.config
        self._critic_objective_fn, self._actor_objective_fn = self._critic_objective, self._actor_objective
        if config.channels_last:
            self.encoder.image.convs.to(memory_format=torch.channels_last)
        if config.compile == "none":
            return
        reason = compile_unavailable(self.device)
        if reason is not None:
            warnings.warn(f"{self.algo}: {reason}; the fast update runs without torch.compile", stacklevel=2)
            return
        mode = None if config.compile == "default" else config.compile
        self._critic_objective_fn = torch.compile(self._critic_objective, mode=mode)
        self._actor_objective_fn = torch.compile(self._actor_objective, mode=mode)

    def load_replay_buffer(self, path: str | Path) -> None:
        """A checkpointed replay, its frames placed as this agent's ``replay_frames`` says."""
        super().load_replay_buffer(path)
        self.replay_buffer.on_allocate = self._frames_allocated
        self.replay_buffer.move_frames(self._frame_device(self.replay_buffer.frames.shape[1:]))

    def _modules(self) -> dict[str, nn.Module | torch.optim.Optimizer]:
        networks = ("encoder", "actor", "critic", "critic_target", "traffic_light_head")
        optimizers = ("critic_optimizer", "actor_optimizer", "alpha_optimizer")
        return {name: getattr(self, name) for name in networks + optimizers}

    def _state(self) -> dict[str, Any]:
        return {**super()._state(), "log_alpha": self.log_alpha.detach()}

    def _set_state(self, state: dict[str, Any]) -> None:
        super()._set_state(state)
        with torch.no_grad():
            self.log_alpha.copy_(state["log_alpha"])

    @property
    def alpha(self) -> torch.Tensor:
        return self.log_alpha.exp()

    # --- acting --------------------------------------------------------------------------------
    def _tensors(self, obs: dict) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """One environment observation → a batch of one (camera channels first)."""
        images = torch.as_tensor(np.ascontiguousarray(np.moveaxis(obs["camera"], -1, 0)))[None]
        waypoints = torch.as_tensor(obs["waypoints"], dtype=torch.float32)[None]
        measurements = torch.as_tensor(obs["measurements"], dtype=torch.float32)[None]
        return images.to(self.device), waypoints.to(self.device), measurements.to(self.device)

    def act(self, obs: dict, deterministic: bool) -> np.ndarray:
        """The policy's action in [−1, 1]^|A| (A-LIX off: the encoder in evaluation mode)."""
        self.encoder.eval()
        with torch.no_grad():
            h, _ = self.encoder(*self._tensors(obs))
            if deterministic:
                action = torch.tanh(self.actor(h)[0])
            else:
                action, _ = self.actor.sample(h, self.generator)
        return action[0].cpu().numpy()

    def to_env_action(self, action: np.ndarray) -> np.ndarray:
        """[−1, 1] → the action space's box (target speed [0, 1], steer [−1, 1])."""
        return (self.low + (np.asarray(action) + 1.0) * 0.5 * (self.high - self.low)).astype(np.float32)

    def predict(self, obs: Any, deterministic: bool = True) -> tuple[np.ndarray, None]:
        return self.to_env_action(self.act(obs, deterministic)), None

    # --- learning ------------------------------------------------------------------------------
    def _batch_tensors(self, batch: dict[str, np.ndarray]) -> dict[str, torch.Tensor]:
        tensors = {key: torch.as_tensor(value).to(self.device) for key, value in batch.items()}
        if self.config.augment:  # DrQ: fresh shifts of obs and next_obs at every update
            tensors["images"] = random_shift(tensors["images"], self.pad, self.generator)
            tensors["next_images"] = random_shift(tensors["next_images"], self.pad, self.generator)
        return tensors

    def train_step(self, batch: dict[str, np.ndarray] | None = None) -> dict[str, float]:
        """One update of critics + encoder (+ auxiliary head), actor, temperature and targets
        (the fast one, ``_fast_update``, with ``fast_update``)."""
        config = self.config
        if config.fast_update:
            return self._floats(self._fast_update(batch))
        if batch is None:
            batch = self.replay_buffer.sample(config.batch_size, self.rng)
        t = self._batch_tensors(batch)
        self.encoder.train()
        alpha = self.alpha.detach()
        with torch.no_grad():  # eq. 2: y = r + γ(min_k Q̄_k(h', a') − α log π(a'|h'))
            next_h, _ = self.encoder(t["next_images"], t["next_waypoints"], t["next_measurements"])
            next_action, next_log_prob = self.actor.sample(next_h, self.generator)
            next_q = torch.min(*self.critic_target(next_h, next_action)) - alpha * next_log_prob
            target = t["rewards"] + config.gamma * (1.0 - t["terminated"]) * next_q
        h, image = self.encoder(t["images"], t["waypoints"], t["measurements"])
        q1, q2 = self.critic(h, t["actions"])
        critic_loss = nn.functional.mse_loss(q1, target) + nn.functional.mse_loss(q2, target)  # eq. 1
        loss, metrics = critic_loss, {"critic_loss": critic_loss.item(), "q_mean": q1.mean().item()}
        labels = t["labels"]
        if config.aux and bool((labels != UNKNOWN_LABEL).any()):  # eq. 4, through the image encoder
            logits = self.traffic_light_head(image)
            aux_loss = nn.functional.cross_entropy(logits, labels, ignore_index=UNKNOWN_LABEL)
            loss = loss + config.aux_weight * aux_loss
            known = labels != UNKNOWN_LABEL
            accuracy = (logits.argmax(dim=1)[known] == labels[known]).float().mean()
            metrics.update(aux_loss=aux_loss.item(), aux_accuracy=accuracy.item())
        gradient_step(self.critic_optimizer, loss)
        # eq. 3 on the detached state: the actor's gradient does not reach the encoder
        action, log_prob = self.actor.sample(h.detach(), self.generator)
        actor_loss = (alpha * log_prob - torch.min(*self.critic(h.detach(), action))).mean()
        gradient_step(self.actor_optimizer, actor_loss)
        alpha_loss = (self.alpha * (-log_prob.detach() - self.target_entropy)).mean()
        gradient_step(self.alpha_optimizer, alpha_loss)
        with torch.no_grad():  # θ̄ ← τθ + (1 − τ)θ̄
            for target_p, p in zip(self.critic_target.parameters(), self.critic.parameters(), strict=True):
                target_p.lerp_(p, config.tau)
        metrics.update(actor_loss=actor_loss.item(), alpha=self.alpha.item(), entropy=-log_prob.mean().item())
        if config.alix:
            metrics["alix_strength"] = self.encoder.image.strength.item()
        return metrics

    # --- the fast update (fast.py) ------------------------------------------------------------
    def _critic_objective(
        self, t: dict[str, torch.Tensor], noise: dict[str, torch.Tensor | None], alpha: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, dict[str, torch.Tensor]]:
        """Critic (eq. 1, 2) + auxiliary (eq. 4) loss of the fast update, pure tensor code:
        (loss, h detached (B, 304), metrics as 0-dim tensors)."""
        config = self.config
        with torch.autocast(self.device.type, torch.bfloat16, enabled=config.bf16):
            with torch.no_grad():
                next_h, _ = self.encoder(
                    t["next_images"], t["next_waypoints"], t["next_measurements"], noise["next_offsets"]
                )
                next_action, next_log_prob = self.actor.sample(next_h, None, noise["next_noise"])
                next_q = torch.min(*self.critic_target(next_h, next_action)) - alpha * next_log_prob
                target = t["rewards"] + config.gamma * (1.0 - t["terminated"]) * next_q.float()
            h, image = self.encoder(t["images"], t["waypoints"], t["measurements"], noise["offsets"])
            q1, q2 = self.critic(h, t["actions"])
            q1, q2 = q1.float(), q2.float()
            critic_loss = nn.functional.mse_loss(q1, target) + nn.functional.mse_loss(q2, target)
            loss, metrics = critic_loss, {"critic_loss": critic_loss.detach(), "q_mean": q1.detach().mean()}
            if config.aux:  # the masked mean over labelled samples (fast.py)
                labels = t["labels"]
                known = labels != UNKNOWN_LABEL
                count = known.sum().clamp(min=1)
                logits = self.traffic_light_head(image).float()
                total = nn.functional.cross_entropy(
                    logits, labels, ignore_index=UNKNOWN_LABEL, reduction="sum"
                )
                aux_loss = total / count  # cross_entropy's mean, 0 without a labelled sample
                loss = loss + config.aux_weight * aux_loss
                accuracy = ((logits.detach().argmax(dim=1) == labels) & known).sum() / count
                metrics.update(aux_loss=aux_loss.detach(), aux_accuracy=accuracy)
        return loss, h.detach(), metrics

    def _actor_objective(
        self, h: torch.Tensor, noise: torch.Tensor, alpha: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Actor loss (eq. 3) of the fast update on the detached state, the critics read through
        detached parameters: (loss, log π (B,) detached)."""
        with torch.autocast(self.device.type, torch.bfloat16, enabled=self.config.bf16):
            action, log_prob = self.actor.sample(h, None, noise)
            fixed = {name: p.detach() for name, p in self.critic.named_parameters()}
            q1, q2 = torch.func.functional_call(self.critic, fixed, (h, action))
            actor_loss = (alpha * log_prob.float() - torch.min(q1, q2).float()).mean()
        return actor_loss, log_prob.detach().float()

    def _fast_update(self, batch: dict[str, np.ndarray] | None = None) -> dict[str, torch.Tensor]:
        """``train_step``'s update, fast (``fast.py``); metrics as 0-dim tensors on the device."""
        config, device = self.config, self.device
        if batch is None:
            batch = self.replay_buffer.sample(config.batch_size, self.rng)
        batch_size = len(batch["actions"])
        layers = len(self.encoder.image.convs) if config.alix else 0
        pad = self.pad if config.augment else 0
        drawn = draw_update_noise(self.generator, batch_size, self.low.shape[0], pad, layers)
        noise = {key: None if v is None else v.to(device, non_blocking=True) for key, v in drawn.items()}
        t = {key: torch.as_tensor(value).to(device, non_blocking=True) for key, value in batch.items()}
        if pad:
            t["images"] = random_shift(t["images"], pad, None, noise["shifts"])
            t["next_images"] = random_shift(t["next_images"], pad, None, noise["next_shifts"])
        if config.channels_last:
            for key in ("images", "next_images"):
                t[key] = t[key].contiguous(memory_format=torch.channels_last)
        if config.compile == "reduce-overhead" and device.type == "cuda":
            torch.compiler.cudagraph_mark_step_begin()  # the last update's graph outputs are dead
        self.encoder.train()
        if config.alix:
            with torch.no_grad():
                self.encoder.image.strength.clamp_(0.0, 1.0)
        alpha = self.log_alpha.detach().exp()
        loss, h, metrics = self._critic_objective_fn(t, noise, alpha)
        gradient_step(self.critic_optimizer, loss)
        actor_loss, log_prob = self._actor_objective_fn(h, noise["noise"], alpha)
        alpha_loss = (self.log_alpha.exp() * (-log_prob - self.target_entropy)).mean()
        self.actor_optimizer.zero_grad()
        self.alpha_optimizer.zero_grad()
        (actor_loss + alpha_loss).backward()  # disjoint parameters: the same gradients as two backwards
        self.actor_optimizer.step()
        self.alpha_optimizer.step()
        with torch.no_grad():  # θ̄ ← τθ + (1 − τ)θ̄
            targets, online = list(self.critic_target.parameters()), list(self.critic.parameters())
            torch._foreach_lerp_(targets, online, config.tau)
        metrics = {key: value.clone() for key, value in metrics.items()}  # graph outputs are reused
        metrics.update(actor_loss=actor_loss.detach().clone(), alpha=self.log_alpha.detach().exp(),
                       entropy=-log_prob.mean())  # fmt: skip
        if config.alix:
            metrics["alix_strength"] = self.encoder.image.strength.detach().clone()
        return metrics

    @staticmethod
    def _floats(metrics: dict[str, torch.Tensor]) -> dict[str, float]:
        """Tensor metrics → floats with one host synchronisation."""
        if not metrics:
            return {}
        values = torch.stack([value.float() for value in metrics.values()]).tolist()
        return dict(zip(metrics, values, strict=True))

    def _record(self, obs: dict, info: dict) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
        """What the replay keeps of an observation: newest frame (3, H, W), waypoints,
        measurements, and the traffic-light label of ``info``."""
        frame = np.moveaxis(obs["camera"][..., -3:], -1, 0)
        return frame, obs["waypoints"], obs["measurements"], label_index(info.get("traffic_light"))

    def _start_worlds(self, worlds: Worlds) -> None:
        if self._last_obs is None:
            self._last_obs = row(worlds.reset(), 0)
            self.replay_buffer.start_episode(*self._record(self._last_obs, worlds.reset_infos[0]))

    def _learn(self, worlds: Worlds, callback: BaseCallback, target: int) -> None:
        """Warm-up with random actions, then act with the policy and update every ``train_freq``
        steps. One world (``worlds.Worlds`` with K = 1): the replay keeps one stream of episodes
        and ``_last_obs`` is that world's observation."""
        config, replay = self.config, self.replay_buffer
        metrics: dict[str, Any] = {}  # the fast update's are tensors until logged
        while self.num_timesteps < target:
            callback.on_rollout_start()  # a safe point: nothing is half-done (contract in base.py)
            if self.num_timesteps < config.learning_starts:
                action = self.rng.uniform(-1.0, 1.0, size=self.low.shape).astype(np.float32)
            else:
                action = self.act(self._last_obs, deterministic=False)
            new_obs, rewards, terminated, truncated, final_obs, returns = worlds.step(
                self.to_env_action(action)[None]
            )
            self.num_timesteps += 1
            callback.update_locals(locals())
            if not callback.on_step():  # before the step changes the replay or the networks
                break
            info = worlds.infos[0]
            replay.add(action, float(rewards[0]), bool(terminated[0]), *self._record(row(final_obs, 0), info))
            self.episode_returns += returns
            if terminated[0] or truncated[0]:  # the world has started again: a new episode's first record
                replay.start_episode(*self._record(row(new_obs, 0), worlds.reset_infos[0]))
            self._last_obs = row(new_obs, 0)
            ready = self.num_timesteps >= config.learning_starts and replay.size >= config.batch_size
            if ready and self.num_timesteps % config.train_freq == 0:
                metrics = self._fast_update() if config.fast_update else self.train_step()
            if self.num_timesteps % config.log_interval == 0:
                self._log_progress(self._floats(metrics) if config.fast_update else metrics)


class DrQ(RLAD):
    """The DrQ baseline (``--algo drq``): ``DrQConfig``'s defaults on RLAD's machinery."""

    config_class = DrQConfig
