"""The pooled probe of ``jaxgest zeggs evaluate --probe-data`` on the session's tiny ZeroEGGS model: datasets
pooled with leave-one-content-out folds over all of them and a second CI over datasets."""

from __future__ import annotations

import pytest

from jaxgest.runtime.errors import DataError


def _relabelled(src, dst, labels):
    """A manifest folder over ``src``'s clips with (content, style) labels of our choice."""
    dst.mkdir()
    rows = ["path,content,style,audio"]
    for p, (content, style) in zip(sorted(src.glob("*.bvh")), labels):
        rows.append(f"{p.resolve()},{content},{style},{p.with_suffix('.wav').resolve()}")
    (dst / "manifest.csv").write_text("\n".join(rows) + "\n")
    return dst


def test_evaluate_pools_probe_datasets(zeggs_workdir, tiny_data, tmp_path):
    from jaxgest.zeggs.evaluate import evaluate, markdown

    labels = [("c0", "a"), ("c0", "b"), ("c1", "a"), ("c1", "b")]
    a = _relabelled(tiny_data, tmp_path / "a", labels)
    b = _relabelled(tiny_data, tmp_path / "b", labels[::-1])
    r = evaluate(zeggs_workdir, a, probe_data=[a, b], generation=False, progress=False)
    assert "beat_alignment" not in r and "frechet_distance" not in r  # generation skipped
    p = r["probe_pooled"]
    assert p["datasets"] == [str(a), str(b)]
    for task, folds in (("style", 2), ("content", 2)):
        for enc in ("trained", "random_init", "raw_statistics"):
            t = p[task][enc]
            assert t["clips"] == 8 and t["folds"] == folds and t["unit_names"] == sorted([str(a), str(b)])
            assert t["unit_mean"]["n"] == 2 and len(t["per_unit"]) == 2
        d = p[task]["trained_minus_by_unit"]["raw_statistics"]
        assert d["mean"] == pytest.approx(p[task]["trained"]["unit_mean"]["mean"]
                                          - p[task]["raw_statistics"]["unit_mean"]["mean"])
    # the same clips relabelled identically in both datasets: the per-dataset accuracies agree
    assert p["style"]["raw_statistics"]["per_unit"][0] == pytest.approx(p["style"]["raw_statistics"]["per_unit"][1])
    md = markdown(r)
    assert "pooled probe over 2 datasets" in md and "CI over 2 datasets" in md and "BeatAlign" not in md
    with pytest.raises(DataError, match="probe-seeds"):
        evaluate(zeggs_workdir, a, probe_seeds=-1, generation=False, progress=False)


def test_encode_windows_batched_equals_clip_by_clip(zeggs_workdir, tiny_data):
    """Batched encoding (windows of several clips and lengths together, padded rows masked out) gives the
    posterior means of encoding each clip's windows alone."""
    import numpy as np

    from jaxgest.motion.datasets import load_folder
    from jaxgest.zeggs import probes
    from jaxgest.zeggs.inference import load_model

    model = load_model(zeggs_workdir)
    clips = load_folder(tiny_data)[:3]
    spec = [(clips[0], 1.0), (clips[1], 2.0), (clips[2], 1.0)]  # two window lengths, interleaved
    xs = [probes._windows(model, c, w, 0.5) for c, w in spec]
    got = probes.encode_windows(model, xs, batch=4)  # 4 < windows per length: several chunks, last one padded
    for (c, w), g in zip(spec, got):
        want = probes.style_windows(model, c, w, stride_s=0.5)
        assert g.shape == want.shape and np.allclose(g, want, atol=1e-5)
