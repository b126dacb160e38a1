"""ZeroEGGS evaluation pieces with known answers (no model): the grouped probe, the leakage plan and its
statistics on planted embeddings."""

from __future__ import annotations

import types

import numpy as np
import pytest

from jaxgest.zeggs import probes

CONTENTS = ["c0", "c1", "c2", "c3", "c4"]
STYLES = ["s0", "s1", "s2", "s3"]


def _clips():
    return [types.SimpleNamespace(content=c, style=s) for c in CONTENTS for s in STYLES]


def _planted_windows(clips, rng, *, style_scale=3.0, content_scale=3.0, windows=6, dims=8):
    style_c = {s: rng.normal(size=dims) * style_scale for s in STYLES}
    content_c = {c: rng.normal(size=dims) * content_scale for c in CONTENTS}
    return [style_c[c.style] + content_c[c.content] + rng.normal(size=(windows, dims)) * 0.3 for c in clips]


def test_mean_se_known_answer():
    d = probes._mean_se([0.2, 0.0, -0.1])  # mean 1/30, sample std sqrt(0.07 / 3)
    assert d["mean"] == pytest.approx(1 / 30) and d["n"] == 3
    assert d["standard_error"] == pytest.approx(np.sqrt(0.07 / 3) / np.sqrt(3))
    assert d["z"] == pytest.approx(d["mean"] / d["standard_error"])
    assert d["ci95_half_width"] == pytest.approx(1.96 * d["standard_error"])
    assert probes._mean_se([1.0])["z"] is None  # one unit: no standard error


def test_grouped_probe_separable_shuffled_and_content_only():
    rng = np.random.default_rng(0)
    clips = _clips()
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    feats = _planted_windows(clips, rng, style_scale=5.0, content_scale=1.0)
    r = probes.grouped_probe(feats, styles, contents)  # leave-one-content-out
    assert r["accuracy"] == 1.0 and r["clip_mean"]["ci95_half_width"] == 0.0
    assert r["chance"] == 0.25 and r["folds"] == 5 and r["clips"] == 20 and r["windows"] == 120
    # labels shuffled across clips: no structure to find, so the probe is near chance (1/4)
    accs = [probes.grouped_probe(feats, list(rng.permutation(styles)), contents)["accuracy"] for _ in range(20)]
    assert abs(np.mean(accs) - 0.25) < 0.1
    # features that only encode the content: leave-one-content-out cannot use them to predict the style
    # (chance), while the content probe (leave-one-style-out) is perfect
    content_only = _planted_windows(clips, rng, style_scale=0.0)
    assert probes.grouped_probe(content_only, styles, contents)["accuracy"] < 0.45
    assert probes.grouped_probe(content_only, contents, styles)["accuracy"] == 1.0
    assert probes.variance_share(content_only, contents) > 0.9 and probes.variance_share(content_only, styles) < 0.1


def test_leakage_plan_sources():
    clips = _clips()
    frames = [600] * len(clips)
    T, M = 64, 128
    plan = probes.leakage_plan(clips, frames, window=T, style_len=M, targets_per_clip=3)
    assert len(plan) == 3 * len(clips)
    seen_contents = set()
    for p in plan:
        c, t0, src = clips[p["clip"]], p["t0"], p["sources"]
        i, s0 = src["own_window"]
        assert i == p["clip"] and s0 <= t0 and t0 + T <= s0 + M  # contains the target
        i, s0 = src["same_clip_disjoint"]
        assert i == p["clip"] and (s0 + M <= t0 or s0 >= t0 + T) and 0 <= s0 <= 600 - M  # apart from it
        j, _ = src["same_style_other_content"]
        k, _ = src["other_style"]
        assert clips[j].style == c.style and clips[j].content != c.content
        assert clips[k].style != c.style and clips[k].content == clips[j].content  # differs by the style only
        assert src["zero"] is None
        seen_contents.add((p["clip"], clips[j].content))
    assert len(seen_contents) == 3 * len(clips)  # another content for each of a clip's targets
    # a clip too short for a target plus a disjoint window has no target
    assert probes.leakage_plan(clips[:2], [T + M - 1, 600], window=T, style_len=M)[0]["clip"] == 1


def _planted_losses(clips, plan, embed, rng):
    """Loss = squared distance of the embedding to the target's true code + target noise (shared by sources)."""
    losses = {k: [] for k in probes.LEAKAGE_SOURCES}
    for p in plan:
        noise = rng.normal() * 0.5
        truth = embed(clips[p["clip"]], p["t0"])
        for k, src in p["sources"].items():
            e = np.zeros_like(truth) if src is None else embed(clips[src[0]], src[1])
            losses[k].append(float(np.sum((e - truth) ** 2)) + noise)
    return {k: np.asarray(v) for k, v in losses.items()}


def test_leakage_statistics_on_planted_embeddings():
    rng = np.random.default_rng(1)
    clips = _clips()
    plan = probes.leakage_plan(clips, [600] * len(clips), window=64, style_len=128)
    groups = [p["clip"] for p in plan]
    code = {s: rng.normal(size=4) for s in STYLES}
    # an embedding that is a function of the style label: another style hurts, the content does not matter
    r = probes.leakage_statistics(_planted_losses(clips, plan, lambda c, s0: code[c.style], rng), groups)
    d = r["contrasts"]["other_style - same_style_other_content"]
    assert d["mean"] > 0 and d["z"] >= 3 and r["contrasts"]["zero - same_style_other_content"]["z"] >= 3
    assert r["contrasts"]["same_style_other_content - same_clip_disjoint"]["mean"] == pytest.approx(0, abs=1e-12)
    assert r["clips"] == 20 and r["targets"] == 60
    # an embedding of the window's content and position (pure leakage): the own window is best, and given
    # the same other content, another style is exactly as good as the same style
    ccode = {c: rng.normal(size=4) for c in CONTENTS}
    leak = _planted_losses(clips, plan, lambda c, s0: ccode[c.content] * (1 + s0 / 600), rng)
    r = probes.leakage_statistics(leak, groups)
    assert r["contrasts"]["other_style - same_style_other_content"]["mean"] == pytest.approx(0, abs=1e-12)
    assert r["contrasts"]["same_clip_disjoint - own_window"]["z"] >= 3
    assert r["mean_loss"]["own_window"] < r["mean_loss"]["same_style_other_content"]


def test_probe_folds_hold_out_each_group_once():
    groups = ["c1", "c0", "c1", "c2", "c0", "c2", "c1"]
    folds = probes.probe_folds(groups)
    assert [g for g, _, _ in folds] == ["c0", "c1", "c2"]
    tested = sorted(i for _, _, test in folds for i in test)
    assert tested == list(range(len(groups)))  # every clip tested exactly once
    for g, train, test in folds:
        assert all(groups[i] == g for i in test) and all(groups[i] != g for i in train)
        assert sorted(train + test) == list(range(len(groups)))
    with pytest.raises(probes.DataError):
        probes.probe_folds(["c0", "c0"])


def test_grouped_probe_one_fit_per_fold_matches_per_clip_refits():
    """One fit per fold scores every clip as a probe refitted for that clip alone would."""
    rng = np.random.default_rng(2)
    clips = _clips()
    styles, contents = [c.style for c in clips], [c.content for c in clips]
    feats = _planted_windows(clips, rng, style_scale=1.0, content_scale=1.0)  # noisy: accuracies in (0, 1)
    r = probes.grouped_probe(feats, styles, contents)
    for g, train, test in probes.probe_folds(contents):
        xtr = np.concatenate([feats[i] for i in train])
        ytr = np.concatenate([[styles[i]] * len(feats[i]) for i in train])
        for i in test:
            assert r["per_clip"][i] == probes.metrics.linear_probe_accuracy(xtr, ytr, feats[i], [styles[i]] * 6)
    assert 0.25 < r["accuracy"] < 1.0  # neither chance nor perfect: the comparison above is not trivial


def test_grouped_probe_units_pooled_datasets():
    """Pooled datasets: the folds are by content across all datasets and the second CI is over datasets."""
    rng = np.random.default_rng(3)
    clips = _clips()
    # dataset "a": style well separated; dataset "b": the same centres, windows drowned in noise
    style_c = {s: rng.normal(size=8) * 3.0 for s in STYLES}
    good = [style_c[c.style] + rng.normal(size=(6, 8)) * 0.1 for c in clips]
    bad = [style_c[c.style] + rng.normal(size=(6, 8)) * 6.0 for c in clips]
    feats, styles = good + bad, [c.style for c in clips] * 2
    contents, units = [c.content for c in clips] * 2, ["a"] * len(clips) + ["b"] * len(clips)
    r = probes.grouped_probe(feats, styles, contents, units)
    assert r["folds"] == len(CONTENTS) and r["clips"] == 2 * len(clips)
    assert r["unit_names"] == ["a", "b"]
    per = np.asarray(r["per_clip"])
    assert r["per_unit"] == pytest.approx([per[:20].mean(), per[20:].mean()])
    assert r["per_unit"][0] > 0.9 and r["per_unit"][1] < 0.7
    # CI over units: the mean of the two dataset means, SE of two values
    m = probes._mean_se(r["per_unit"])
    assert r["unit_mean"] == m and m["n"] == 2
    assert m["standard_error"] == pytest.approx(abs(r["per_unit"][0] - r["per_unit"][1]) / 2)
    # the clip-level CI of the pooled set: SE over all 40 clips
    assert r["clip_mean"]["standard_error"] == pytest.approx(per.std(ddof=1) / np.sqrt(40))
    assert probes.unit_means([1.0, 0.0, 0.5, 0.5], ["y", "x", "y", "x"]) == (["x", "y"], [0.25, 0.75])
