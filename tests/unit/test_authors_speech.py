"""jaxgest's speech features and speech encoder against the ZeroEGGS authors' own code and released encoders.

The authors' code and files are read where they lie (``../shared/third_party/zeggs-official``, never copied)
through ``tests/helpers/authors_zeggs.py``; these tests skip with the reason when it or its Python packages
(torch, pandas, omegaconf, rich, pyloudnorm, sox; ``.ci/run`` installs them) are missing. Real speech: a 10 s crop
of one ZEGGS and one BEAT2 recording from ``../shared/data/speech-gesture``.

Measured (10 s crops; numpy 2.4, scipy 1.17, librosa 0.11, soxr 1.1, pyloudnorm 0.2, torch 2.13 CPU):

* features, ``speech_features(path, method="authors")`` vs their ``read_wavfile`` + ``preprocess_audio`` on
  the same 16 kHz file: identical, max abs difference 0.0 (ZEGGS, int16 WAV, and BEAT2, float32 WAV); on
  samples handed over in memory (float32 rather than re-read) up to 9.5e-7, one float32 rounding step of
  the final cast (relative to the largest value, the energy ~9.4: 1e-7). Tolerance: rtol 1e-6, atol 1e-7.
* a 44.1 / 48 kHz file: their SoX ``rate -h`` (through a 32-bit integer WAV) and jaxgest's libsoxr "HQ"
  differ by up to 6e-5 of full scale per sample; the features then differ by up to 9.1e-6 (mel bands, whose
  values lie in [0, 0.115]) and 3.8e-6 (energy, ~9.4). Tolerance: atol 5e-5.
* loudness: ``integrated_loudness(meter="pyloudnorm")`` equals pyloudnorm's exactly (0.0 LU on these files);
  the BS.1770 meter reads 0.12 LU louder at 16 kHz (pyloudnorm's default K-weighting is an RBJ approximation).
* released speech encoders on those features (normalised with the release's stats.npz), their torch module
  in eval mode vs jaxgest's SpeechEncoder with the converted parameters: max abs difference / max abs value
  3.5e-7 (v1: max abs 6.0e-7 of 1.70) and 2.3e-7 (v2: 3.6e-7 of 1.56). Tolerance: 1e-5.
"""

from __future__ import annotations

import json
import pathlib
import shutil
import os
import subprocess
import sys
import textwrap

import jax
import numpy as np
import pytest
import soundfile as sf

from jaxgest import audio
from jaxgest.runtime.errors import CheckpointError
from jaxgest.zeggs import torch_import
from jaxgest.zeggs.config import MODEL_ADDED_FIELDS, Config, ModelConfig, preset
from jaxgest.zeggs.speech_encoder import SpeechEncoder
from authors_zeggs import SHARED, ZEGGS_CODE, authors_code, released, require_authors, their

SPEECH = SHARED / "data" / "speech-gesture"
WAVS = {"zeggs": SPEECH / "zeggs" / "067_Speech_2_x_1_0.wav", "beat2": SPEECH / "beat2" / "2_scott_0_1_1.wav"}
CROP_S = 10


def _conf():
    from omegaconf import OmegaConf

    return OmegaConf.create(json.loads(released("v1", "data_pipeline_conf.json").read_text()))


def _their_features(path) -> np.ndarray:
    """Their generate.py's speech features of a WAV: ``read_wavfile`` at 16 kHz, then ``preprocess_audio``."""
    with authors_code():
        read_wavfile = their("audio.audio_files").read_wavfile
        preprocess_audio = their("data_pipeline").preprocess_audio
        conf = _conf()
        _, y = read_wavfile(str(path), rescale=True, desired_fs=16000, desired_nb_channels=None, out_type="float32")
        n_frames = int(round(60.0 * (len(y) / 16000)))
        return preprocess_audio(y, 60, n_frames, conf.audio_conf, feature_type=conf.audio_feature_type)


@pytest.fixture(scope="module", params=sorted(WAVS))
def crop(request, tmp_path_factory):
    """``(name, path)``: the first 10 s of a shared recording, written losslessly in its own sample format."""
    src = WAVS[request.param]
    if not src.is_file():
        pytest.skip(f"real speech not found at {src}")
    info = sf.info(str(src))
    y, sr = sf.read(str(src), dtype="float32", frames=CROP_S * info.samplerate)
    path = tmp_path_factory.mktemp(f"crop_{request.param}") / f"{request.param}.wav"
    sf.write(str(path), y, sr, subtype=info.subtype)  # PCM_16 / FLOAT: the float32 samples round-trip exactly
    return request.param, path


@pytest.mark.parametrize("version", ["v1", "v2"])
def test_constants_are_their_released_conf(version):
    """jaxgest's constants are the released ``data_pipeline_conf.json`` audio options (v1 and v2 alike)."""
    path = released(version, "data_pipeline_conf.json")
    if not path.is_file():
        pytest.skip(f"the authors' {path.name} is not at {path}")
    d = json.loads(path.read_text())
    c = d["audio_conf"]
    assert d["audio_feature_type"] == ["mel_spec", "energy"]
    assert (c["sampling_rate"], c["filter_length"], c["hop_length"], c["n_mel_channels"], c["mel_fmin"], c["mel_fmax"],
            c["min_clipping"]) == (audio.AUTHORS_SR, audio.AUTHORS_N_FFT, audio.AUTHORS_HOP, audio.N_MELS, audio.FMIN,
                                   audio.FMAX, audio.AUTHORS_MIN_AMPLITUDE)
    assert (c["pre_emphasis"], c["centered"], c["real_amplitude"], c["normalize_mel_bins"], c["normalize_range"],
            c["normalize_loudness"], c["resample_method"]) == (False, True, True, True, True, True, "linear")


def test_authors_features_equal_their_pipeline(crop):
    """From the same WAV file, jaxgest's ``method="authors"`` features are theirs to float32 rounding."""
    require_authors()
    name, path = crop
    ref = _their_features(path)
    got = audio.speech_features(path)  # the default method is the authors'
    assert got.shape == ref.shape == (CROP_S * 60, audio.FEATURE_DIM) and got.dtype == np.float32
    diff = np.abs(got.astype(np.float64) - ref)
    print(f"{name}: max abs {diff.max():.2e} (mel {diff[:, :80].max():.2e}, energy {diff[:, 80].max():.2e}), "
          f"relative {diff.max() / np.abs(ref).max():.2e}")
    np.testing.assert_allclose(got, ref, rtol=1e-6, atol=1e-7)
    # Control: the librosa method is another feature (and the check above can fail).
    assert np.abs(audio.speech_features(path, method="librosa") - ref).max() > 0.1
    # Their features carry the speech: a realistic range, not a constant.
    assert np.all(ref[:, :80].std(axis=0) > 1e-3) and np.ptp(ref[:, 80]) > 0.1


@pytest.mark.parametrize("rate,subtype", [(44100, "PCM_16"), (48000, "PCM_24")])
def test_other_sample_rates_resample_like_their_sox(crop, rate, subtype, tmp_path):
    """A file not at 16 kHz: they resample with SoX ``rate -h``, jaxgest with libsoxr "HQ" (the same library,
    another build and a 32-bit integer WAV in between): features equal to 5e-5 (measured up to 1e-5)."""
    require_authors()
    if shutil.which("sox") is None:
        pytest.skip("their read_wavfile resamples with the SoX program, which is not installed (apt-get install sox)")
    import soxr

    name, path = crop
    y, sr = sf.read(str(path), dtype="float32")
    other = tmp_path / f"{name}_{rate}.wav"
    sf.write(str(other), soxr.resample(y, sr, rate, quality="VHQ"), rate, subtype=subtype)
    ref = _their_features(other)
    got = audio.speech_features(other)
    diff = np.abs(got.astype(np.float64) - ref)
    print(f"{name} at {rate} Hz: max abs {diff.max():.2e} (mel {diff[:, :80].max():.2e}, energy {diff[:, 80].max():.2e})")
    np.testing.assert_allclose(got, ref, rtol=0, atol=5e-5)
    # Control: a coarser resampler (libsoxr "LQ") is told apart at this tolerance.
    wrong = audio.speech_features(soxr.resample(sf.read(str(other), dtype="float32")[0], rate, 16000,
                                                quality="LQ"), sr=16000)
    assert np.abs(wrong - ref).max() > 5e-5


@pytest.mark.filterwarnings("ignore:Possible clipped samples")
def test_pyloudnorm_meter_is_theirs(crop):
    """``integrated_loudness(meter="pyloudnorm")`` is pyloudnorm's to 1e-9 LU (float32 and float64 samples,
    16 and 44.1 kHz); the BS.1770 meter differs (0.12 LU at 16 kHz), so the authors' method uses the former."""
    pyln = pytest.importorskip("pyloudnorm")
    import soxr

    _, path = crop
    y, sr = sf.read(str(path), dtype="float32")
    for x, rate in ((y, sr), (y.astype(np.float64), sr), (soxr.resample(y, sr, 44100), 44100)):
        theirs = pyln.Meter(rate).integrated_loudness(x)
        assert audio.integrated_loudness(x, rate, meter="pyloudnorm") == pytest.approx(theirs, abs=1e-9)
        assert abs(audio.integrated_loudness(x, rate) - theirs) > 0.03  # the standard's filters: not theirs
    z = audio.normalize_loudness(y, sr, meter="pyloudnorm")
    np.testing.assert_array_equal(z, pyln.normalize.loudness(y, pyln.Meter(sr).integrated_loudness(y), -20.0))
    # Silence (pyloudnorm would scale it into NaN) and audio shorter than a 400 ms block stay finite.
    assert np.array_equal(audio.normalize_loudness(np.zeros(sr, np.float32), sr, meter="pyloudnorm"), np.zeros(sr))
    loudest = int(np.argmax([np.sum(y[i:i + 4000] ** 2) for i in range(0, len(y) - 4000, 4000)])) * 4000
    short = audio.normalize_loudness(y[loudest:loudest + 4000], sr, meter="pyloudnorm")  # 250 ms of speech
    assert np.all(np.isfinite(short)) and audio.integrated_loudness(short, sr, meter="pyloudnorm") == pytest.approx(-20.0)


@pytest.mark.parametrize("y", [np.zeros(16000, np.float32), np.full(16000, 0.3, np.float32),
                               np.zeros(10, np.float32), np.ones(3, np.float32),
                               np.r_[np.zeros(8000), 0.5 * np.ones(8000)].astype(np.float32)],
                         ids=["silence", "dc", "short", "tiny", "step"])
def test_authors_method_on_degenerate_audio_is_finite(y):
    for sr in (16000, 44100):
        f = audio.speech_features(y, sr=sr)
        assert f.shape == (max(1, int(round(60 * len(y) / sr))), 81) and np.all(np.isfinite(f))


def test_authors_method_errors_name_the_file(tmp_path):
    from jaxgest.runtime.errors import AudioError

    bad = tmp_path / "nan.wav"
    y = np.zeros(1600, np.float32)
    y[3] = np.nan
    sf.write(str(bad), y, 16000, subtype="FLOAT")
    with pytest.raises(AudioError, match="nan.wav.*NaN"):
        audio.speech_features(bad, method="authors")
    (tmp_path / "junk.wav").write_bytes(b"RIFF0000WAVEnope")
    with pytest.raises(AudioError, match="junk.wav: unreadable"):
        audio.speech_features(tmp_path / "junk.wav", method="authors")
    with pytest.raises(AudioError, match="junk.wav.*16000 Hz"):
        audio.speech_features(tmp_path / "junk.wav", sr=22050, method="authors")
    with pytest.raises(AudioError, match="unknown method 'mfcc'"):
        audio.speech_features(y[:2], sr=16000, method="mfcc")


# ----- which method a model uses ---------------------------------------------------------------------------

def test_new_models_use_the_authors_features_and_old_workdirs_keep_librosa():
    from jaxgest.zeggs.workdir import checkpoint_config, stored_checkpoint_config

    for name in ("paper", "small", "tiny"):
        assert preset(name).model.speech_features == "authors"
    d = preset("tiny").to_dict()
    assert Config.from_dict(d).model.speech_features == "authors"  # written by this version: as written
    del d["model"]["speech_features"]  # config.json of a workdir trained before the field existed
    old = Config.from_dict(d)
    assert old.model.speech_features == "librosa" and old == preset("tiny").override(speech_features="librosa")
    assert MODEL_ADDED_FIELDS == {"speech_features": "librosa"}
    # A checkpoint's stored model section without the field reads as librosa, so it matches the old model.
    stored = checkpoint_config(old.model)
    del stored["speech_features"]
    assert stored_checkpoint_config(stored) == checkpoint_config(old.model)
    assert stored_checkpoint_config(stored) != checkpoint_config(preset("tiny").model)
    with pytest.raises(ValueError, match="speech_features"):
        ModelConfig(speech_features="mfcc")


def test_data_and_inference_use_the_models_method(zeggs_dir):
    """Training data (one clip, no augmentation) and inference compute a model's features with its
    ``speech_features``."""
    from types import SimpleNamespace

    from jaxgest.motion.datasets import NormStats
    from jaxgest.zeggs import data as zdata
    from jaxgest.zeggs.inference import TrainedZeggs

    clip = next(c for c in zdata.load_folder(zeggs_dir) if c.audio is not None)
    samples, sr = zdata.load_clip_audio(clip)
    a = zdata.clip_sequences(clip, fps=30, mirror=False, speeds=(1.0,), speech_method="authors")[0].speech
    b = zdata.clip_sequences(clip, fps=30, mirror=False, speeds=(1.0,), speech_method="librosa")[0].speech
    n = len(a)
    np.testing.assert_array_equal(a, audio.speech_features(samples, sr=sr, fps=30, method="authors")[:n])
    np.testing.assert_array_equal(b, audio.speech_features(samples, sr=sr, fps=30, method="librosa")[:n])
    y = samples[: 2 * sr]
    for method in audio.SPEECH_METHODS:
        model = SimpleNamespace(cfg=preset("tiny").override(speech_features=method),
                                speech_stats=NormStats(np.zeros(81, np.float32), np.ones(81, np.float32)))
        feats, _ = TrainedZeggs.speech(model, y, sr=sr)
        np.testing.assert_allclose(feats, audio.speech_features(y, sr=sr, method=method), rtol=1e-6, atol=1e-7)


# ----- the released speech encoders ------------------------------------------------------------------------

def test_converted_params_have_jaxgests_tree():
    cfg = torch_import.released_speech_config()
    want = jax.eval_shape(lambda: SpeechEncoder(cfg).init(jax.random.key(0), np.zeros((1, 8, 81), np.float32)))
    rng = np.random.default_rng(0)
    state = {k: rng.normal(size=s).astype(np.float32) for k, s in torch_import.expected_shapes(cfg).items()}
    got = torch_import.speech_encoder_params(state, cfg)
    assert jax.tree_util.tree_structure(got) == jax.tree_util.tree_structure(want["params"])
    assert jax.tree_util.tree_map(np.shape, got) == jax.tree_util.tree_map(lambda s: s.shape, want["params"])
    np.testing.assert_array_equal(got["conv1"]["kernel"][:, 2, 5], state["layer1.weight"][5, 2, :])  # (k, in, out)
    np.testing.assert_array_equal(got["linear"]["kernel"][3, 7], state["layer2.weight"][7, 3])  # (in, out)


def test_wrong_state_dict_is_a_clear_error():
    cfg = torch_import.released_speech_config()
    state = {k: np.zeros(s, np.float32) for k, s in torch_import.expected_shapes(cfg).items()}
    with pytest.raises(CheckpointError, match=r"enc.pt: layer1.weight has shape \(64, 64, 30\), expected \(64, 64, 31\)"):
        torch_import.speech_encoder_params({**state, "layer1.weight": np.zeros((64, 64, 30))}, cfg, name="enc.pt")
    with pytest.raises(CheckpointError, match="missing layer2.bias"):
        torch_import.speech_encoder_params({k: v for k, v in state.items() if k != "layer2.bias"}, cfg)
    with pytest.raises(CheckpointError, match="unexpected layer3.weight"):
        torch_import.speech_encoder_params({**state, "layer3.weight": np.zeros(1)}, cfg)
    with pytest.raises(CheckpointError, match="layer0.bias contains NaN"):
        torch_import.speech_encoder_params({**state, "layer0.bias": np.full(64, np.nan)}, cfg)
    # Control: the same dict, untouched, converts.
    assert torch_import.speech_encoder_params(state, cfg)["conv0"]["kernel"].shape == (1, 81, 64)


def test_converting_numpy_arrays_does_not_import_torch():
    code = textwrap.dedent("""
        import sys
        import numpy as np
        from jaxgest.zeggs import torch_import as t
        cfg = t.released_speech_config()
        p = t.speech_encoder_params({k: np.ones(s) for k, s in t.expected_shapes(cfg).items()}, cfg)
        print(sorted(p), "torch" in sys.modules)
    """)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "JAX_PLATFORMS": "cpu"})
    assert out.stdout.split() == ["['conv0',", "'conv1',", "'linear']", "False"]


@pytest.mark.parametrize("version", ["v1", "v2"])
def test_released_speech_encoder_runs_in_jaxgest(version):
    """Their ``speech_encoder.pt`` (eval mode) and jaxgest's SpeechEncoder with the converted parameters, on the
    authors' features of a 10 s ZEGGS crop normalised with the release's stats.npz: equal to 1e-5 of the
    largest output."""
    require_authors()
    pt, stats = released(version, "speech_encoder.pt"), released(version, "stats.npz")
    if not (pt.is_file() and stats.is_file() and WAVS["zeggs"].is_file()):
        pytest.skip(f"released {version} speech encoder, its stats.npz or the ZEGGS recording not found")
    import torch

    y, sr = sf.read(str(WAVS["zeggs"]), dtype="float32", frames=CROP_S * 16000)
    with np.load(stats) as s:
        x = ((audio.speech_features(y, sr=sr) - s["audio_input_mean"]) / s["audio_input_std"]).astype(np.float32)
    with authors_code():
        module = torch.load(str(pt), map_location="cpu")
        module.eval()
        with torch.no_grad():
            ref = module(torch.as_tensor(x[None])).numpy()[0]
        params = torch_import.speech_encoder_params(module, name=str(pt))
    cfg = torch_import.released_speech_config()
    got = np.asarray(SpeechEncoder(cfg).apply({"params": params}, x[None], deterministic=True))[0]
    rel = np.abs(got - ref).max() / np.abs(ref).max()
    print(f"{version}: max abs {np.abs(got - ref).max():.2e}, max |out| {np.abs(ref).max():.3f}, relative {rel:.2e}")
    assert got.shape == ref.shape == (CROP_S * 60, 64) and rel <= 1e-5
    # The loader (torch.load with their folder on sys.path) gives the same parameters, and leaves no module behind.
    before, path_before = set(sys.modules), list(sys.path)
    loaded = torch_import.load_torch_speech_encoder(pt, ZEGGS_CODE)
    jax.tree_util.tree_map(np.testing.assert_array_equal, loaded, params)
    theirs = str(ZEGGS_CODE.resolve())
    left = [k for k in set(sys.modules) - before if str(getattr(sys.modules[k], "__file__", "") or "").startswith(theirs)]
    assert not left and sys.path == path_before, left
    # Control: with the kernels not transposed (torch's layout read as Flax's) the outputs differ.
    bad = {**params, "linear": {**params["linear"], "kernel": params["linear"]["kernel"].T}}
    assert np.abs(np.asarray(SpeechEncoder(cfg).apply({"params": bad}, x[None]))[0] - ref).max() > 1e-3
