"""PCA control of style embeddings: fit, explained variance, edits, errors, persistence."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from jaxgest.runtime.errors import CheckpointError, JaxgestError
from jaxgest.zeggs.pca import StylePCA, fit_pca, parse_edits


def data(seed=0, n=200, d=8):
    rng = np.random.default_rng(seed)
    scales = np.array([5.0, 2.0, 1.0, 0.5, 0.2, 0.1, 0.05, 0.01])[:d]
    basis = np.linalg.qr(rng.normal(size=(d, d)))[0]
    return (rng.normal(size=(n, d)) * scales) @ basis.T + rng.normal(size=d), basis, scales


def test_fit_recovers_variance_order_and_ratio_sums_to_one():
    x, basis, scales = data()
    pca = fit_pca(x)
    assert np.all(np.diff(pca.explained_variance_ratio) <= 1e-12)
    np.testing.assert_allclose(pca.explained_variance_ratio.sum(), 1.0)
    np.testing.assert_allclose(pca.components @ pca.components.T, np.eye(8), atol=1e-9)
    assert abs(abs(pca.components[0] @ basis[:, 0]) - 1) < 0.05  # first axis found
    assert pca.std[0] == pytest.approx(5.0, rel=0.15)


@settings(max_examples=20, deadline=None)
@given(st.integers(0, 7), st.floats(-3, 3))
def test_edit_moves_only_the_chosen_coordinate(k, delta):
    x, _, _ = data(1)
    pca = fit_pca(x)
    e = x[:5]
    moved = pca.edit(e, {k: delta})
    d = pca.project(moved) - pca.project(e)
    expected = np.zeros(8)
    expected[k] = delta * pca.std[k]
    np.testing.assert_allclose(d, np.broadcast_to(expected, d.shape), atol=1e-9)
    np.testing.assert_allclose(pca.edit(e, {}), e)


def test_errors_and_round_trip(tmp_path):
    pca = fit_pca(data()[0], num_components=3)
    with pytest.raises(JaxgestError, match="component 3 does not exist"):
        pca.edit(np.zeros(8), {3: 1.0})
    with pytest.raises(JaxgestError, match="COMPONENT=DELTA"):
        parse_edits(["x"])
    assert parse_edits(["0=2", "2=-1.5"]) == {0: 2.0, 2: -1.5}
    with pytest.raises(CheckpointError, match="no PCA fitted"):
        StylePCA.load(tmp_path / "pca.json")
    pca.save(tmp_path / "pca.json")
    back = StylePCA.load(tmp_path / "pca.json")
    np.testing.assert_allclose(back.components, pca.components)
    with pytest.raises(JaxgestError, match="at least 2"):
        fit_pca(np.zeros((1, 4)))
