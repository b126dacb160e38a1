"""Shared test configuration (STYLE.md): strict JAX promotion rules, a `key` fixture, data paths.

Real-data tests read ../shared/data and skip cleanly when it is absent.
"""

from __future__ import annotations

import os
import pathlib

import jax
import pytest

jax.config.update("jax_numpy_rank_promotion", "raise")
jax.config.update("jax_numpy_dtype_promotion", "strict")

REPO = pathlib.Path(__file__).resolve().parents[1]
SHARED = pathlib.Path(os.environ.get("JAXGEST_SHARED", REPO.parent / "shared")).resolve()
BANDAI = SHARED / "data" / "bandai-namco-1" / "data"
ZEGGS = SHARED / "data" / "speech-gesture" / "zeggs"
BEAT2 = SHARED / "data" / "speech-gesture" / "beat2"


@pytest.fixture
def key():
    return jax.random.PRNGKey(0)


@pytest.fixture(scope="session")
def bandai_dir():
    if not BANDAI.is_dir():
        pytest.skip(f"real data not found at {BANDAI}")
    return BANDAI


@pytest.fixture(scope="session")
def zeggs_dir():
    if not ZEGGS.is_dir():
        pytest.skip(f"real data not found at {ZEGGS}")
    return ZEGGS
