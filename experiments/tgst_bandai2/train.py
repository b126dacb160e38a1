"""Train one run of this experiment from its config file (``runs/NAME.toml``) into ``out/runs/NAME``.

    python experiments/tgst_bandai2/train.py experiments/tgst_bandai2/runs/full_s0.toml [--data DIR]

The training folder ``out/splits/NAME`` holds symlinks to the Bandai-Namco-2 clips of the config's
``train_takes`` (001-004), without ``hold_out_content`` (zero-shot runs), plus every clip of the folders in
``extra_data`` (paths relative to the repository root, e.g. ``../shared/data/bandai-namco-1``); no data is
copied. Resumes when the
workdir already holds checkpoints. Writes ``out/runs/NAME/train_summary.json`` (stamped).
"""
import argparse
import json
import tomllib
import pathlib
import sys

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT_DATA = HERE.parents[1] / ".." / "shared" / "data" / "bandai-namco-2"


def main() -> int:
    from jaxgest.runtime.errors import DataError
    from jaxgest.runtime.provenance import write_results
    from jaxgest.tgst import multitake
    from jaxgest.tgst.trainer import train

    ap = argparse.ArgumentParser()
    ap.add_argument("config")
    ap.add_argument("--data", default=str(DEFAULT_DATA))
    a = ap.parse_args()
    cfg = tomllib.loads(pathlib.Path(a.config).read_text())
    split = HERE / "out" / "splits" / cfg["name"]
    try:
        n = multitake.link_split(a.data, split, takes=cfg["train_takes"],
                                 exclude_contents=[cfg["hold_out_content"]] if cfg["hold_out_content"] else ())
        for extra in cfg.get("extra_data", []):  # every clip of another dataset (e.g. Bandai-Namco-1)
            n += multitake.link_split(HERE.parents[1] / extra, split, takes=None, clear=False)
    except DataError as e:
        print(f"error: {e}", file=sys.stderr)
        return 2
    print(f"{split}: {n} training clips", flush=True)
    workdir = HERE / "out" / "runs" / cfg["name"]
    summary = train(split, workdir, preset=cfg["preset"], ae_steps=cfg["ae_steps"],
                    transformer_steps=cfg["transformer_steps"], seed=cfg["seed"], progress=False, log_every=50,
                    ckpt_every=max(cfg["ae_steps"], cfg["transformer_steps"]), overrides=cfg["overrides"])
    write_results(workdir / "train_summary.json", summary, cfg)
    print(json.dumps({k: summary[k] for k in ("wall_s",) if k in summary}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
