"""Shared test configuration (STYLE.md): strict rank promotion, a `key` fixture, data paths.

Real-data tests read ../shared/data and skip cleanly when it is absent.
"""

from __future__ import annotations

import os
import pathlib

import jax
import pytest

# Implicit rank promotion hides shape bugs: forbid it. Dtype promotion stays "standard": optax's own Adam
# (bias correction `b ** count` with an int32 count) is not "strict"-clean, so strict would test optax,
# not us; our modules cast explicitly instead.
jax.config.update("jax_numpy_rank_promotion", "raise")

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
