"""Compiled CPU kernels called through ``jax.ffi`` (C++ source inline, built on first use)."""
