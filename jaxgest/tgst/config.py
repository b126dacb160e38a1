"""Configuration of tokenized gesture style transfer (Kuriyama et al. 2022): model, training, inference.

A preset (:class:`Config`, ``PRESETS[name]`` / :func:`preset`) is three frozen dataclasses:

* :class:`ModelConfig` -- what the trained networks are: the autoencoder and transformer sizes
  (:class:`AutoencoderConfig`, :class:`TransformerConfig`), the model frame rate, token width/stride, clip
  padding (``edge_frames``) and the soft swap (similarity and temperature). Checkpoints store and check only
  this (:meth:`ModelConfig.autoencoder_dict` for the autoencoder, all of it for the transformer), so a
  training or inference setting never blocks a resume or a transfer.
* :class:`TrainConfig` -- how each stage is trained, step counts included: :class:`AutoencoderTrainConfig`
  and :class:`TransformerTrainConfig` (optimiser, schedule, batch, window, sampling, the loss weights and
  switches of eq. 12).
* :class:`InferenceConfig` -- settings used only when transferring.

The swap temperature is a model setting: the same soft swap is used inside the training losses (eqs. 5-8),
so the transformer is fitted to one temperature.

Presets (:data:`PRESETS`); change any field with a dotted override
(:func:`jaxgest.runtime.config.apply_overrides`, ``--override train.autoencoder.learning_rate=3e-4``):

* ``"paper"`` -- the published sizes and training setup (App. A, §3.3-3.5): autoencoder 23,743 parameters,
  transformer 50,240; pre-LN, band mask, sinusoidal token positions; clips replicate-padded by 16 frames at
  both ends (docs/design.md §3); 10,000 + 10,000 steps.
* ``"fit-motion"`` -- the recommended preset for real data: the paper's networks plus, none of it in the
  paper, standardised autoencoder channels, a lapped linear path started in closed form, content-balanced
  windows, tokens without positions, and a loss for motion quality (frame-to-frame and joint-displacement
  terms, trunk weight, leg targets on the branch nearest the rest pose); 500 + 10,000 steps. Each value was
  chosen in experiments/tgst_bandai (sections 2, 2c, 2f).
* ``"tiny"`` -- the paper's networks with short windows, small batches and Adam 1e-3, so tests and
  ``jaxgest demo --quick`` train in seconds; 200 + 200 steps. Not the paper's training setup.

Training windows are scaled to the data (:func:`jaxgest.tgst.data.fit_windows`); the windows used are
stored in the workdir's config.json. Every config is a frozen (hashable, a valid jit static argument)
dataclass of JSON-friendly fields: ``cfg.to_dict()`` is stored in config.json and :meth:`Config.from_dict`
rebuilds it -- also from the flat config of older workdirs (:func:`legacy_to_dict`).
"""

from __future__ import annotations

import dataclasses
from typing import Any, Mapping

from jaxgest.runtime.config import get_preset

VARIANTS = ("paper", "authors")
ATTENTION_IMPLS = ("blockwise", "dense")
TOKEN_POSITIONS = ("index", "none")
SWAP_SIMILARITIES = ("dot", "scaled")
AE_LR_SCHEDULES = ("constant", "cosine")
AE_SAMPLINGS = ("windows", "content")
POSITION_VELOCITY_JOINTS = ("all", "upper")  # joints of the optional joint-displacement term
EXPMAP_BRANCHES = ("principal", "rest")  # branch of the training targets' exp-maps (body.nearest_branch)
#: the style clip a transfer gives the model (``style_input=``, ``--style-input``): ``"mirror"`` (default) the
#: exemplar followed by its mirror (the input of the experiments' results), ``"as-is"`` the exemplar itself;
#: built by :func:`jaxgest.tgst.protocol.style_input_clip`
STYLE_INPUTS = ("mirror", "as-is")
TRANSFORMER_STYLE_TOKENS = ("window", "clip_and_mirror")  # TransformerTrainConfig.style_tokens
# InferenceConfig.method (tgst.model.METHODS)
METHODS = ("soft", "hard", "adain", "avatarnet", "coherent", "autoencoder")


@dataclasses.dataclass(frozen=True)
class AutoencoderConfig:
    """Conv1d autoencoder over time (Kuriyama et al. 2022, App. A). Layout (batch, frames, channels)."""

    upper_channels: int = 39  # input/output exp-map channels of the 13 upper-body joints
    lower_channels: int = 24  # output exp-map channels of the 8 lower-body joints
    encoder_channels: tuple[int, ...] = (64, 32, 16)  # conv widths; the last one is the latent size d_z
    encoder_kernels: tuple[int, ...] = (1, 3, 3)  # kernel widths of the encoder convs
    encoder_strides: tuple[int, ...] = (1, 2, 2)  # strides (PyTorch padding = kernel // 2)
    upper_decoder_channels: tuple[int, ...] = (32, 64)  # hidden widths of the upper decoder (-> 39)
    lower_decoder_channels: tuple[int, ...] = (16, 32)  # hidden widths of the lower decoder (-> 24)
    decoder_kernels: tuple[int, ...] = (3, 3, 1)  # kernel widths of the three decoder convs
    decoder_upsample: tuple[int, ...] = (2, 2, 1)  # linear x2 upsampling before each decoder conv (1 = none)
    # per-channel standardisation: the encoder sees (x - mean) / std and the decoders predict mean + std * y,
    # with the training data's statistics stored as (frozen) parameters; False = the paper's raw exp-maps
    standardize: bool = False
    # GELU after the last encoder conv, i.e. on the latent itself (True: the paper's/authors' code); False
    # leaves the latent linear (GELU is bounded below at -0.17: negative latent values are squashed)
    latent_activation: bool = True
    # a block-linear path beside the conv stacks (not in the paper): the encoder adds a linear map of each
    # non-overlapping block of ``time_reduction`` frames to the latent, each decoder adds a linear map of
    # each latent frame back to its block; initialised to the block PCA of the training data (train.py:
    # ``AutoencoderTrainConfig.pca_init``) with the conv stacks' last layers zeroed, so training starts at
    # the PCA reconstruction and the convs learn the non-linear remainder
    linear_path: bool = False
    # latent frames on each side the linear path also uses (not in the paper): 0 = non-overlapping blocks;
    # c > 0 = lapped: the linear encoder reads c blocks on each side too and each decoder maps
    # latent frames t - c .. t + c to block t, initialised by least squares (autoencoder.init_linear_path)
    linear_context: int = 0

    @property
    def latent_dim(self) -> int:
        return self.encoder_channels[-1]

    @property
    def time_reduction(self) -> int:
        """Frames per latent frame (4 for the paper)."""
        r = 1
        for s in self.encoder_strides:
            r *= s
        return r


@dataclasses.dataclass(frozen=True)
class TransformerConfig:
    """Style transformer (Kuriyama et al. 2022, §3.4): one encoder block, one decoder block, single head."""

    token_dim: int = 64  # d_g = w * d_z
    omega: int = 20  # band half-width of the encoder self-attention mask (in tokens)
    variant: str = "paper"  # "paper" (pre-LN, |i-j| <= omega) or "authors" (public code; see transformer.py)
    layernorms_per_block: int = 1  # 1 = one LN shared by both residuals (50,240 params); 2 = two (50,496)
    attention_impl: str = "blockwise"  # "blockwise": O(N * omega) banded attention; "dense": masked reference
    block_size: int = 32  # query block length of the blockwise attention; must be >= omega
    max_authors_pe: int = 150  # authors' variant: length of the positional table (indexed by batch, a bug)
    # paper variant: "index" adds sinusoidal positions over the token index (eq. 2 read literally; the swap
    # can then match by position), "none" adds none (the tokens carry no position, as in the authors' code,
    # whose table is added along the batch axis); the band mask still limits attention to neighbours
    token_positions: str = "index"


@dataclasses.dataclass(frozen=True)
class ModelConfig:
    """What a trained TGST model is: the networks, the data representation and the swap."""

    fps: float = 60.0  # model frame rate: every clip is resampled to it (the paper's capture rate, §4.1)
    autoencoder: AutoencoderConfig = AutoencoderConfig()  # motion <-> latent autoencoder
    transformer: TransformerConfig = TransformerConfig()  # token encoder/decoder
    token_width: int = 4  # w: latent frames per gesture token (eq. 1)
    token_stride: int = 2  # h = w / 2: stride between tokens (half overlap, eq. 1)
    min_frames: int = 16  # shortest clip accepted (one token = w * 4 = 16 frames)
    frame_multiple: int = 16  # clips are padded at the end to a multiple of this many frames
    # replicate-pad every clip by this many frames at BOTH ends before encoding and trim after decoding
    # (docs/design.md §3, clip ends); a multiple of the encoder's total stride. 0 = the end-only padding of old runs
    edge_frames: int = 0
    swap_temperature: float = 1.0  # softmax temperature of the soft swap (1 = eq. 4; also used in training)
    # similarity of the swap: "dot" = plain dot product (eq. 4 as printed); "scaled" = both sides
    # LayerNorm-ed (no parameters) and divided by sqrt(d_g) before the temperature
    swap_similarity: str = "dot"

    def __post_init__(self):
        t = self.transformer
        if t.variant not in VARIANTS:
            raise ValueError(f"transformer.variant must be one of {VARIANTS}, got {t.variant!r}")
        if t.attention_impl not in ATTENTION_IMPLS:
            raise ValueError(
                f"transformer.attention_impl must be one of {ATTENTION_IMPLS}, got {t.attention_impl!r}")
        if t.layernorms_per_block not in (1, 2):
            raise ValueError(f"transformer.layernorms_per_block must be 1 or 2, got {t.layernorms_per_block}")
        if t.block_size < max(t.omega, 1):
            raise ValueError(f"transformer.block_size ({t.block_size}) must be >= omega ({t.omega})")
        if self.token_width != 2 * self.token_stride:
            raise ValueError("token_width must be twice token_stride (half-overlapping tokens, eq. 1)")
        if t.token_dim != self.token_width * self.autoencoder.latent_dim:
            raise ValueError(f"transformer.token_dim must be token_width * latent_dim = "
                             f"{self.token_width * self.autoencoder.latent_dim}, got {t.token_dim}")
        for name, value, allowed in (("transformer.token_positions", t.token_positions, TOKEN_POSITIONS),
                                     ("swap_similarity", self.swap_similarity, SWAP_SIMILARITIES)):
            if value not in allowed:
                raise ValueError(f"{name} must be one of {allowed}, got {value!r}")
        step = self.autoencoder.time_reduction * self.token_stride
        if self.edge_frames < 0 or self.edge_frames % step:
            raise ValueError(f"edge_frames must be a non-negative multiple of {step} (encoder stride x token "
                             f"stride, so tokens start at the clip's first frame), got {self.edge_frames}")
        if self.frame_multiple % step:
            raise ValueError("frame_multiple must be a multiple of time_reduction * token_stride")

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    def autoencoder_dict(self) -> dict:
        """The fields the trained autoencoder depends on (its checkpoint's config): its sizes, the frame rate
        and the clip padding it was trained with. A stage-1 checkpoint is shared by runs that differ only in
        the transformer, the swap or the training settings (the loss ablations of Table 4 reuse one)."""
        d = self.to_dict()
        return {k: d[k] for k in AUTOENCODER_FIELDS}


#: the ModelConfig fields an autoencoder checkpoint stores and checks (:meth:`ModelConfig.autoencoder_dict`)
AUTOENCODER_FIELDS = ("fps", "autoencoder", "min_frames", "frame_multiple", "edge_frames")


@dataclasses.dataclass(frozen=True)
class AutoencoderTrainConfig:
    """Training of stage 1, the motion autoencoder (§3.5)."""

    steps: int = 10_000  # training steps (about the paper's 1000 epochs of its AE data in batches of 32)
    learning_rate: float = 1e-4  # Adam learning rate (§3.5)
    batch_size: int = 32  # windows per batch (§3.5)
    window: int = 256  # training window in frames (§3.5)
    lr_schedule: str = "constant"  # "constant" (§3.5) or "cosine" (warm-up, cosine decay to 10 %)
    lr_decay_steps: int = 10_000  # length of the cosine schedule (steps); constant lr afterwards
    sampling: str = "windows"  # "windows": uniform over all windows; "content": each content label equally
    mirror: bool = True  # the autoencoder also sees the mirrored clips (False: the original clips only)
    # with ``AutoencoderConfig.linear_path``: start from the block PCA of the training clips (True) or from
    # the random initialisation (False, an ablation)
    pca_init: bool = True
    # weight of the frame-to-frame difference term (autoencoder.expmap_velocity_loss) added to the training
    # loss (not in the paper); 0 = the paper's loss only
    velocity_weight: float = 0.0
    # weight of the joint-displacement term (autoencoder.position_velocity_loss, cm per frame, forward kinematics
    # of the canonical body) added to the training loss (not in the paper); 0 = off
    position_velocity_weight: float = 0.0
    position_velocity_joints: str = "all"  # joints of that term: "all" 21, "upper" the 13 upper-body joints
    # extra weight of the trunk joints (autoencoder.TRUNK_JOINTS: Hips, Spine, Chest; their rotations move
    # everything above them) in the reconstruction term and, with velocity_weight, in the frame-to-frame
    # term (not in the paper): the loss adds (trunk_weight - 1) x the trunk-only terms; 1 = off
    trunk_weight: float = 1.0
    # weight of the squared frame-to-frame differences in the least-squares start of a lapped linear path
    # (``AutoencoderConfig.linear_context`` > 0; autoencoder.lapped_decoder_fit): larger = smoother start
    init_velocity_weight: float = 0.0
    # lower-body exp-maps of the training clips (the lower decoder's targets, never an input): "principal"
    # (|v| <= pi, the paper's) or "rest": each joint on the branch nearest the canonical rest pose
    # (body.nearest_branch; not in the paper), continuous for joints resting at ~pi (the Bandai-Namco upper
    # legs). Outputs are written as rotations either way, so inference does not depend on it
    expmap_branch: str = "principal"

    def __post_init__(self):
        for name, value, allowed in (("lr_schedule", self.lr_schedule, AE_LR_SCHEDULES),
                                     ("expmap_branch", self.expmap_branch, EXPMAP_BRANCHES),
                                     ("sampling", self.sampling, AE_SAMPLINGS),
                                     ("position_velocity_joints", self.position_velocity_joints, POSITION_VELOCITY_JOINTS)):
            if value not in allowed:
                raise ValueError(f"train.autoencoder.{name} must be one of {allowed}, got {value!r}")
        if not self.trunk_weight >= 1.0:
            raise ValueError(f"train.autoencoder.trunk_weight must be >= 1 (1 = off), got {self.trunk_weight}")


@dataclasses.dataclass(frozen=True)
class TransformerTrainConfig:
    """Training of stage 2, the style transformer with the autoencoder frozen (§3.5, eq. 12)."""

    steps: int = 10_000  # training steps (about the paper's 1000 epochs of its 63 pairs in batches of 8)
    learning_rate: float = 1e-4  # Adam learning rate (§3.5)
    batch_size: int = 8  # content/style pairs per batch (§3.5)
    window: int = 1280  # frames per content training window (§3.5; and per style window with "window")
    # style token set of a training pair: "window" = a random window of another clip (mirrored with
    # probability 0.5); "clip_and_mirror" = that clip whole followed by its mirror (0.5 s blend), one set of
    # tokens, as the authors' trainer (``setup_style_tokens``); padded to length buckets with a mask
    style_tokens: str = "window"
    style_max_frames: int = 1024  # "clip_and_mirror": longer style clips give a random window this long (0 = no cap)
    style_bucket: float = 1.6  # "clip_and_mirror": length-bucket ratio of the padded style sets (3 shapes here)
    style_transition_seconds: float = 0.5  # "clip_and_mirror": blend into the mirror (their 30 frames at 60 fps)
    lambda_identity: float = 1.0  # weight of L_identity (eq. 12 fixes it to 1; settable for ablations)
    lambda_cyclic: float = 1.0  # lambda_c of eq. 12
    lambda_structure: float = 1.0  # lambda_s of eq. 12
    lambda_appearance: float = 1.0  # lambda_a of eq. 12
    use_identity: bool = True  # switch L_identity on/off (ablation, Table 4)
    use_cyclic: bool = True  # switch L_cyclic on/off
    use_structure: bool = True  # switch L_structure on/off
    use_appearance: bool = True  # switch L_appearance on/off

    def __post_init__(self):
        if self.style_tokens not in TRANSFORMER_STYLE_TOKENS:
            raise ValueError(f"train.transformer.style_tokens must be one of {TRANSFORMER_STYLE_TOKENS}, "
                             f"got {self.style_tokens!r}")
        if self.style_max_frames < 0 or not self.style_bucket >= 1.0 or self.style_transition_seconds < 0:
            raise ValueError("train.transformer: style_max_frames >= 0, style_bucket >= 1 and "
                             "style_transition_seconds >= 0 required")


@dataclasses.dataclass(frozen=True)
class TrainConfig:
    """Training of both stages."""

    autoencoder: AutoencoderTrainConfig = AutoencoderTrainConfig()
    transformer: TransformerTrainConfig = TransformerTrainConfig()


@dataclasses.dataclass(frozen=True)
class InferenceConfig:
    """Settings used only at transfer time (no effect on training or checkpoints)."""

    method: str = "soft"  # default transfer method: the soft swap of eq. 4 (see tgst.model.METHODS)
    bucket: float = 1.25  # length-bucket ratio of batched evaluation transfers (1 = exact shapes)

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"inference.method must be one of {METHODS}, got {self.method!r}")
        if not self.bucket >= 1.0:
            raise ValueError(f"inference.bucket must be >= 1, got {self.bucket}")


@dataclasses.dataclass(frozen=True)
class Config:
    """A preset: the model, how to train it and how to run it."""

    name: str = "paper"  # preset name, informational
    model: ModelConfig = ModelConfig()
    train: TrainConfig = TrainConfig()
    inference: InferenceConfig = InferenceConfig()

    def to_dict(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> "Config":
        """Inverse of :meth:`to_dict` (JSON lists become tuples again); a flat config of a workdir written
        before the split is mapped first (:func:`legacy_to_dict`). Absent fields take their defaults."""
        if is_legacy(d):
            d = legacy_to_dict(d)
        return _build(cls, d)


def _build(cls, m: Mapping[str, Any]):
    kwargs = {}
    hints = {f.name: f for f in dataclasses.fields(cls)}
    for name, f in hints.items():
        if name not in m:
            continue
        v = m[name]
        default = f.default
        if dataclasses.is_dataclass(default):
            v = _build(type(default), v)
        elif isinstance(v, list):
            v = tuple(v)
        kwargs[name] = v
    return cls(**kwargs)


def model_config_from_dict(d: Mapping[str, Any]) -> ModelConfig:
    """A :class:`ModelConfig` from its :meth:`~ModelConfig.to_dict` (absent fields: defaults)."""
    return _build(ModelConfig, d)


def is_legacy(d: Mapping[str, Any]) -> bool:
    """Whether ``d`` is the flat config of the versions before the model/train/inference split."""
    return not isinstance(d.get("model"), Mapping)


#: legacy flat field -> (section, stage or None, new field)
_LEGACY_TRAIN = {
    "ae_learning_rate": ("autoencoder", "learning_rate"), "ae_batch_size": ("autoencoder", "batch_size"),
    "ae_window": ("autoencoder", "window"), "ae_lr_schedule": ("autoencoder", "lr_schedule"),
    "ae_lr_decay_steps": ("autoencoder", "lr_decay_steps"), "ae_sampling": ("autoencoder", "sampling"),
    "ae_mirror": ("autoencoder", "mirror"),
    "transformer_learning_rate": ("transformer", "learning_rate"),
    "transformer_batch_size": ("transformer", "batch_size"), "transformer_window": ("transformer", "window"),
    **{f"{p}_{t}": ("transformer", f"{p}_{t}") for p in ("lambda", "use")
       for t in ("identity", "cyclic", "structure", "appearance")},
}


def legacy_to_dict(flat: Mapping[str, Any]) -> dict:
    """The flat config dict of older workdirs (one ``TGSTConfig``) in the layout of :meth:`Config.to_dict`.

    A field the old dict lacks (it predates the field) is left out, so it takes its class default -- the
    behaviour of the version that wrote it (e.g. ``edge_frames`` 0, ``swap_similarity`` "dot").
    """
    model_fields = {f.name for f in dataclasses.fields(ModelConfig)}
    out = {"model": {}, "train": {"autoencoder": {}, "transformer": {}}}
    for k, v in flat.items():
        if k == "name":
            out["name"] = v
        elif k in model_fields:
            out["model"][k] = v
        elif k in _LEGACY_TRAIN:
            stage, field = _LEGACY_TRAIN[k]
            out["train"][stage][field] = v
    return out


def _tiny() -> Config:
    return Config(
        name="tiny",
        model=ModelConfig(edge_frames=16),
        train=TrainConfig(
            autoencoder=AutoencoderTrainConfig(steps=200, learning_rate=1e-3, batch_size=4, window=64,
                                               expmap_branch="rest"),
            transformer=TransformerTrainConfig(steps=200, learning_rate=1e-3, batch_size=4, window=128)),
    )


def _fit_motion() -> Config:
    """The recommended real-data preset; the experiment that chose each value in experiments/tgst_bandai."""
    return Config(
        name="fit-motion",
        model=ModelConfig(
            edge_frames=16,
            transformer=TransformerConfig(token_positions="none"),  # section 4
            autoencoder=AutoencoderConfig(standardize=True,  # section 2
                                          linear_path=True,  # section 2b
                                          linear_context=1)),  # section 2c
        train=TrainConfig(autoencoder=AutoencoderTrainConfig(
            steps=500, lr_decay_steps=500,  # section 2f
            learning_rate=3e-4, init_velocity_weight=64.0, velocity_weight=10.0,  # section 2c
            lr_schedule="cosine", sampling="content",  # section 2
            position_velocity_weight=0.15,  # section 2d
            trunk_weight=4.0,  # section 2e
            expmap_branch="rest")),  # section 2f
    )


#: every preset by name: the published setup, the recommended real-data preset, the fast one for tests
PRESETS: dict[str, Config] = {
    "paper": Config(name="paper", model=ModelConfig(edge_frames=16)),
    "fit-motion": _fit_motion(),
    "tiny": _tiny(),
}


def preset(name: str = "paper") -> Config:
    """The preset ``name`` of :data:`PRESETS` (an unknown name: a one-line error listing them)."""
    return get_preset(PRESETS, name, "TGST")
