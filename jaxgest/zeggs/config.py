"""Configuration of ZeroEGGS (Ghorbani et al. 2023): network sizes, loss weights, training settings.

A preset (:class:`Config`, ``PRESETS[name]`` / :func:`preset`) has three parts:

* :class:`ModelConfig` -- what rebuilds the network and interprets its inputs and outputs: layer sizes,
  the rig (joints, FK parents/offsets; set from the data), frame rate, speech features (their method and
  loudness normalisation: they change the features the network was trained on) and pose input normalisation. A
  checkpoint carries only this part; a resumed run must request the same one.
* :class:`TrainConfig` -- losses and their weights, KL schedule, optimiser, batch, windows, style sampling,
  initial-pose options, augmentation, steps and XLA compiler options. Changing any of it never blocks resuming.
* :class:`InferenceConfig` -- sampling temperature, the shortest style example, compiler options.

Presets (:data:`PRESETS`); change any field with a dotted override
(:func:`jaxgest.runtime.config.apply_overrides`, ``--override model.gru_hidden=128``):

* ``"paper"`` -- the published sizes and training setup (§4.2-4.3) on the paper's 75-joint skeleton (pose
  vector 15j+6 = 1131); about 25.5 M parameters; 120,000 steps.
* ``"small"`` -- the mid-size model of experiments/zeggs_synthetic, which chose its values: speech kernels
  3, 63 (about 1 s of speech), D_e = 64, training window 128 frames, KL schedule, and a fifth of the training
  rows started from the mean pose (``initial_pose_shuffle=0.2``, ``initial_pose_source="mean"``; not the
  paper's); 8,000 steps.
* ``"tiny"`` -- the same architecture with tiny widths and short windows, compiled at XLA optimisation level
  0 (``xla_opt_level``), so tests and ``jaxgest demo --quick`` run in seconds; 300 steps.

Where the paper's text and the authors' public code differ (kept as in the code unless stated): the first
speech conv has kernel 3 (the paper; the code has 1); the style encoder's second conv outputs 2 D_e channels
and the FFT block runs at that width (the code), so ``style_projection=False`` adds no extra layer.

Style sampling (``style_sampling``, docs/design.md §4): ``"overlap"`` (the paper: the style window contains
the target window), ``"disjoint"`` (the default: the same clip, apart from the target) or ``"other-clip"``
(another clip of the same style label, in the target's variant); chosen in experiments/zeggs_synthetic.

Every part is a frozen (hashable, jit-static) dataclass of JSON-friendly fields. ``Config.to_dict()`` is
written to ``config.json`` and :meth:`Config.from_dict` reads it back, including the flat dict of earlier
versions (with :data:`LEGACY_DEFAULTS` for fields those versions did not have, and
:data:`MODEL_ADDED_FIELDS` for model fields added since).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping, Optional

from jaxgest.runtime.config import get_preset
from jaxgest.zeggs.features import PoseLayout

SPEECH_DIM = 81  # 80 log-mel bands + log energy (jaxgest.audio.FEATURE_DIM)


class _Part:
    """What the three config parts share: ``to_dict`` and ``replace``."""

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def replace(self, **kw):
        return dataclasses.replace(self, **kw)


class _Compiled(_Part):
    """A part with an ``xla_opt_level`` field."""

    @property
    def compiler_options(self) -> Optional[dict]:
        """``compiler_options`` for ``jax.jit`` (None: XLA's defaults)."""
        level = self.xla_opt_level
        return None if level is None else {"xla_backend_optimization_level": int(level)}


@dataclasses.dataclass(frozen=True)
class ModelConfig(_Part):
    """What rebuilds the ZeroEGGS networks and interprets their inputs and outputs (stored with checkpoints)."""

    # --- data ---------------------------------------------------------------------------------------
    num_joints: int = 75  # j: joints of the skeleton (the paper's rig has 75); pose_dim = 15 j + 6
    speech_dim: int = SPEECH_DIM  # speech feature channels per frame (80 log-mel + energy)
    facing_dim: int = 3  # target facing direction (ground-plane unit vector in the root frame)
    fps: float = 60.0  # model frame rate; root velocities are integrated with dt = 1 / fps
    loudness: bool = True  # speech loudness-normalised to -20 LUFS (ITU-R BS.1770) before features, as the authors
    input_norm: str = "group"  # pose inputs (style clip, generator's pose state): "group" = one std per feature
    #   group, as the authors (outputs stay per channel); "channel" = the per-channel std of outputs (old)
    fk_parents: tuple[int, ...] = ()  # the rig's parents: position terms by FK of the predicted rotations (():
    #   on the predicted root-frame positions); set from the data by train (features.fk_fields)
    fk_offsets: tuple[float, ...] = ()  # the rig's rest offsets, J * 3 (file units)
    fk_translated: tuple[int, ...] = ()  # joints whose translation the pose sets (root and its chain to the hips)
    # --- speech encoder (§3.1, §4.2) ----------------------------------------------------------------
    speech_channels: tuple[int, ...] = (64, 64)  # output channels of the two Conv1d layers
    speech_kernels: tuple[int, ...] = (3, 31)  # their kernel sizes (receptive field ~ 0.5 s at 60 fps)
    speech_embedding: int = 64  # D_S: framewise linear output size
    speech_dropout: float = 0.2  # dropout after each conv
    # --- style encoder (§3.2, §4.2) -----------------------------------------------------------------
    style_hidden: int = 512  # channels of the first Conv1d (k3)
    style_kernel: int = 3  # kernel size of every style-encoder conv (convs and FFT feed-forward)
    style_embedding: int = 64  # D_e: size of the style embedding e (mu and log sigma^2 each D_e)
    style_dropout: float = 0.2  # dropout after each of the two input convs
    style_heads: int = 4  # heads of the FFT block's self-attention
    style_attention_dropout: float = 0.1  # dropout in and after the self-attention, and after the FF convs
    style_projection: bool = False  # extra Dense to 2 D_e after the FFT block (the code has none)
    style_min_frames: int = 8  # shortest style clip accepted (frames)
    # --- generator (§3.3, §4.2) ---------------------------------------------------------------------
    gru_hidden: int = 1024  # hidden size of each GRU layer, of the pre-GRU linear layer and initializer
    gru_layers: int = 2  # number of stacked GRU layers
    init_hidden: int = 1024  # hidden width of the 3-layer hidden-state initializer
    # --- speech features (appended: fields above keep their order) ---------------------------------
    speech_features: str = "authors"  # jaxgest.audio.speech_features(method=...): "authors" (the authors'
    #   pipeline, which the released speech encoders expect) or "librosa" (models trained before it existed:
    #   a stored config without this field means "librosa", MODEL_ADDED_FIELDS)

    def __post_init__(self):
        if len(self.speech_channels) != len(self.speech_kernels):
            raise ValueError("speech_channels and speech_kernels must have the same length")
        if self.style_embedding * 2 % self.style_heads:
            raise ValueError(f"2 * style_embedding must be divisible by style_heads ({self.style_heads})")
        if self.gru_layers < 1 or self.num_joints < 1:
            raise ValueError("gru_layers and num_joints must be >= 1")
        if self.input_norm not in ("group", "channel"):
            raise ValueError(f"input_norm must be 'group' or 'channel', got {self.input_norm!r}")
        if self.speech_features not in ("authors", "librosa"):
            raise ValueError(f"speech_features must be 'authors' or 'librosa', got {self.speech_features!r}")

    @property
    def layout(self) -> PoseLayout:
        """Slices of the pose vector (see :class:`jaxgest.zeggs.features.PoseLayout`)."""
        return PoseLayout(self.num_joints)

    @property
    def pose_dim(self) -> int:
        """P = 15 j + 6: [local pos 3j | 2-axis rot 6j | vel 3j | ang vel 3j | root vel 3 | root ang 3]."""
        return self.layout.size

    @property
    def style_model_dim(self) -> int:
        """Width of the style encoder's FFT block (2 D_e)."""
        return 2 * self.style_embedding


@dataclasses.dataclass(frozen=True)
class TrainConfig(_Compiled):
    """Losses, KL schedule, optimiser, batches, windows, augmentation, steps and compiler options."""

    # --- losses (eqs. 1-2); weights from the authors' code, mapped onto this feature layout ----------
    w_local_position: float = 15.0  # lambda_p: root-frame joint positions (cm)
    w_world_position: float = 0.1  # lambda_p: world joint positions (cm)
    w_local_rotation: float = 15.0  # lambda_r: root-frame 2-axis rotations
    w_world_rotation: float = 3.0  # lambda_r: world 2-axis rotations
    w_local_velocity: float = 10.0  # lambda_vp: predicted joint velocities, root frame (cm/s)
    w_world_velocity: float = 0.06  # lambda_vp: joint velocities in world space (cm/s)
    w_local_angular: float = 7.0  # lambda_vr: predicted joint angular velocities, root frame (rad/s)
    w_world_angular: float = 1.25  # lambda_vr: joint angular velocities in world space (rad/s)
    w_fd_local_position: float = 7.0  # lambda_dp: finite-difference velocity of root-frame positions
    w_fd_world_position: float = 0.06  # lambda_dp: finite-difference velocity of world positions
    w_fd_local_rotation: float = 8.0  # lambda_dr: finite-difference velocity of root-frame 2-axis rotations
    w_fd_world_rotation: float = 1.25  # lambda_dr: finite-difference velocity of world 2-axis rotations
    w_root_position: float = 0.1  # root position (cm), world
    w_root_rotation: float = 10.0  # root rotation (as a matrix), world
    w_root_velocity: float = 0.1  # root translational velocity, root frame (cm/s)
    w_root_angular: float = 5.0  # root angular velocity, root frame (rad/s)
    w_facing: float = 10.0  # lambda_f: world facing direction of the character root
    w_predicted_position: float = 1.0  # with FK: the predicted root-frame position channels themselves (read back)
    loss_scale: float = 1.0 / 18.0  # the authors divide the sum of their 18 terms (incl. KL) by 18
    kl_center: float = 7500.0  # step at which the logistic KL weight reaches half its asymptote
    kl_growth: float = 0.005  # growth rate of the logistic KL weight (per step)
    kl_cap: float = 0.2  # upper bound of the KL weight
    kl_reduction: str = "mean"  # KL over the D_e dims: "mean" (authors' code) or "sum" (the exact KL)
    # --- optimiser and batches (§4.3) ---------------------------------------------------------------
    learning_rate: float = 1e-4  # RAdam learning rate
    lr_decay: float = 0.995  # multiplicative decay ...
    lr_decay_steps: int = 1000  # ... applied every this many steps (staircase)
    batch_size: int = 32  # sequences per batch
    window: int = 256  # T: frames per target sequence
    style_window_min: int = 256  # M: shortest style window (frames)
    style_window_max: int = 512  # longest style window (frames); batches pad to this with a mask
    style_sampling: str = "disjoint"  # where a training style window comes from (jaxgest.zeggs.data.style_window):
    #   "overlap" (the paper: contains the target), "disjoint" (same clip, apart from the target) or
    #   "other-clip" (another clip of the same style label); chosen in experiments/zeggs_synthetic
    initial_pose_shuffle: float = 0.0  # probability that a training row starts the generator from another
    #   row's first pose (the previous row of the batch) instead of its own; 0 = the paper (always its own).
    #   Not in the paper (jaxgest.zeggs.steps.initial_poses); small's 0.2 chosen in experiments/zeggs_synthetic
    initial_pose_source: str = "row"  # what a shuffled row starts from: "row" (the previous row's first pose)
    #   or "mean" (the data's mean pose: zeros of the normalised features)
    initial_pose_mask_seconds: float = 0.0  # seconds at the start of a shuffled row left out of its
    #   reconstruction loss (the move from the replaced pose to the target's has no target of its own)
    speed_augmentation: float = 0.1  # +-10 % speed changes of whole sequences (data pipeline)
    mirror: bool = True  # add mirrored sequences (data pipeline)
    exclude_styles: tuple[str, ...] = ()  # style labels left out of training (leave-one-style-out, the zero-shot
    #   claim: jaxgest.zeggs.claims); their clips stay in the data folder for examples and evaluation
    steps: int = 120_000  # default number of training steps (the authors')
    # --- compilation ----------------------------------------------------------------------------------
    xla_opt_level: Optional[int] = None  # XLA backend optimisation level of the jitted training functions
    #   (None: XLA's default; 0 compiles faster and runs slower: for tiny models and short runs)

    def __post_init__(self):
        if self.kl_reduction not in ("mean", "sum"):
            raise ValueError(f"kl_reduction must be 'mean' or 'sum', got {self.kl_reduction!r}")
        if not self.style_window_min <= self.style_window_max:
            raise ValueError("style_window_min must be <= style_window_max")
        if not 0.0 <= self.initial_pose_shuffle <= 1.0:
            raise ValueError(f"initial_pose_shuffle must be in [0, 1], got {self.initial_pose_shuffle}")
        if self.initial_pose_source not in ("row", "mean"):
            raise ValueError(f"initial_pose_source must be 'row' or 'mean', got {self.initial_pose_source!r}")
        if self.initial_pose_mask_seconds < 0.0:
            raise ValueError(f"initial_pose_mask_seconds must be >= 0, got {self.initial_pose_mask_seconds}")
        if self.style_sampling not in ("overlap", "disjoint", "other-clip"):
            raise ValueError(f"style_sampling must be 'overlap', 'disjoint' or 'other-clip', got {self.style_sampling!r}")


@dataclasses.dataclass(frozen=True)
class InferenceConfig(_Compiled):
    """Generation settings that do not change the trained model."""

    temperature: float = 1.0  # default sampling temperature of the style embedding
    min_style_seconds: float = 0.5  # the shortest style example accepted
    xla_opt_level: Optional[int] = None  # XLA backend optimisation level of the jitted inference functions


_PARTS = {"model": ModelConfig, "train": TrainConfig, "inference": InferenceConfig}
_FIELDS = {part: {f.name for f in dataclasses.fields(cls)} for part, cls in _PARTS.items()}

# Fields of the flat config of earlier versions that were added after models had been trained with the old
# behaviour: a flat config.json without one was trained with this value (the dataclass default is the new one).
LEGACY_DEFAULTS = {"loudness": False, "input_norm": "channel", "speech_features": "librosa"}
# Model fields added after the three-part config.json existed: a stored model section (config.json or a
# checkpoint's meta) without one was trained with this value.
MODEL_ADDED_FIELDS = {"speech_features": "librosa"}


def _tuples(d: Mapping[str, Any]) -> dict:
    return {k: tuple(v) if isinstance(v, list) else v for k, v in d.items()}


@dataclasses.dataclass(frozen=True)
class Config:
    """A preset: the model, training and inference parts together (``name`` is informational)."""

    model: ModelConfig = ModelConfig()
    train: TrainConfig = TrainConfig()
    inference: InferenceConfig = InferenceConfig()
    name: str = "paper"

    def to_dict(self) -> dict:
        return {"name": self.name, **{part: getattr(self, part).to_dict() for part in _PARTS}}

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Config":
        """Inverse of :meth:`to_dict` (JSON lists become tuples; unknown fields rejected; missing ones take
        the defaults). A flat dict (one ``ZeggsConfig`` of an earlier version) is split field by field, and a
        field it lacks from :data:`LEGACY_DEFAULTS` takes its old value."""
        if not isinstance(d.get("model"), Mapping):  # the flat layout of earlier versions
            return cls.from_flat({**{k: v for k, v in LEGACY_DEFAULTS.items() if k not in d}, **d})
        unknown = set(d) - {"name", *_PARTS}
        if unknown:
            raise ValueError(f"unknown ZeroEGGS config sections: {sorted(unknown)}")
        parts = {}
        for part, kind in _PARTS.items():
            section = dict(d.get(part) or {})
            if part == "model":
                section = {**{k: v for k, v in MODEL_ADDED_FIELDS.items() if k not in section}, **section}
            bad = set(section) - _FIELDS[part]
            if bad:
                raise ValueError(f"unknown ZeroEGGS {part} config fields: {sorted(bad)}")
            parts[part] = kind(**_tuples(section))
        return cls(name=str(d.get("name", "paper")), **parts)

    @classmethod
    def from_flat(cls, d: Mapping[str, Any], base: Optional["Config"] = None) -> "Config":
        """``base`` (default: the default Config) with the flat fields of ``d`` routed to their part
        (``xla_opt_level`` to training and inference, ``name`` to the name); unknown fields rejected."""
        return (base or cls()).override(**_tuples(d))

    def override(self, **fields) -> "Config":
        """A copy with fields replaced by their bare names (``gru_hidden=128``, ``learning_rate=3e-4``)."""
        unknown = set(fields) - {"name"} - set().union(*_FIELDS.values())
        if unknown:
            raise ValueError(f"unknown ZeroEGGS config fields: {sorted(unknown)}")
        parts = {part: getattr(self, part).replace(**{k: v for k, v in fields.items() if k in _FIELDS[part]})
                 for part in _PARTS}
        return dataclasses.replace(self, name=fields.get("name", self.name), **parts)


def field_names() -> dict[str, set]:
    """The field names of each part (``{"model": {...}, "train": {...}, "inference": {...}}``)."""
    return {part: set(names) for part, names in _FIELDS.items()}


def _preset(name, model: dict, train: dict, xla_opt_level=None) -> Config:
    return Config(ModelConfig(**model), TrainConfig(**train, xla_opt_level=xla_opt_level),
                  InferenceConfig(xla_opt_level=xla_opt_level), name=name)


PRESETS: dict[str, Config] = {
    "paper": Config(),
    "tiny": _preset(
        "tiny",
        dict(num_joints=5, speech_channels=(16, 16), speech_kernels=(3, 5), speech_embedding=8, style_hidden=16,
             style_embedding=8, style_heads=2, gru_hidden=32, init_hidden=32, style_min_frames=4),
        dict(kl_center=50.0, kl_growth=0.1, learning_rate=1e-3, lr_decay_steps=100, batch_size=4, window=32,
             style_window_min=32, style_window_max=48, steps=300),
        xla_opt_level=0),
    "small": _preset(
        "small",
        dict(num_joints=21, speech_channels=(32, 32), speech_kernels=(3, 63), speech_embedding=16, style_hidden=64,
             style_embedding=64, style_heads=2, gru_hidden=128, init_hidden=128, style_min_frames=4),
        dict(kl_center=1000.0, kl_growth=0.005, learning_rate=1e-3, lr_decay_steps=100, batch_size=16, window=128,
             style_window_min=64, style_window_max=128, steps=8000,
             initial_pose_shuffle=0.2, initial_pose_source="mean")),
}


def preset(name: str = "paper", **fields) -> Config:
    """The preset ``name`` of :data:`PRESETS` (an unknown name: a one-line error listing them), optionally
    with fields replaced by their bare names (:meth:`Config.override`; how the data's rig is set). Users
    change fields with dotted overrides (:func:`jaxgest.runtime.config.apply_overrides`)."""
    cfg = get_preset(PRESETS, name, "ZeroEGGS")
    return cfg.override(**fields) if fields else cfg
