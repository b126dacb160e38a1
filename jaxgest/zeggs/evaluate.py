"""ZeroEGGS evaluation: style/content probes with controls, a content-leakage report, beat alignment
against a shuffled control, and the Fréchet distance between motion-feature statistics of generated and
real clips (docs/design.md §5).

* **Probes** and **leakage**: :mod:`jaxgest.zeggs.probes` (:func:`probe`, :func:`leakage`), run here.
* **Beat alignment**: for each test clip with audio, gestures are generated from its audio in its style,
  with another recording of that style (a training-half clip of another content when there is one, see
  :func:`style_example`) as the zero-shot style example, so the example's timing cannot leak; kinematic
  beats (minima of smoothed hand speed) are scored against the audio's onsets (BeatAlign, sigma 0.1 s) and
  against circularly shifted onsets (the shuffled control), with the per-clip paired difference (mean,
  standard error over clips, clips above the control). Also reported for the real motion.
* **Fréchet distance** between Gaussian fits of per-frame motion features (root-frame joint positions and
  velocities) of the generated clips and of the real clips; the same distance between the real training
  clips and the real test clips is reported as the floor to compare with.

References: Ghorbani et al. 2023, §5.1-5.2 (style generalisation, embedding space); docs/design.md §5; Li et al. 2021
(BeatAlign); Heusel et al. 2017 (Fréchet distance).
"""

from __future__ import annotations

import collections
import pathlib
from typing import Optional

import numpy as np

from jaxgest import metrics
from jaxgest.runtime.errors import DataError
from jaxgest.motion import body, kinematics
from jaxgest.motion.datasets import load_clip_audio, load_folder
from jaxgest.zeggs import features
from jaxgest.zeggs.inference import load_model
from jaxgest.zeggs.probes import LEAKAGE_SOURCES, leakage, pooled_probe, probe


def _split_by_style(clips, seed: int = 0):
    by_style = collections.defaultdict(list)
    for c in clips:
        by_style[c.style].append(c)
    rng = np.random.default_rng(seed)
    train, test = [], []
    for style in sorted(by_style):
        group = sorted(by_style[style], key=lambda c: str(c.path))
        rng.shuffle(group)
        if len(group) < 2:
            train.extend(group)
            continue
        half = len(group) // 2
        test.extend(group[:half])
        train.extend(group[half:])
    return train, test


def _hand_indices(motion):
    return body.joint_indices(motion.skeleton, body.HANDS)


def beat_scores(motion, audio, sr: int, *, seed: int = 0) -> dict:
    """BeatAlign of a motion against its audio's onsets and against shifted onsets."""
    pos = kinematics.forward_kinematics(motion)
    speed = metrics.hand_speed(pos, motion.fps, _hand_indices(motion))
    beats = metrics.kinematic_beats(speed, motion.fps)
    onsets = metrics.onset_times(audio, sr)
    duration = motion.num_frames / motion.fps
    return {"aligned": metrics.beat_alignment(beats, onsets),
            "shuffled": metrics.shuffled_beat_alignment(beats, onsets, duration, seed=seed)}


def style_example(clip, others):
    """The style example for generating ``clip``: another recording of its style (the first of ``others``
    with the same style and another content when there is one, else another file), else the clip itself."""
    same = [o for o in others if o.style == clip.style and o.path != clip.path]
    other_content = [o for o in same if o.content != clip.content]
    return (other_content or same or [clip])[0]


def paired_difference(scores) -> dict:
    """Per-clip BeatAlign minus its shuffled control: mean, standard error of the mean, clips above.

    scores: list of :func:`beat_scores` dicts (one per clip). The clips are the independent units, so the
    standard error is std(diff, ddof=1) / sqrt(clips) (0 for one clip).
    """
    d = np.array([s["aligned"] - s["shuffled"] for s in scores], np.float64)
    se = float(d.std(ddof=1) / np.sqrt(len(d))) if len(d) > 1 else 0.0
    return {"mean": float(d.mean()), "standard_error": se, "clips_above": int(np.sum(d > 0)), "clips": len(d)}


def motion_statistics_features(motion) -> np.ndarray:
    """Per-frame features for the Fréchet distance: root-frame joint positions and velocities (F, 6J)."""
    f = features.extract_features(motion)["features"].astype(np.float64)
    lay = features.PoseLayout(motion.skeleton.num_joints)
    return np.concatenate([f[:, lay.local_positions], f[:, lay.local_velocities]], axis=1)


def probe_datasets(probe_data=(), probe_seeds: int = 0, *, tmp_dir=None, progress: bool = True) -> list:
    """The datasets of the pooled probe: ``(name, clips)`` of each folder of ``probe_data`` (named by its
    path), then of the built-in synthetic dataset of seeds 1..``probe_seeds`` (the same 6 contents x 7
    styles as ``jaxgest synth --seed 0`` with new scripts and performances), written by ``jaxgest synth``'s
    writer into ``tmp_dir`` (required when ``probe_seeds > 0``) and named ``synth-seed-K``."""
    from tqdm.auto import tqdm

    from jaxgest.motion.synthetic.dataset import write_dataset

    out = []
    for d in probe_data or ():
        clips = load_folder(d)
        if not clips:
            raise DataError(f"{d}: no clips for the pooled probe")
        out.append((str(d), clips))
    if probe_seeds < 0:
        raise DataError(f"--probe-seeds must be >= 0, got {probe_seeds}")
    for k in tqdm(range(1, probe_seeds + 1), desc="probe datasets (synth)", disable=not progress, leave=False):
        folder = pathlib.Path(tmp_dir) / f"seed{k}"
        write_dataset(folder, seed=k, progress=False)
        out.append((f"synth-seed-{k}", load_folder(folder)))
    return out


def evaluate(workdir, data_dir, *, seed: int = 0, max_clips: Optional[int] = None, progress: bool = True,
             probe_data=(), probe_seeds: int = 0, generation: bool = True, model=None) -> dict:
    """All three figures for a trained model on a data folder (see the module docstring).

    ``probe_data`` (folders) / ``probe_seeds`` (synthetic seeds 1..N, generated in a temporary folder):
    also the probes on those datasets pooled (:func:`jaxgest.zeggs.probes.pooled_probe`; the same
    leave-one-content-out folds over the pooled clips, CIs over clips and over datasets) as
    ``probe_pooled``. ``generation=False`` skips beat alignment and the Fréchet distance (probes and
    leakage only). ``model``: the loaded model of ``workdir`` when the caller has it already."""
    import tempfile

    from tqdm.auto import tqdm

    if probe_seeds < 0:
        raise DataError(f"--probe-seeds must be >= 0, got {probe_seeds}")
    model = load_model(workdir) if model is None else model
    clips = load_folder(data_dir)
    if not clips:
        raise DataError(f"{data_dir}: no clips")
    result = {"probe": probe(model, clips)}
    if probe_data or probe_seeds:
        with tempfile.TemporaryDirectory(prefix="jaxgest-probe-") as tmp:
            sets = probe_datasets(probe_data, probe_seeds, tmp_dir=tmp, progress=progress)
            result["probe_pooled"] = pooled_probe(model, sets, progress=progress)
    with_audio = [c for c in clips if c.audio is not None]
    result["leakage"] = leakage(model, with_audio) if with_audio else None
    if not generation:
        return result
    train, test = _split_by_style([c for c in clips if c.audio is not None], seed)
    test = test[:max_clips] if max_clips else test
    if not test:
        raise DataError(f"{data_dir}: no test clip with audio for beat alignment")
    gen_scores, real_scores, gen_feats, real_feats, per_clip = [], [], [], [], []
    for c in tqdm(test, desc="zeggs evaluate", disable=not progress, leave=False):
        audio, sr = load_clip_audio(c)
        example = style_example(c, train)
        gen = model.generate(audio, [example.motion], sr=sr, seed=seed, name=f"{c.path.stem}_gen")
        try:
            gen_scores.append(beat_scores(gen, audio, sr, seed=seed))
            real_scores.append(beat_scores(c.motion, audio, sr, seed=seed))
        except DataError:
            continue  # a clip without kinematic beats has no defined score
        per_clip.append({"clip": str(c.path), "style_example": str(example.path), "generated": gen_scores[-1],
                         "real": real_scores[-1]})
        gen_feats.append(motion_statistics_features(gen))
        real_feats.append(motion_statistics_features(c.motion))
    if not gen_scores:
        raise DataError("beat alignment: no test clip produced kinematic beats")

    def mean(xs, k):
        return float(np.mean([x[k] for x in xs]))

    result["beat_alignment"] = {
        "generated": mean(gen_scores, "aligned"), "generated_shuffled": mean(gen_scores, "shuffled"),
        "real": mean(real_scores, "aligned"), "real_shuffled": mean(real_scores, "shuffled"),
        "generated_vs_control": paired_difference(gen_scores), "real_vs_control": paired_difference(real_scores),
        "clips": len(gen_scores), "sigma_s": 0.1, "per_clip": per_clip,
    }
    real_test = np.concatenate(real_feats)
    result["frechet_distance"] = {
        "generated_vs_real": metrics.frechet_distance(np.concatenate(gen_feats), real_test),
        # the floor: other real clips (the training half) against the same real test clips
        "real_train_vs_real_test": metrics.frechet_distance(
            np.concatenate([motion_statistics_features(c.motion) for c in train]), real_test) if train else None,
        "features": "root-frame joint positions and velocities",
    }
    return result


def _diff(d) -> str:
    if not d:
        return ""
    return f" (difference {d['mean']:+.3f} ± {d['standard_error']:.3f} SE, {d['clips_above']}/{d['clips']} clips above)"


def _pm(d) -> str:
    z = "n/a" if d["z"] is None else f"{d['z']:.1f}"
    return f"{d['mean']:+.3f} ± {d['standard_error']:.3f} (z = {z})"


def _probe_lines(p: dict, title: str) -> list:
    lines = [f"| {title} | trained | random init | raw statistics | chance |", "|---|---:|---:|---:|---:|"]
    for task in ("style", "content"):
        t = p[task]
        cells = [f"{t[k]['accuracy']:.3f} ± {t[k]['clip_mean']['ci95_half_width']:.3f}"
                 for k in ("trained", "random_init", "raw_statistics")]
        lines.append(f"| {task} probe accuracy (chance {t['trained']['chance']:.3f}), ± 95 % CI over "
                     f"{t['trained']['clips']} clips ({t['trained']['windows']} windows) | " + " | ".join(cells)
                     + f" | {t['trained']['chance']:.3f} |")
        lines.append(f"| {task}: trained minus control (paired over clips) | | "
                     f"{_pm(t['trained_minus']['random_init'])} | {_pm(t['trained_minus']['raw_statistics'])} | |")
        if "unit_mean" in t["trained"]:
            cells = [f"{t[k]['unit_mean']['mean']:.3f} ± {t[k]['unit_mean']['ci95_half_width']:.3f}"
                     for k in ("trained", "random_init", "raw_statistics")]
            lines.append(f"| {task}: mean of the per-dataset accuracies, ± 95 % CI over {t['trained']['unit_mean']['n']} "
                         "datasets | " + " | ".join(cells) + " | |")
            lines.append(f"| {task}: trained minus control (paired over datasets) | | "
                         f"{_pm(t['trained_minus_by_unit']['random_init'])} | "
                         f"{_pm(t['trained_minus_by_unit']['raw_statistics'])} | |")
    lines += [f"| share of embedding variance explained by style / content | "
              f"{p['style_variance_share']:.3f} / {p['content_variance_share']:.3f} | | | |", ""]
    return lines


def markdown(result: dict) -> str:
    lines = _probe_lines(result["probe"], "probe (leave-one-content-out for style, leave-one-style-out for content)")
    if result.get("probe_pooled"):
        lines += _probe_lines(result["probe_pooled"], f"pooled probe over {len(result['probe_pooled']['datasets'])} "
                              "datasets (same folds: leave-one-content-out / leave-one-style-out)")
    lk = result.get("leakage")
    if lk:
        m = lk["mean_loss"]
        lines += ["| reconstruction loss of fixed targets, style embedding from | loss |", "|---|---:|"]
        lines += [f"| {k.replace('_', ' ')} | {m[k]:.4f} |" for k in LEAKAGE_SOURCES if k in m]
        lines += [f"| contrast {k} (mean ± SE over {lk['clips']} clips) | {_pm(v)} |"
                  for k, v in lk["contrasts"].items()]
        lines.append("")
    if "beat_alignment" not in result:
        return "\n".join(lines)
    b, f = result["beat_alignment"], result["frechet_distance"]
    lines += [
        "| metric | value |",
        "|---|---:|",
        f"| BeatAlign generated / shuffled control | {b['generated']:.3f} / {b['generated_shuffled']:.3f}"
        f"{_diff(b.get('generated_vs_control'))} |",
        f"| BeatAlign real motion / shuffled control | {b['real']:.3f} / {b['real_shuffled']:.3f}"
        f"{_diff(b.get('real_vs_control'))} |",
        f"| Fréchet distance generated vs real | {f['generated_vs_real']:.4g} |",
    ]
    if f.get("real_train_vs_real_test") is not None:
        lines.append(f"| Fréchet distance real (train clips) vs real (test clips) | {f['real_train_vs_real_test']:.4g} |")
    return "\n".join(lines)
