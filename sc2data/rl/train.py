"""Train MaskablePPO agents on BuildMarines with a chosen reward.

A run folder (``--out RUN``) holds:

* ``config.json`` — the settings (what a rerun must match to resume);
* ``model.zip`` — the latest checkpoint (sb3-contrib's format), replaced atomically;
* ``state.json`` — decisions and pysc2 steps trained so far, episodes, resume count;
* ``curve.csv`` / ``curve.json`` — one row per finished training episode: the env, SB3's
  timestep count (decisions over all envs) and the pysc2 steps over all envs when it ended, the
  marines made (the game's score), the game's return and the shaped return;
* ``eval.json`` — sampled and argmax play on the evaluation episodes, written by
  :func:`sc2data.rl.evaluate.evaluate`.

Resuming: rerunning the same command (the same settings; a larger ``--steps`` is allowed)
continues from ``model.zip``; episodes running at the interruption are lost, and the resumed
part's environments are seeded ``seed + 1000·resumes + i`` so that no episode repeats.
Training seeds env i with ``seed + i`` (then ``+ 1000`` per resume); evaluation episodes use
seeds from ``EVAL_SEED`` on, a range training never uses while ``seed < 900,000``.
"""

from __future__ import annotations

import dataclasses
import math
import os
import shutil
import typing
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from sc2data.ground.errors import MissingDependencyError, Sc2DataError
from sc2data.ground.files import FolderLock, check_out, sha256_file, writing
from sc2data.ground.formats import Shape
from sc2data.ground.progress import bar
from sc2data.ground.resume import differences, read_record, refusal
from sc2data.ground.vocab import BACKENDS, LAYER_SETS, STEP_MUL
from sc2data.rl import runs
from sc2data.rl.runs import CURVE_FIELDS, STATE_SHAPE  # noqa: F401  (names users import)

EVAL_SEED = 1_000_000
"""First evaluation episode seed (training's seeds stay below it)."""


def require_rl(purpose: str) -> None:
    """Raise a one-line :class:`MissingDependencyError` unless the ``rl`` extra is installed."""
    for module, package in (("gymnasium", "gymnasium"), ("stable_baselines3", "stable-baselines3"),
                            ("sb3_contrib", "sb3-contrib"), ("torch", "torch")):
        try:
            __import__(module)
        except ImportError:
            raise MissingDependencyError(package, "rl", purpose) from None


def default_shaping(reward: str) -> str:
    """How ``reward`` pays its bonus unless told: ``potential`` for the rules reward, ``event``
    for the others — what the experiment chose (BENCHMARKS.md, "Event or potential-based
    shaping"): paid per firing, the rules' bonus is farmed (agents build depots, not marines,
    below the uniform policy), as a potential it is not; the narration bonus did at least as
    well per match."""
    return "potential" if reward == "rules" else "event"


@dataclass(frozen=True)
class RLConfig:
    """Everything that defines a training run (``steps`` and ``progress`` may change on resume).

    ``sc2data rl train`` takes one option per field (``--batch-size`` for ``batch_size``), its
    default the field's and its help the docstring under it
    (:func:`sc2data.cli.cliopts.config_options`): a new field is a new option, with no edit to the
    command line.
    """

    out: str
    """Run folder (rerun the same command to resume)."""
    action_space: str = "macro"
    """macro (6 macro actions) or paper (pysc2 function + screen point)."""
    reward: str = "sparse"
    """sparse, rules, narration or zero (a control: no reward)."""
    narration: str | None = None
    """Narration file (TOML or one command per line) [default: the shipped BuildMarines
    narration]."""
    mem: str | None = None
    """Trained MEM run (sc2data train --out), for --reward narration."""
    steps: int = 10_000
    """Decisions to train for, over all envs."""
    envs: int = 16
    """Games stepped together (one batched policy and reward call per step)."""
    seed: int = 0
    """Seed of the policy and the environments."""
    bonus: float | None = None
    """Shaping bonus: per rule firing (rules) or per matched command (narration) [default: 0.1
    rules, 1.0 narration]."""
    threshold: float = 0.5
    """MEM distance below which a command is matched."""
    patience: int = 0
    """Skip a narration command not matched within this many decisions (0: never)."""
    shaping: str | None = None
    """How rules/narration pay their bonus: event (each firing or match) or potential
    (gamma*phi(s') - phi(s): cannot be farmed) [default: potential for rules, event
    otherwise]."""
    # potential: γ·Φ(s') − Φ(s) with the run's gamma (sc2data.rl.rewards); the defaults are
    # the experiment's choice (default_shaping).
    episode_steps: int | None = None
    """pysc2 steps per episode on the simulator [default: 1800]."""
    rollout: int = 64
    """PPO rollout length per env."""
    # SB3's n_steps.
    batch_size: int = 256
    """PPO minibatch size."""
    checkpoint_every: int = 2048
    """Decisions between checkpoints."""
    layers: str = "paper"
    """Layers of the stored observation (--obs stored): paper (the paper's 13 + 7) or full (all
    27 + 11)."""
    backend: str = "sim"
    """The game: sim (the embedded simulator) or sc2 (StarCraft II; needs the game)."""
    obs: str = "compact"
    """What the policy sees: compact (one-hot unit types, few layers) or stored (the stored
    schema's layers)."""
    # sc2data.rl.obs.
    obs_size: int = 32
    """compact: 64 or 32 pixels a side."""
    minimap: bool = False
    """compact: add the minimap's channels."""
    env_groups: int = 2
    """Games stepped a group at a time: the learner acts for one group while the others step
    (1: all in lockstep; capped at --envs)."""
    # sc2data.rl.pipeline: the same decisions as lockstep, sampled a group at a time, so the
    # same seed gives another run for another number of groups (not for other --processes).
    processes: int | None = None
    """Worker processes stepping the games (0: in this process) [default: one per core, one
    fewer with the narration reward, at least one; none for one env]."""
    # Changes nothing but speed, so it may differ on resume.
    device: str = "auto"
    """Policy and MEM on cpu, cuda or auto (cuda where a GPU is present)."""
    threads: int | None = None
    """Torch threads of the learner (policy, MEM, updates) [default: one per core]."""
    # The games' workers wait while PPO updates, so its threads take no core from them: two
    # threads halved an update on this project's 2-core machine (BENCHMARKS.md, "RL at speed").
    policy: str = "auto"
    """spatial (paper space: the point given the function), independent (SB3's heads) or
    auto."""
    # spatial: sc2data.rl.spatial; auto: spatial for the paper space on the compact
    # observation, independent otherwise.
    point_head: str = "cell"
    """Spatial policy: cell (one logit per observation cell, shared by its pixels) or pixel
    (a logit per screen pixel: a 3×3 convolution weighing the pixels within each cell, and a
    learnt preference per pixel; argmax clicks a pixel, not a cell's centre)."""
    # sc2data.rl.spatial.PaperPolicy. Costs 1.9× in decisions/s at --obs-size 32
    # (BENCHMARKS.md, "A point head that chooses the pixel"), so not the default.
    gamma: float = 0.99
    """PPO discount (per pysc2 step with --smdp)."""
    gae_lambda: float = 0.95
    """GAE lambda."""
    epochs: int = 4
    """PPO epochs over each rollout."""
    learning_rate: float = 3e-4
    """Adam's step size for the policy and value (SB3's default)."""
    ent_coef: float = 0.01
    """Entropy bonus coefficient."""
    ent_coef_final: float | None = None
    """Entropy bonus at --steps, reached linearly from --ent-coef [default: --ent-coef
    throughout]."""
    # Set before each update from the decisions trained (_curve), so a resumed run goes on
    # along the same line.
    normalize_advantage: bool = False
    """Normalise advantages per minibatch (SB3's default; off: a zero-reward control then stays
    where it started)."""
    # With a value function that explains nothing yet, each update is then a full clipped step
    # of noise, and a zero-reward control drifts from its initial policy
    # (tests/rl/test_control.py).
    reward_scale: float = 1.0
    """Multiply the reward PPO learns from by this (the curve keeps the game's marines and
    the unscaled return)."""
    # One clipped gradient norm (--max-grad-norm) covers the value loss and the policy's: with
    # the game's returns (tens of marines) the value's gradient takes nearly all of it
    # (BENCHMARKS.md, "The value loss's share of the gradient"). Engstrom et al. 2020 list
    # reward scaling among PPO's essential details.
    vf_coef: float = 0.5
    """Weight of the value loss in PPO's loss (SB3's default)."""
    max_grad_norm: float = 0.5
    """Norm the gradient of PPO's whole loss (policy, entropy, value) is clipped to (SB3's
    default)."""
    share_features: bool = True
    """One feature network for the policy and the value function (SB3's default); off: one
    each (macro space)."""
    # Andrychowicz et al. 2021 ("What matters in on-policy RL") found separate networks learn
    # better; the paper space's spatial policy reads its one trunk's map, so it keeps one.
    target_kl: float | None = 0.05
    """Stop an update's epochs once the policy moved this far (0: never)."""
    # Approximate KL; 0 is kept as None (never).
    smdp: bool = True
    """Discount a decision of k pysc2 steps by gamma^k."""
    # The same as gamma in the paper space, where every decision is one step
    # (sc2data.rl.smdp).
    merge_waits: bool = True
    """Macro space: while no_op is the only macro allowed, wait on within the decision (up to
    64 pysc2 steps), so the policy is asked only when it has a choice."""
    # sc2data.rl.envs: the game plays exactly as before; decisions (and --steps) count only
    # choices. Most forced waits come after the macro space's supply ceiling (BENCHMARKS.md).
    macro_sites: str = "random"
    """Macro space: build on random free sites (the paper's random agent) or far (the site
    farthest from the minerals, as the scripted agent: more buildings fit)."""
    # BENCHMARKS.md, "The macro space's ceiling": the scripted rules make 88.2 marines on random
    # sites and 119.2 on far ones.
    history: bool = False
    """Compact observation: the policy also sees the game time since each macro (paper space:
    each function) last acted (as pysc2's last_actions; else a builder on its way shows
    nowhere)."""
    # sc2data.rl.obs.MacroClock.
    init_policy: str | None = None
    """Start from this trained run's policy (its model.zip: the same action space, observation
    and network) instead of a fresh one, e.g. a clone of the macro-rules agent."""
    # benchmarks/clone_rules.py writes such a run. The starting checkpoint is recorded by
    # content when the run begins (inputs.init_policy_sha256); a resume reads its own.
    kickstart: str | None = None
    """Keep the policy near this trained run's (a teacher of the same action space and
    observation, e.g. a clone of the macro-rules agent): after each PPO update, one pass over
    the rollout lowering --kickstart-coef × KL(teacher ‖ policy) on its states (the teacher's
    policy of the run's kind: independent, or the paper space's spatial one)."""
    # Kickstarting (Schmitt et al. 2018) as a phase of its own after PPO's epochs, as PPG's
    # auxiliary phase (Cobbe et al. 2020): sc2data.rl.pipeline.PipelinedPPO.train. The
    # teacher's checkpoint is recorded by content (inputs.kickstart_sha256): a resume needs the
    # same file.
    kickstart_coef: float = 1.0
    """Weight of the kickstart KL (--kickstart)."""
    tensorboard: bool = False
    """Also write SB3's log as TensorBoard events (RUN/logs/<session>/; needs tensorboard)."""
    progress: bool | None = None
    """Progress bar [default: on a terminal]."""

    RESUMABLE = ("steps", "progress", "out", "processes", "device", "threads", "tensorboard")
    LEGACY: typing.ClassVar[dict[str, Any]] = {
        "obs": "stored", "obs_size": 64, "minimap": False, "policy": "independent", "gamma": 0.99,
        "gae_lambda": 0.95, "epochs": 4, "learning_rate": 3e-4, "ent_coef": 0.01,
        "ent_coef_final": None, "normalize_advantage": True, "target_kl": None, "smdp": False,
        "shaping": "event", "env_groups": 1, "merge_waits": False, "macro_sites": "random",
        "history": False, "share_features": True, "reward_scale": 1.0,
        "vf_coef": 0.5, "max_grad_norm": 0.5, "init_policy": None, "kickstart": None,
        "kickstart_coef": 1.0, "point_head": "cell"}
    """Settings added since runs were first written, as those runs had them: a run folder whose
    ``config.json`` lacks one was trained so."""

    def __post_init__(self) -> None:
        if self.target_kl == 0:  # 0: never stop early, as None
            object.__setattr__(self, "target_kl", None)
        if self.shaping is None:
            object.__setattr__(self, "shaping", default_shaping(self.reward))

    def obs_config(self) -> Any:
        from sc2data.rl.obs import ObsConfig

        return ObsConfig(kind=self.obs, layers=self.layers, size=self.obs_size,
                         minimap=self.minimap, history=self.history,
                         action_space=self.action_space)

    def identity(self) -> dict[str, Any]:
        return {k: v for k, v in dataclasses.asdict(self).items() if k not in self.RESUMABLE}


CONFIG_SHAPE: Shape = {name: typing.get_args(hint) or hint for name, hint in
                      typing.get_type_hints(RLConfig).items()
                      if name not in RLConfig.RESUMABLE and name != "LEGACY"}
"""``config.json``: :meth:`RLConfig.identity`, every field of its type."""

def check_values(cfg: RLConfig) -> None:
    """One-line error unless every setting of ``cfg`` is one sc2data can run."""
    from sc2data.game.agents import SITES
    from sc2data.rl.envs import ACTION_SPACES
    from sc2data.rl.obs import OBSERVATIONS
    from sc2data.rl.rewards import REWARDS

    for name, known in (("action_space", ACTION_SPACES), ("reward", REWARDS),
                        ("macro_sites", SITES),
                        ("layers", LAYER_SETS), ("backend", BACKENDS), ("obs", OBSERVATIONS),
                        ("device", DEVICES)):
        if getattr(cfg, name) not in known:
            raise Sc2DataError(f"unknown {name.replace('_', ' ')} {getattr(cfg, name)!r}; choose "
                               f"one of: {', '.join(known)}")
    for name in ("steps", "envs", "rollout", "batch_size", "checkpoint_every", "env_groups"):
        if getattr(cfg, name) < 1:
            raise Sc2DataError(f"--{name.replace('_', '-')} must be at least 1")
    if cfg.episode_steps is not None and cfg.episode_steps < 1:
        raise Sc2DataError("--episode-steps must be at least 1")
    for name in ("reward_scale", "vf_coef", "max_grad_norm", "kickstart_coef"):
        if not (math.isfinite(getattr(cfg, name)) and getattr(cfg, name) > 0):
            raise Sc2DataError(f"--{name.replace('_', '-')} must be a positive finite number, "
                               f"got {getattr(cfg, name)}")
    if cfg.bonus is not None and not math.isfinite(cfg.bonus):
        raise Sc2DataError(f"--bonus must be a finite number, got {cfg.bonus}")
    if not (math.isfinite(cfg.threshold) and cfg.threshold > 0):
        raise Sc2DataError(f"--threshold must be a positive finite distance, got {cfg.threshold}")
    if cfg.patience < 0:
        raise Sc2DataError("--patience must be 0 or more")
    if cfg.normalize_advantage and min(cfg.batch_size, cfg.rollout * cfg.envs) < 2:
        raise Sc2DataError("--normalize-advantage needs minibatches of at least 2 samples "
                           "(--batch-size, and --rollout × --envs)")
    if not 0 <= cfg.seed < EVAL_SEED - 100_000:
        raise Sc2DataError(f"--seed must lie in [0, {EVAL_SEED - 100_000})")
    if cfg.processes is not None and cfg.processes < 0:
        raise Sc2DataError("--processes must be 0 or more")
    if cfg.threads is not None and cfg.threads < 1:
        raise Sc2DataError("--threads must be at least 1")
    cfg.obs_config().check()
    if cfg.policy not in POLICIES:
        raise Sc2DataError(f"unknown policy {cfg.policy!r}; choose one of: {', '.join(POLICIES)}")
    if cfg.policy == "spatial" and (cfg.action_space != "paper" or cfg.obs != "compact"):
        raise Sc2DataError("--policy spatial needs --action-space paper and --obs compact")
    if cfg.point_head not in POINT_HEADS:
        raise Sc2DataError(f"unknown point head {cfg.point_head!r}; choose one of: "
                           f"{', '.join(POINT_HEADS)}")
    if cfg.point_head != "cell" and resolved_policy(cfg) != "spatial":
        raise Sc2DataError(f"--point-head {cfg.point_head} goes with the spatial policy "
                           "(--action-space paper --obs compact)")
    if not cfg.share_features and resolved_policy(cfg) == "spatial":
        raise Sc2DataError("--no-share-features goes with --policy independent (the spatial "
                           "policy's point head reads the shared trunk's map)")
    for name in ("gamma", "gae_lambda"):
        if not 0.0 <= getattr(cfg, name) <= 1.0:
            raise Sc2DataError(f"--{name.replace('_', '-')} must lie in [0, 1]")
    if cfg.epochs < 1:
        raise Sc2DataError("--epochs must be at least 1")
    if not (0.0 < cfg.learning_rate < float("inf")):
        raise Sc2DataError(f"--learning-rate must be a positive finite number, got "
                           f"{cfg.learning_rate}")
    for name in ("ent_coef", "ent_coef_final"):
        value = getattr(cfg, name)
        if value is not None and not (value >= 0.0 and value < float("inf")):
            raise Sc2DataError(f"--{name.replace('_', '-')} must be a finite number, 0 or more")
    if cfg.target_kl is not None and not 0.0 < cfg.target_kl < float("inf"):
        raise Sc2DataError("--target-kl must be a positive finite number")
    from sc2data.rl.rewards import SHAPINGS

    if cfg.shaping not in SHAPINGS:
        raise Sc2DataError(f"unknown shaping {cfg.shaping!r}; choose one of: {', '.join(SHAPINGS)}")
    if cfg.macro_sites != "random" and cfg.action_space != "macro":
        raise Sc2DataError("--macro-sites goes with --action-space macro (the paper space's "
                           "policy chooses its sites)")
    if cfg.shaping != "event" and cfg.reward not in ("rules", "narration"):
        raise Sc2DataError(f"--shaping {cfg.shaping} goes with --reward rules or narration")


DEVICES: tuple[str, ...] = ("auto", "cpu", "cuda")


def cores() -> int:
    """The cores this process may run on."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def resolve_device(name: str) -> str:
    """``cpu`` or ``cuda`` for ``--device`` (``auto``: cuda where a GPU is present); asking for
    cuda without one is a one-line error."""
    import torch

    if name == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if name == "cuda" and not torch.cuda.is_available():
        raise Sc2DataError("--device cuda: PyTorch sees no CUDA GPU here; use --device cpu "
                           "(or auto)")
    return name


def check_config(cfg: RLConfig) -> tuple[Any, Any]:
    """Validate ``cfg`` before anything is written: (narration, scorer) for the narration reward."""
    check_values(cfg)
    if cfg.reward != "narration":
        if cfg.mem is not None or cfg.narration is not None:
            raise Sc2DataError("--mem and --narration go with --reward narration")
        return None, None
    if cfg.mem is None:
        raise Sc2DataError("--reward narration needs --mem RUN (a trained MEM: sc2data train)")
    from sc2data.model.scorer import load_model
    from sc2data.rl.narration import check_readable, load_narration

    narration = load_narration(cfg.narration)
    # threads=None: the scorer runs on the learner's threads (load_model's default is one)
    scorer = load_model(cfg.mem, device=resolve_device(cfg.device), threads=None)
    check_readable(narration, scorer)
    return narration, scorer


def make_env(cfg: RLConfig, scorer: Any = None, narration: Any = None) -> Any:
    """One environment as a gymnasium ``Env``: ``BuildMarinesGym`` under the run's per-game
    reward wrapper (training uses :func:`make_vec_env`, whose reward is batched)."""
    from sc2data.rl.envs import BuildMarinesGym
    from sc2data.rl.rewards import wrap_reward

    env = BuildMarinesGym(cfg.action_space, backend=cfg.backend, obs=cfg.obs_config(),
                          game_loops=game_loops(cfg), merge_waits=cfg.merge_waits,
                          sites=cfg.macro_sites)
    if cfg.reward == "narration" and scorer is None:
        narration, scorer = check_config(cfg)
    return wrap_reward(env, cfg.reward, scorer=scorer, narration=narration, bonus=cfg.bonus,
                       threshold=cfg.threshold, patience=cfg.patience, shaping=cfg.shaping,
                       gamma=cfg.gamma, smdp=cfg.smdp and cfg.action_space == "macro")


def game_loops(cfg: RLConfig) -> int | None:
    """The episode length in game loops (None: the map's)."""

    return cfg.episode_steps * STEP_MUL if cfg.episode_steps else None


def make_vec_env(cfg: RLConfig, scorer: Any = None, narration: Any = None) -> Any:
    """``cfg.envs`` games as one :class:`~sc2data.rl.vector.BuildMarinesVecEnv`, stepped by
    ``cfg.processes`` worker processes, the run's reward batched in this process."""
    from sc2data.rl.batched import make_shaping
    from sc2data.rl.vector import BuildMarinesVecEnv, GameConfig

    if cfg.reward == "narration" and scorer is None:
        narration, scorer = check_config(cfg)
    shaping = make_shaping(cfg.reward, scorer=scorer, narration=narration, bonus=cfg.bonus,
                           threshold=cfg.threshold, patience=cfg.patience, shaping=cfg.shaping,
                           gamma=cfg.gamma, smdp=cfg.smdp and cfg.action_space == "macro")
    game = GameConfig(cfg.action_space, cfg.backend, cfg.obs_config(), game_loops(cfg),
                      merge_waits=cfg.merge_waits, sites=cfg.macro_sites)
    return BuildMarinesVecEnv(game, cfg.envs, processes=cfg.processes, shaping=shaping,
                              reward_scale=cfg.reward_scale)


def new_model(cfg: RLConfig, vec: Any, seed: int, device: str = "cpu") -> Any:
    """An untrained MaskablePPO agent of the run's settings on ``vec`` (seeded: the same seed
    gives the same initial policy)."""
    from sc2data.rl.pipeline import PipelinedPPO
    from sc2data.rl.smdp import SMDPRolloutBuffer

    model = PipelinedPPO(
        policy_class(cfg), vec, n_steps=cfg.rollout, batch_size=cfg.batch_size,
        n_epochs=cfg.epochs, learning_rate=cfg.learning_rate, gamma=cfg.gamma,
        gae_lambda=cfg.gae_lambda,
        ent_coef=cfg.ent_coef, normalize_advantage=cfg.normalize_advantage,
        vf_coef=cfg.vf_coef, max_grad_norm=cfg.max_grad_norm,
        target_kl=cfg.target_kl, seed=seed, device=device, verbose=0,
        rollout_buffer_class=SMDPRolloutBuffer if cfg.smdp else None,
        policy_kwargs=policy_kwargs(cfg))
    model.groups = cfg.env_groups
    return model


POLICIES: tuple[str, ...] = ("auto", "spatial", "independent")
POINT_HEADS: tuple[str, ...] = ("cell", "pixel")


def resolved_policy(cfg: RLConfig) -> str:
    """``spatial`` or ``independent`` (see :attr:`RLConfig.policy`)."""
    if cfg.policy != "auto":
        return cfg.policy
    return "spatial" if cfg.action_space == "paper" and cfg.obs == "compact" else "independent"


def policy_class(cfg: RLConfig) -> Any:
    """The policy MaskablePPO builds: :class:`~sc2data.rl.spatial.PaperPolicy` or SB3's."""
    if resolved_policy(cfg) == "spatial":
        from sc2data.rl.spatial import PaperPolicy

        return PaperPolicy
    return "MultiInputPolicy"


def policy_kwargs(cfg: RLConfig) -> dict[str, Any]:
    """The policy network: the feature extractor of the run's observation."""
    from sc2data.rl.obs import Observer
    from sc2data.rl.policy import CompactExtractor, StateExtractor

    share: dict[str, Any] = {} if cfg.share_features else {"share_features_extractor": False}
    if resolved_policy(cfg) == "spatial" and cfg.point_head != "cell":
        share["point_head"] = cfg.point_head
    if cfg.obs == "stored":
        return {"features_extractor_class": StateExtractor, **share}
    return {"features_extractor_class": CompactExtractor,
            "features_extractor_kwargs": {"scales": Observer(cfg.obs_config()).scales()},
            **share}


def _read_json(path: Path, shape: Shape) -> dict[str, Any]:
    """A run record, checked to have ``shape``."""
    return runs.read_record(path, shape, path.parent)


def _write_json(path: Path, data: Any) -> None:
    runs.write_record(path, data)


def read_config(run: Path) -> dict[str, Any]:
    """A run's ``config.json``, checked; settings added since it was written read as the run
    had them (:attr:`RLConfig.LEGACY`)."""
    return read_record(run / runs.CONFIG, CONFIG_SHAPE, runs.remedy(run),  # type: ignore[no-any-return]
                       defaults=RLConfig.LEGACY)


read_curve = runs.read_curve


def train(cfg: RLConfig) -> Path:
    """Train (or resume) a MaskablePPO agent; returns the run folder (:mod:`sc2data.rl.runs`
    says what it holds and how a checkpoint is committed)."""
    require_rl("sc2data rl train")
    narration, scorer = check_config(cfg)
    run = Path(cfg.out)
    check_out(run)
    if runs.is_record(run):
        raise Sc2DataError(runs.no_model(run))
    if run.exists() and not run.is_dir():
        raise Sc2DataError(f"cannot write {run}: it is a file; choose another --out")
    if run.is_dir() and any(run.iterdir()) and not (run / runs.CONFIG).is_file():
        raise Sc2DataError(f"{run} exists and is not an sc2data rl run; pick another --out")
    made = not run.exists()
    begun = (run / runs.CONFIG).is_file()  # an existing run: never forgotten on failure
    run.mkdir(parents=True, exist_ok=True)
    try:
        with writing(f"the run {run}", "free some space, then rerun the same command to "
                                       "resume"), FolderLock(run, "rl train"):
            return _train_locked(cfg, run, narration, scorer)
    except BaseException:
        if not begun and not (run / runs.STATE).is_file():
            _forget(run, whole=made)  # a new run with no checkpoint yet: the rerun starts afresh
        raise


def _forget(run: Path, whole: bool) -> None:
    """Remove what a run that never reached its first checkpoint wrote (so a corrected command
    is not refused as "other settings"); the folder too if this command made it."""
    if whole:
        shutil.rmtree(run, ignore_errors=True)
        return
    for name in (runs.CONFIG, runs.CURVE_CSV, runs.CURVE_JSON, runs.MODEL_PARTIAL,
                 runs.CURVE_PARTIAL, runs.STATE_PARTIAL):
        (run / name).unlink(missing_ok=True)
    shutil.rmtree(run / runs.LOGS, ignore_errors=True)


def _train_locked(cfg: RLConfig, run: Path, narration: Any, scorer: Any) -> Path:
    runs.recover(run)
    inputs = runs.input_digests(narration, cfg.mem)
    if cfg.init_policy is not None:
        inputs.update(_init_digest(cfg, run))
    if cfg.kickstart is not None:
        inputs["kickstart_sha256"] = sha256_file(_trained_model(cfg.kickstart, "--kickstart"))
    identity = {**cfg.identity(), "inputs": inputs}
    state = _resume_state(cfg, run, identity)
    if cfg.init_policy is not None and not state["timesteps"]:
        check_init(cfg, cfg.init_policy, "--init-policy", INIT_MATCH, "a starting policy needs "
                   "the run's action space, observation and network")
    if cfg.kickstart is not None:
        check_init(cfg, cfg.kickstart, "--kickstart", TEACHER_MATCH, "a teacher needs the run's "
                   "action space, observation and policy")
    if state["timesteps"] >= cfg.steps:
        print(f"{run} is already trained for {state['timesteps']} steps (--steps {cfg.steps})")
        return run

    import torch
    from stable_baselines3.common.logger import configure

    # PPO's update runs while the games' workers wait, so it may use every core (a pipelined
    # rollout, sc2data.rl.pipeline, runs on one thread while the workers step beside it).
    torch.set_num_threads(cfg.threads or cores())
    device = resolve_device(cfg.device)
    formats = _log_formats(cfg)
    _write_json(run / runs.CONFIG, identity)
    rows = [r for r in runs.read_curve(run) if r["timesteps"] <= state["timesteps"]]
    seed = cfg.seed + 1000 * state["resumes"]
    vec = make_vec_env(cfg, scorer, narration)
    try:
        if state["timesteps"]:
            model = runs.load_model(run, vec, device, attach=True)
            model.set_random_seed(seed)
            model.groups = cfg.env_groups
        else:
            model = new_model(cfg, vec, seed, device)
            if cfg.init_policy is not None:
                start_from(model, Path(cfg.init_policy), vec, device)
        if cfg.kickstart is not None:
            model.teacher = runs.load_model(Path(cfg.kickstart), vec, device).policy
            model.teacher.set_training_mode(False)
            model.kickstart_coef = cfg.kickstart_coef
        model.set_logger(configure(str(run / runs.LOGS / str(state["resumes"])), formats))
        with bar(cfg.steps, desc="rl train", unit="step", show=cfg.progress) as progress:
            progress.update(state["timesteps"])
            callback = _curve(cfg, run, model, rows, state, progress)
            model.learn(total_timesteps=cfg.steps - state["timesteps"], callback=callback,
                        reset_num_timesteps=False)
            callback.save()
    finally:
        vec.close()
    return run


INIT_MATCH: tuple[str, ...] = ("action_space", "obs", "obs_size", "minimap", "history",
                               "layers", "point_head", "share_features")
"""Settings a starting policy (``--init-policy``) must share with the run: they shape its
inputs, outputs and network."""
TEACHER_MATCH: tuple[str, ...] = INIT_MATCH[:-1]
"""Settings a teacher (``--kickstart``) must share with the run: its inputs and outputs (its
network may be another)."""


def check_init(cfg: RLConfig, source: str, option: str, match: tuple[str, ...],
               need: str) -> None:
    """One line unless ``source`` is a trained run (checked by content) that fits this run:
    the same ``match`` settings and the same policy. ``need`` ends the line."""
    src = Path(source)
    init = load_config(src)
    odd = [(k.replace("_", "-"), getattr(init, k), getattr(cfg, k)) for k in match
           if getattr(init, k) != getattr(cfg, k)]
    if resolved_policy(init) != resolved_policy(cfg):
        odd.append(("policy", resolved_policy(init), resolved_policy(cfg)))
    if odd:
        name, theirs, ours = odd[0]
        raise Sc2DataError(f"{option} {src} was trained with --{name} {theirs} and this run "
                           f"has {ours}; {need}")


def start_from(model: Any, src: Path, vec: Any, device: Any) -> None:
    """Give the new ``model`` the policy (and value function) of the trained run ``src``."""
    init = runs.load_model(src, vec, device)
    try:
        model.policy.load_state_dict(init.policy.state_dict())
    except RuntimeError as e:
        first = (str(e).strip().splitlines() or ["another network"])[0]
        raise Sc2DataError(f"--init-policy {src}: its network does not fit this run's "
                           f"({first})") from None


def _init_digest(cfg: RLConfig, run: Path) -> dict[str, str]:
    """The starting policy's checkpoint by content, as recorded when the run began (a resume
    reads it from its own ``config.json``, whatever became of that file since)."""
    if (run / runs.CONFIG).is_file():
        old = read_config(run).get("inputs") or {}
        if "init_policy_sha256" in old:
            return {"init_policy_sha256": old["init_policy_sha256"]}
    return {"init_policy_sha256": sha256_file(_trained_model(str(cfg.init_policy),
                                                             "--init-policy"))}


def _trained_model(source: str, option: str) -> Path:
    """``source``'s checkpoint, or one line if it has none."""
    if runs.is_record(Path(source)):
        raise Sc2DataError(f"{option} {runs.no_model(Path(source))}")
    model = Path(source) / runs.MODEL
    if not model.is_file():
        raise Sc2DataError(f"{option} {source} is not a trained sc2data rl run (no model.zip); "
                           f"pass the --out of sc2data rl train")
    return model


def _resume_state(cfg: RLConfig, run: Path, identity: dict[str, Any]) -> dict[str, Any]:
    """The run's progress to go on from: its last checkpoint's (a resume, counted), or a new
    run's; a one-line refusal if the folder holds a run of other settings or inputs."""
    state: dict[str, Any] = {"timesteps": 0, "env_steps": 0, "episodes": 0, "resumes": 0}
    if not (run / runs.CONFIG).is_file():
        return state
    old = read_config(run)
    old_inputs = old.pop("inputs", None)
    diff = differences(old, cfg.identity())
    if diff:
        raise refusal(run, "a run", diff, "rerun with the same options to resume, or pick "
                      "another --out")
    if old_inputs is not None and old_inputs != identity["inputs"]:
        what = sorted(k.replace("_sha256", "") for k in set(old_inputs) | set(
            identity["inputs"]) if old_inputs.get(k) != identity["inputs"].get(k))
        raise Sc2DataError(f"{run} was trained with another {' and '.join(what)} (the file "
                           f"at that path changed); restore it, or pick another --out")
    previous = runs.read_state(run)
    return state if previous is None else {**previous, "resumes": previous["resumes"] + 1}


def _log_formats(cfg: RLConfig) -> list[str]:
    """SB3's log outputs: CSV, and TensorBoard events with ``--tensorboard`` (its package
    present, else one line)."""
    if not cfg.tensorboard:
        return ["csv"]
    try:
        import tensorboard  # noqa: F401
    except ImportError:
        raise MissingDependencyError("tensorboard", "rl", "--tensorboard") from None
    return ["csv", "tensorboard"]


def ent_coef_at(cfg: RLConfig, timesteps: int) -> float:
    """The entropy bonus of the update after ``timesteps`` decisions: ``--ent-coef``, or linear
    from it to ``--ent-coef-final`` at ``--steps``."""
    if cfg.ent_coef_final is None:
        return cfg.ent_coef
    done = min(1.0, timesteps / cfg.steps)
    return cfg.ent_coef + (cfg.ent_coef_final - cfg.ent_coef) * done


def _curve(cfg: RLConfig, run: Path, model: Any, rows: list[dict[str, Any]],
           state: dict[str, Any], progress: Any) -> Any:
    """The callback that keeps the run's record while PPO learns: episode rows, SMDP step
    counts, the game's score in SB3's log, the progress bar and periodic checkpoints (its
    ``save`` commits one). ``rows`` and ``state`` are updated in place."""
    from stable_baselines3.common.callbacks import BaseCallback

    class Curve(BaseCallback):
        def __init__(self) -> None:
            super().__init__()
            self.game = np.zeros(cfg.envs)
            self.ret = np.zeros(cfg.envs)
            self.next_save = state["timesteps"] + cfg.checkpoint_every
            self.last = state["timesteps"]
            self.finished: list[float] = []

        def _on_step(self) -> bool:
            infos, dones = self.locals["infos"], self.locals["dones"]
            rewards = self.locals["rewards"]
            buffer = self.model.rollout_buffer
            if hasattr(buffer, "record_steps"):  # SMDPRolloutBuffer, before SB3 adds the step
                buffer.record_steps([int(i.get("env_steps", 1)) for i in infos])
            for i, info in enumerate(infos):
                state["env_steps"] += int(info.get("env_steps", 1))
                self.game[i] += float(info.get("game_reward", rewards[i]))
                self.ret[i] += float(rewards[i]) / cfg.reward_scale
                if dones[i]:
                    self._episode_end(i, info)
            progress.update(self.num_timesteps - self.last)
            self.last = self.num_timesteps
            if self.num_timesteps >= self.next_save:
                self.save()
                self.next_save = self.num_timesteps + cfg.checkpoint_every
            return True

        def _episode_end(self, i: int, info: dict[str, Any]) -> None:
            state["episodes"] += 1
            marines = int(info.get("marines", self.game[i]))
            rows.append({"episode": state["episodes"], "env": i,
                         "timesteps": self.num_timesteps, "env_steps": state["env_steps"],
                         "marines": marines, "game_return": round(self.game[i], 6),
                         "return": round(self.ret[i], 6)})
            self.finished.append(marines)
            self.game[i] = self.ret[i] = 0.0

        def _on_rollout_end(self) -> None:  # the update that follows uses this entropy bonus
            self.model.ent_coef = ent_coef_at(cfg, self.num_timesteps)
            self.logger.record("train/ent_coef", self.model.ent_coef)
            self.logger.record("game/pysc2_steps", state["env_steps"])
            self.logger.record("game/episodes", state["episodes"])
            if self.finished:
                self.logger.record("game/marines_mean", float(np.mean(self.finished)))
                self.finished = []

        def save(self) -> None:
            state["timesteps"] = self.num_timesteps
            runs.commit(run, model, rows, {"config": cfg.identity(), "episodes": list(rows)},
                        state)

    return Curve()


def trained_steps(run: Path) -> int:
    """Decisions a run folder holds so far (0 for none, or for files training will refuse)."""
    try:
        state = runs.read_state(run) if run.is_dir() else None
    except Sc2DataError:
        return 0
    return int(state["timesteps"]) if state else 0


def summary_line(run: Path, seconds: float | None = None, since: int = 0) -> str:
    """One line on a trained run: decisions, pysc2 steps, episodes and the last episodes'
    marines (the game's score); with ``seconds``, the decisions per second of this session
    (those trained after ``since``, the count it resumed from)."""
    state = runs.read_state(run) or {"timesteps": 0, "env_steps": 0, "episodes": 0}
    rows = runs.read_curve(run)
    last = [r["marines"] for r in rows[-10:]]
    score = (f"; last {len(last)} training episodes: {np.mean(last):.1f} marines on average"
             if last else "; no episode finished yet")
    done = state["timesteps"] - since
    speed = f"; {done / seconds:,.0f} decisions/s this session" if seconds and done > 0 else ""
    return (f"trained {run}: {state['timesteps']:,} decisions, {state['env_steps']:,} pysc2 "
            f"steps, {state['episodes']} episodes{score}{speed}")


def load_config(run: Path, records: bool = False) -> RLConfig:
    """The settings of a trained run (its ``config.json``), its checkpoint checked by content
    (every reader of a run's model opens it through here). ``records``: a run's record (no
    model, :mod:`sc2data.rl.record`) is read too, else refused in one line."""
    if runs.is_record(run):
        if not records:
            raise Sc2DataError(runs.no_model(run))
    elif not (run / runs.CONFIG).is_file() or not (run / runs.MODEL).is_file():
        raise Sc2DataError(f"{run} is not a trained sc2data rl run (no config.json and "
                           f"model.zip); train one with sc2data rl train --out {run}")
    runs.read_state(run)  # the model (and curve) must be what the last checkpoint recorded
    data = read_config(run)
    cfg = RLConfig(out=str(run), **{k: data[k] for k in CONFIG_SHAPE})
    try:
        check_values(cfg)
    except Sc2DataError as e:
        raise Sc2DataError(f"{run / 'config.json'}: {e}") from None
    return cfg


_MOVED = ("evaluate", "play", "plot", "seed_band", "summary")


def __getattr__(name: str) -> Any:
    """Evaluation and plotting live in :mod:`sc2data.rl.evaluate`; their names still import from
    here (``from sc2data.rl.train import play``)."""
    if name in _MOVED:
        import importlib

        return getattr(importlib.import_module("sc2data.rl.evaluate"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
