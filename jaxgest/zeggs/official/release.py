"""Import the ZeroEGGS authors' released models into a jaxgest workdir, and read such a workdir back.

A clone of the authors' repository (ubisoft/ubisoft-laforge-ZeroEGGS, with its Git LFS files pulled) holds,
per version ``v1`` / ``v2``::

    data/outputs/<v>/options.json                      network and training options
    data/outputs/<v>/saved_models/speech_encoder.pt    whole pickled torch modules (ZEGGS/modules.py)
    data/outputs/<v>/saved_models/decoder.pt
    data/outputs/<v>/saved_models/style_encoder.pt     (example-based models only: v1)
    data/processed_<v>/stats.npz                       input / output means and stds
    data/processed_<v>/data_definition.json            dt, label names, parents, bone names
    data/processed_<v>/data_pipeline_conf.json         the audio feature settings
    ZEGGS/modules.py ...                               the classes the .pt files unpickle to

:func:`import_release` reads them (torch only here, and only to unpickle; ``import torch`` fails with one
line naming the extra to install), checks every array against the options and statistics, and writes a
workdir: ``official.json`` (what was imported, from where, the options, the data definition, the audio
settings, sha256 of each file), ``official_params.npz`` (the state dicts under the authors' names,
``<network>/<name>``) and ``official_stats.npz``. The converted weights stay on the user's machine: the
authors' licence (CC BY-NC-ND 4.0) allows no shared adapted material, so jaxgest ships none.

References: the authors' ``generate.py`` (which files a model needs), ``modules.py`` (the classes),
``data_pipeline.py`` (the statistics); Ghorbani et al. 2023, §4.2.
"""

from __future__ import annotations

import hashlib
import json
import pathlib
from dataclasses import dataclass
from typing import Mapping

import numpy as np

from jaxgest.runtime.errors import CheckpointError, DataError
from jaxgest.runtime.io import atomic_output, write_json_atomic
from jaxgest.zeggs.authors_path import their_code_on_path

FORMAT = "jaxgest-zeggs-official/1"
MANIFEST, PARAMS, STATS = "official.json", "official_params.npz", "official_stats.npz"
VERSIONS = ("v1", "v2")
STAT_KEYS = ("audio_input_mean", "audio_input_std", "anim_input_mean", "anim_input_std", "anim_output_mean",
             "anim_output_std")


def release_files(repo, version: str) -> dict[str, pathlib.Path]:
    """The files of ``version`` in a clone of the authors' repository (not checked for existence)."""
    repo = pathlib.Path(repo)
    out, data = repo / "data" / "outputs" / version, repo / "data" / f"processed_{version}"
    return {"options": out / "options.json", "speech_encoder": out / "saved_models" / "speech_encoder.pt",
            "decoder": out / "saved_models" / "decoder.pt", "style_encoder": out / "saved_models" / "style_encoder.pt",
            "stats": data / "stats.npz", "data_definition": data / "data_definition.json",
            "data_pipeline_conf": data / "data_pipeline_conf.json", "code": repo / "ZEGGS" / "modules.py"}


def _read_json(path: pathlib.Path) -> dict:
    try:
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise DataError(f"{path}: not a readable JSON file ({e.__class__.__name__})") from None


def _sha256(path: pathlib.Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def _load_module(path: pathlib.Path, code_dir: pathlib.Path) -> dict[str, np.ndarray]:
    """The state dict (numpy float32) of a pickled torch module of the authors' repository."""
    with open(path, "rb") as f:
        head = f.read(64)
    if head.startswith(b"version https://git-lfs"):
        raise DataError(f"{path}: a Git LFS pointer, not the model: run `git lfs pull` in the repository")
    try:
        import torch
    except ImportError:
        raise DataError("importing the authors' models needs PyTorch to read their .pt files: "
                        "pip install 'jaxgest[authors]' (or pip install torch)") from None
    try:
        with their_code_on_path(code_dir):  # their generic names ("modules", "anim") leave with their path
            module = torch.load(str(path), map_location="cpu", weights_only=False)
    except Exception as e:  # noqa: BLE001 -- unpickling can raise anything; name the file, no traceback
        raise DataError(f"{path}: cannot be read as the authors' pickled module ({e.__class__.__name__}: "
                        f"{str(e).splitlines()[0][:160] if str(e) else ''})") from None
    state = module.state_dict() if hasattr(module, "state_dict") else module
    if not isinstance(state, Mapping):
        raise DataError(f"{path}: holds a {type(module).__name__}, not a torch module or state dict")
    return {k: np.asarray(v.detach().cpu().numpy() if hasattr(v, "detach") else v, np.float32)
            for k, v in state.items()}


def _expect(arrays: Mapping[str, np.ndarray], shapes: Mapping[str, tuple], path) -> None:
    for name, shape in shapes.items():
        if name not in arrays:
            raise DataError(f"{path}: has no parameter {name!r} (not the authors' network of these options)")
        if tuple(arrays[name].shape) != tuple(shape):
            raise DataError(f"{path}: {name} has shape {tuple(arrays[name].shape)}, expected {tuple(shape)} "
                            "from options.json and stats.npz")
        if not np.all(np.isfinite(arrays[name])):
            raise DataError(f"{path}: {name} has non-finite values")


def expected_shapes(options: dict, joints: int, labels: int) -> dict[str, dict[str, tuple]]:
    """Parameter shapes of the three networks implied by ``options.json`` and the rig (authors' names)."""
    net, train = options["net_opt"], options["train_opt"]
    S = int(net["speech_encoder"]["speech_encoding_size"])
    Hs = int(net["speech_encoder"]["nhidden"])
    H, L = int(net["decoder"]["nhidden"]), int(net["decoder"]["num_rnn_layers"])
    example = train.get("style_encoding_type", "example") == "example"
    E = int(net["style_encoder"]["style_encoding_size"]) if example else labels
    P_in, P_out = 9 + 15 * joints, 6 + 15 * joints
    speech = {"layer0.weight": (Hs, 81, 1), "layer0.bias": (Hs,), "layer1.weight": (S, Hs, 31),
              "layer1.bias": (S,), "layer2.weight": (S, S), "layer2.bias": (S,)}
    dec = {"cell_state_encoder.layer0.weight": (H, P_in + E), "cell_state_encoder.layer1.weight": (H, H),
           "cell_state_encoder.layer2.weight": (H * L, H)}
    cond = net["decoder"].get("rnn_cond", "normal")
    r = "recurrent_decoder"
    if cond == "normal":
        inp = P_in + S + E
        dec.update({f"{r}.layer0.weight": (H, inp), f"{r}.layer2.weight": (P_out, H),
                    f"{r}.layer1.weight_ih_l0": (3 * H, inp + H)})
    else:
        inp = P_in + S
        dec.update({f"{r}.layer0.weight": (H, inp), f"{r}.layer2.weight": (H, H), f"{r}.layer3.weight": (P_out, H),
                    f"{r}.layer1.weight_ih_l0": (3 * H, inp + H),
                    f"{r}.gammas_predictor.linear_layer.weight": (2 * H, E)})
    for layer in range(L):
        dec[f"{r}.layer1.weight_hh_l{layer}"] = (3 * H, H)
        if layer:
            dec[f"{r}.layer1.weight_ih_l{layer}"] = (3 * H, H)
    out = {"speech_encoder": speech, "decoder": dec}
    if example:
        Hst, D = int(net["style_encoder"]["nhidden"]), 2 * E
        e = "encoder"
        out["style_encoder"] = {f"{e}.convs.0.conv.weight": (Hst, P_in, 3), f"{e}.convs.2.weight": (Hst,),
                                f"{e}.convs.4.conv.weight": (D, Hst, 3), f"{e}.convs.6.weight": (D,),
                                f"{e}.blocks.0.attention.multi_head_attention.in_proj_weight": (3 * D, D),
                                f"{e}.blocks.0.feed_forward.convs.0.conv.weight": (D, D, 3)}
    return out


@dataclass(frozen=True)
class Release:
    """An imported release: ``manifest`` (official.json), ``params`` ``{network: {name: array}}``, ``stats``."""

    manifest: dict
    params: dict
    stats: dict

    @property
    def example_based(self) -> bool:
        return self.manifest["style_encoding_type"] == "example"


def import_release(repo, version: str, workdir, *, log=print) -> Release:
    """Read ``version`` of the authors' release in ``repo`` and write it as a jaxgest workdir (module doc).

    Raises :class:`DataError` naming the first missing or mismatched file; writes nothing then.
    References: the authors' ``generate.py`` (``generate_gesture``: the files a model needs).
    """
    if version not in VERSIONS:
        raise DataError(f"--version must be one of {', '.join(VERSIONS)}, got {version!r}")
    repo = pathlib.Path(repo)
    if not repo.is_dir():
        raise DataError(f"{repo}: no such directory (a clone of ubisoft/ubisoft-laforge-ZeroEGGS)")
    files = release_files(repo, version)
    for key in ("options", "stats", "data_definition", "data_pipeline_conf", "code", "speech_encoder", "decoder"):
        if not files[key].is_file():
            raise DataError(f"{files[key]}: missing (a clone of the authors' repository with `git lfs pull` done "
                            f"has it)")
    options = _read_json(files["options"])
    definition = _read_json(files["data_definition"])
    conf = _read_json(files["data_pipeline_conf"])
    try:
        style_type = options["train_opt"].get("style_encoding_type", "example")
        cond = options["net_opt"]["decoder"].get("rnn_cond", "normal")
        joints, labels = len(definition["bone_names"]), len(definition["label_names"])
        if len(definition["parents"]) != joints:
            raise DataError(f"{files['data_definition']}: {len(definition['parents'])} parents for {joints} bones")
        dt = float(definition["dt"])
        shapes = expected_shapes(options, joints, labels)
    except (KeyError, TypeError, ValueError) as e:
        raise DataError(f"{files['options']}: not the authors' options / data definition ({e!r})") from None
    if style_type not in ("example", "label") or cond not in ("normal", "film"):
        raise DataError(f"{files['options']}: style_encoding_type {style_type!r} / rnn_cond {cond!r} unknown")
    if style_type == "example" and not files["style_encoder"].is_file():
        raise DataError(f"{files['style_encoder']}: missing (an example-based model needs its style encoder)")
    try:
        with np.load(files["stats"]) as z:
            stats = {k: np.asarray(z[k], np.float32) for k in STAT_KEYS}
    except (OSError, KeyError, ValueError) as e:
        raise DataError(f"{files['stats']}: not the authors' statistics ({e!r})") from None
    sizes = {"audio_input_mean": (81,), "anim_input_mean": (9 + 15 * joints,), "anim_input_std": (9 + 15 * joints,),
             "anim_output_mean": (6 + 15 * joints,), "anim_output_std": (6 + 15 * joints,)}
    for k, shape in sizes.items():
        if stats[k].shape != shape:
            raise DataError(f"{files['stats']}: {k} has shape {stats[k].shape}, expected {shape} for {joints} bones")
    if stats["audio_input_std"].size != 1 and stats["audio_input_std"].shape != (81,):
        raise DataError(f"{files['stats']}: audio_input_std has shape {stats['audio_input_std'].shape}")
    params = {}
    code_dir = files["code"].parent
    for net in shapes:
        log(f"reading {files[net]}")
        arrays = _load_module(files[net], code_dir)
        _expect(arrays, shapes[net], files[net])
        params[net] = arrays
    manifest = {  # fps: nominal, as theirs (dt 0.016667 is 60 fps: ``int(np.ceil(1 / frametime))``)
        "format": FORMAT, "version": version, "name": options.get("name", f"ZEGGS_{version}"),
        "source": str(repo.resolve()), "style_encoding_type": style_type, "rnn_cond": cond, "dt": dt,
        "fps": float(round(1.0 / dt)), "bone_names": list(definition["bone_names"]),
        "parents": [int(p) for p in definition["parents"]], "label_names": list(definition["label_names"]),
        "options": options, "audio_conf": conf.get("audio_conf", {}),
        "audio_feature_type": conf.get("audio_feature_type", ["mel_spec", "energy"]),
        "sha256": {k: _sha256(files[k]) for k in list(shapes) + ["stats", "options", "data_definition"]},
    }
    write_workdir(workdir, manifest, params, stats)
    return Release(manifest, params, stats)


def write_workdir(workdir, manifest: dict, params: dict, stats: dict) -> pathlib.Path:
    """Write an imported release into ``workdir`` (created; an existing jaxgest training workdir is refused)."""
    w = pathlib.Path(workdir)
    if w.exists() and not w.is_dir():
        raise DataError(f"{w}: exists and is not a directory")
    if w.is_dir() and (w / "config.json").exists():
        raise DataError(f"{w}: holds a trained jaxgest model (config.json); import into a new folder")
    try:
        w.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise DataError(f"{w}: cannot create the workdir ({e.strerror})") from None
    flat = {f"{net}/{name}": a for net, arrays in params.items() for name, a in arrays.items()}
    with atomic_output(w / PARAMS) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **flat)
    with atomic_output(w / STATS) as tmp:
        with open(tmp, "wb") as f:
            np.savez(f, **stats)
    write_json_atomic(w / MANIFEST, manifest)  # last: a workdir with official.json is complete
    return w


def is_official(workdir) -> bool:
    """Whether ``workdir`` holds an imported release (its ``official.json``)."""
    return (pathlib.Path(workdir) / MANIFEST).is_file()


def read_workdir(workdir) -> Release:
    """The :class:`Release` of a workdir written by :func:`import_release`."""
    w = pathlib.Path(workdir)
    manifest = _read_json(w / MANIFEST)
    if manifest.get("format") != FORMAT:
        raise CheckpointError(f"{w / MANIFEST}: format {manifest.get('format')!r}, this jaxgest reads {FORMAT!r}")
    params: dict = {}
    try:
        with np.load(w / PARAMS) as z:
            for key in z.files:
                net, name = key.split("/", 1)
                params.setdefault(net, {})[name] = np.asarray(z[key], np.float32)
        with np.load(w / STATS) as z:
            stats = {k: np.asarray(z[k], np.float32) for k in STAT_KEYS}
    except (OSError, KeyError, ValueError) as e:
        raise CheckpointError(f"{w}: the imported weights or statistics cannot be read ({e.__class__.__name__}); "
                              "import again") from None
    return Release(manifest, params, stats)

