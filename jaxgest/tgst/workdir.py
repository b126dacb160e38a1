"""A TGST workdir on disk: its config.json, the checkpoint folders of both stages, restoring a model.

Layout (written by :func:`jaxgest.tgst.trainer.train`)::

    config.json                      {"model": "tgst", "preset", "config": Config.to_dict(), "data", ...}
    metrics.jsonl                    one line per log step: {"stage", "step", "loss", ..., "devices", ...}
    checkpoints/autoencoder/<step>   orbax {params, opt_state, step} + meta (kind tgst_autoencoder)
    checkpoints/transformer/<step>   the same for the transformer (kind tgst_transformer)

Each checkpoint carries and checks only the *model* config (:class:`~jaxgest.tgst.config.ModelConfig`) and
the body signature: the autoencoder's :meth:`~jaxgest.tgst.config.ModelConfig.autoencoder_dict`, the
transformer's whole model config plus the autoencoder step it was trained on. Training and inference
settings can change between runs of one workdir. Workdirs written before the model/train/inference split
(a flat config in config.json and in the checkpoints' meta; ``"kind": "tgst"``) are read through
:func:`jaxgest.tgst.config.legacy_to_dict`, so they still load for transfer.

Imported by both training (:mod:`jaxgest.tgst.trainer`) and inference (:mod:`jaxgest.tgst.api`).
"""

from __future__ import annotations

import pathlib
from typing import Mapping, Optional, Union

import jax

from jaxgest.runtime.checkpoint import Checkpointer
from jaxgest.runtime.workdir_format import check_workdir_config
from jaxgest.runtime.errors import CheckpointError
from jaxgest.tgst import data as tdata
from jaxgest.tgst.config import Config, ModelConfig, legacy_to_dict, model_config_from_dict

MODEL = "tgst"  # config.json's "model"
AE_KIND, TRANSFORMER_KIND = "tgst_autoencoder", "tgst_transformer"
AE_SUBDIR, TRANSFORMER_SUBDIR = "checkpoints/autoencoder", "checkpoints/transformer"


def _model(cfg: Union[ModelConfig, Config]) -> ModelConfig:
    return cfg.model if isinstance(cfg, Config) else cfg


def _stored_model(stored: Mapping) -> ModelConfig:
    """The model config in a checkpoint's stored config: a model dict, or the flat config of older versions
    (recognised by its preset ``name``, which a model config does not have)."""
    if "name" in stored:  # the whole flat TGSTConfig of the versions before the split
        return model_config_from_dict(legacy_to_dict(stored)["model"])
    return model_config_from_dict({k: v for k, v in stored.items() if k != "autoencoder_step"})


#: autoencoder fields added after checkpoints were written, with the value that is the older behaviour: a
#: checkpoint without one is read with it (same parameters, same outputs), not rejected as another layout
ADDED_AUTOENCODER_FIELDS = {"latent_activation": True, "linear_path": False, "linear_context": 0}


def _with_added_fields(stored: Mapping) -> dict:
    d = dict(stored)
    if isinstance(d.get("autoencoder"), Mapping):
        d["autoencoder"] = {**ADDED_AUTOENCODER_FIELDS, **d["autoencoder"]}
    return d


def _read_ae_config(stored: Mapping) -> dict:
    return _stored_model(stored).autoencoder_dict() if "name" in stored else _with_added_fields(stored)


def _read_transformer_config(stored: Mapping) -> dict:
    if "name" not in stored:
        return _with_added_fields(stored)
    return dict(_stored_model(stored).to_dict(), autoencoder_step=stored.get("autoencoder_step"))


def ae_checkpointer(workdir, cfg: Union[ModelConfig, Config], read_only: bool = False) -> Checkpointer:
    """The autoencoder stage's checkpoints; checks ``cfg``'s :meth:`~ModelConfig.autoencoder_dict`."""
    return Checkpointer(workdir, kind=AE_KIND, config=_model(cfg).autoencoder_dict(),
                        skeleton=tdata.BODY_SIGNATURE, subdir=AE_SUBDIR, read_only=read_only, ignore=(),
                        read_config=_read_ae_config)


def transformer_checkpointer(workdir, cfg: Union[ModelConfig, Config], ae_step: Optional[int],
                             read_only: bool = False) -> Checkpointer:
    """The transformer stage's checkpoints; checks the whole model config and the autoencoder step it was
    trained on (``ae_step=None``: any, for reading)."""
    config = dict(_model(cfg).to_dict(), autoencoder_step=ae_step)
    return Checkpointer(workdir, kind=TRANSFORMER_KIND, config=config, skeleton=tdata.BODY_SIGNATURE,
                        subdir=TRANSFORMER_SUBDIR, read_only=read_only,
                        ignore=() if ae_step is not None else ("autoencoder_step",),
                        read_config=_read_transformer_config)


def read_config(workdir) -> Config:
    """The :class:`Config` a workdir was trained with (its config.json; the flat layout of older versions is
    mapped). One-line :class:`CheckpointError` when there is none, it is unreadable or names another model."""
    workdir = pathlib.Path(workdir)
    path = workdir / "config.json"
    if not path.is_file():
        raise CheckpointError(f"{workdir}: not a TGST workdir (no config.json; run 'jaxgest tgst train' first)")
    try:
        stored = check_workdir_config(workdir)  # one line for an unreadable, newer or unknown config.json
        model = stored.get("model", stored.get("kind", MODEL))  # "kind": the name in older versions
        if model != MODEL:
            raise CheckpointError(f"{workdir}: a {model} workdir, not a TGST one (train one with 'jaxgest tgst "
                                  "train')")
        return Config.from_dict(stored["config"])
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise CheckpointError(f"{path}: unreadable TGST config ({type(e).__name__}: {e})") from None


def restore_params(workdir, cfg: ModelConfig) -> tuple[dict, dict]:
    """The newest readable parameters of both stages, ``({"autoencoder", "transformer"}, {stage: step})``."""
    from jaxgest.tgst.model import init_params

    template = jax.eval_shape(lambda k: init_params(cfg, k), jax.random.key(0))  # shapes only
    with ae_checkpointer(workdir, cfg, read_only=True) as ck:
        ae = ck.restore_params(template["autoencoder"])
        ae_step = ck.restored_step
    with transformer_checkpointer(workdir, cfg, None, read_only=True) as ck:
        tr = ck.restore_params(template["transformer"])
        tr_step = ck.restored_step
    return {"autoencoder": ae, "transformer": tr}, {"autoencoder": ae_step, "transformer": tr_step}


def check_existing(ckpt: Checkpointer) -> None:
    """Raise :class:`CheckpointError` when ``ckpt``'s folder holds a checkpoint of another model."""
    stored = ckpt.stored_meta()
    if stored is not None:
        ckpt.check_meta(stored)


def stored_transformer_meta(workdir, cfg: ModelConfig, check: bool = False) -> Optional[dict]:
    """The stored meta of the transformer checkpoint (None without one); ``check``: raise on a model config
    mismatch other than the autoencoder step."""
    if not (pathlib.Path(workdir) / TRANSFORMER_SUBDIR).is_dir():
        return None
    with transformer_checkpointer(workdir, cfg, None, read_only=True) as probe:
        stored = probe.stored_meta()
        if check and stored is not None:
            probe.check_meta(stored)
        return stored


def set_aside_stale_transformer(workdir, stored: Optional[dict], ae_step: int) -> Optional[str]:
    """Move a transformer checkpoint trained on another autoencoder step out of the way (renamed, not deleted)
    so the transformer retrains on the current autoencoder; returns the new folder name, or None.

    stored: the transformer checkpoint's meta as read before training (:func:`stored_transformer_meta`)."""
    old = (stored or {}).get("config", {}).get("autoencoder_step")
    if stored is None or old is None or int(old) == int(ae_step):
        return None
    src = pathlib.Path(workdir).resolve() / TRANSFORMER_SUBDIR
    dst = src.with_name(f"{src.name}.autoencoder-step-{old}")
    k = 1
    while dst.exists():
        k += 1
        dst = src.with_name(f"{src.name}.autoencoder-step-{old}.{k}")
    if jax.process_index() == 0:
        src.rename(dst)
    if jax.process_count() > 1:
        from jax.experimental import multihost_utils

        multihost_utils.sync_global_devices("tgst: stale transformer set aside")
    return dst.name
