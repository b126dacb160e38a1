"""What the ``<model> train`` commands share: their common arguments and the training-data folder."""

from __future__ import annotations

import argparse
import pathlib
from typing import Optional

from jaxgest.runtime.config import parse_overrides
from jaxgest.runtime.errors import DataError

LOG_EVERY = 50  # default --log-every of every train command


def add_train_arguments(parser: argparse.ArgumentParser, *, presets, data_help: str, workdir_help: str,
                        steps_help: str, ckpt_every: Optional[int] = 500,
                        ckpt_help: str = "checkpoint every N steps (and at the end)") -> None:
    """The arguments every ``<model> train`` command shares, with one set of defaults: ``--data``,
    ``--workdir``, ``--preset``, ``--override``, ``--steps``, ``--seed``, ``--devices``, ``--ckpt-every``,
    ``--log-every``, and the watching ones ``--eval-every``, ``--eval-data``, ``--tb``, ``--profile``
    (:func:`watch_arguments`). Pass the parsed namespace to :func:`training_data` for the data folder and to
    :func:`overrides` for the config overrides."""
    parser.add_argument("--data", default=None, help=data_help)
    parser.add_argument("--workdir", required=True, help=workdir_help)
    parser.add_argument("--preset", default="tiny", choices=tuple(presets))
    parser.add_argument("--override", action="append", default=[], metavar="KEY=VALUE",
                        help="set a config field of the preset by its dotted path, e.g. "
                             "train.learning_rate=3e-4 (VALUE as JSON or a Python literal; repeatable)")
    parser.add_argument("--steps", type=int, default=None, help=steps_help)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--devices", type=int, default=None, help="use the first N devices (data parallel)")
    parser.add_argument("--ckpt-every", type=int, default=ckpt_every, help=ckpt_help)
    parser.add_argument("--log-every", type=int, default=LOG_EVERY,
                        help=f"metrics.jsonl line every N steps, the training metrics averaged over them "
                        f"(default {LOG_EVERY})")
    parser.add_argument("--eval-every", type=int, default=None, metavar="N",
                        help="loss on held-out clips (--eval-data) every N steps (a multiple of "
                        "--log-every), logged as eval_loss, ... in metrics.jsonl")
    parser.add_argument("--eval-data", default=None, metavar="DIR",
                        help="held-out clips for --eval-every (any layout --data takes; not trained on)")
    parser.add_argument("--tb", default=None, metavar="DIR",
                        help="also write the logged metrics as TensorBoard events into DIR (train/, eval/; "
                        "needs tensorboardX: pip install 'jaxgest[tb]')")
    parser.add_argument("--profile", default=None, metavar="DIR",
                        help="trace a few training steps (after the compiling first) with jax.profiler "
                        "into DIR")


def training_data(args: argparse.Namespace) -> pathlib.Path:
    """The data folder of a train command: ``--data``, or the built-in synthetic data written once to
    ``<workdir>/synthetic-data`` (:func:`jaxgest.motion.synthetic.dataset.training_folder`). The step counts
    and intervals are checked first, so a bad argument writes nothing."""
    from jaxgest.motion.synthetic.dataset import training_folder
    from jaxgest.runtime.training import check_intervals, check_steps

    check_steps(**{k: getattr(args, k) for k in ("steps", "ae_steps", "transformer_steps") if hasattr(args, k)})
    check_intervals(log_every=args.log_every, ckpt_every=args.ckpt_every)
    watch_arguments(args)
    return training_folder(args.data, args.workdir, progress=True)


def watch_arguments(args: argparse.Namespace) -> dict:
    """``eval_data``, ``eval_every``, ``tb_dir``, ``profile_dir`` of a train command, checked (one-line errors
    before anything is written): the held-out pair, and the two output folders not files (their parents are
    created)."""
    from jaxgest.runtime.training import check_eval

    check_eval(args.eval_data, args.eval_every, args.log_every)
    for flag, value in (("--tb", args.tb), ("--profile", args.profile)):
        if value is not None and pathlib.Path(value).exists() and not pathlib.Path(value).is_dir():
            raise DataError(f"{value}: {flag} needs a folder, and this is a file")
    if args.tb is not None:
        try:
            import tensorboardX  # noqa: F401
        except ImportError:
            raise DataError("--tb needs tensorboardX: pip install 'jaxgest[tb]' (or pip install tensorboardX)"
                            ) from None
    return {"eval_data": args.eval_data, "eval_every": args.eval_every, "tb_dir": args.tb,
            "profile_dir": args.profile}


def overrides(args: argparse.Namespace) -> dict:
    """``--override KEY=VALUE ...`` as ``{key: value}`` (:func:`jaxgest.runtime.config.parse_overrides`)."""
    return parse_overrides(args.override)
