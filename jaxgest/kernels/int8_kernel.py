"""A CPU kernel for the int8 weight format at small batch: ``y = x . dequant(q, scale)`` streaming int8.

XLA CPU has no mixed-precision matrix-vector kernel: in the generator's scan it hoists the (loop-invariant)
int8 -> float32 conversion out of the loop and streams float32 weights; with that hoisting disabled it
fuses convert + multiply + reduce into one loop that is no faster than the float32 dot. This module holds a
small C++ kernel (AVX-512: sign-extend 16 int8 weights, convert, FMA with x, one FMA per group with its
scale; a portable loop otherwise), registered with XLA through ``jax.ffi`` and called from
:func:`jaxgest.zeggs.quant.dense_apply` when the batch is small.

The kernel is compiled on first use with the system's C++ compiler (``$CXX`` or ``g++``/``c++``,
``-O3 -march=native``) into ``$JAXGEST_CACHE_DIR`` (default ``~/.cache/jaxgest``), keyed on the source,
the jaxlib version and the CPU's feature flags; nothing is built at install time. Without a compiler, on
a non-CPU backend, when the build fails, or with ``JAXGEST_INT8_KERNEL=0`` :func:`available` is False
and the weight format runs through XLA (same numbers up to float reassociation).

Layout: ``q (out, in_padded)`` int8 row-major (input channels contiguous), ``scale (out, in_padded / G)``
float32, groups of G consecutive input channels; ``x (rows, in)`` float32 with ``in <= in_padded`` (the
padded weights are zero).

Threads: the output rows are cut into chunks (multiples of 4 rows, >= 64 kB of weights, ~8 per worker)
that the calling thread and helper tasks scheduled on XLA's own intra-op thread pool (``ffi::ThreadPool``
from the FFI execution context; no thread is created per call) claim from an atomic counter. The caller
never waits for a task that has not started (it takes the remaining chunks itself and waits only for
chunks being computed), so a busy or descheduled pool thread costs at most one chunk, and the pool cannot
deadlock. Each output row is computed exactly as single-threaded (same 4-row blocks, same order): the
result does not depend on the number of workers (:func:`threads`, ``$JAXGEST_INT8_THREADS``).

References: Jacob et al. 2018 (weight-only integer quantisation); the XLA FFI (``jax.ffi``).
"""

from __future__ import annotations

import functools
import hashlib
import os
import pathlib
import platform
import shutil
import subprocess
import tempfile
from typing import Optional

import jax
import jax.numpy as jnp
import numpy as np

TARGET = "jaxgest_int8_gemv"
MAX_ROWS = 4  # batch rows up to which the kernel is used (it streams the weights once per row)

SOURCE = r"""
#include <algorithm>
#include <atomic>
#include <cstdint>
#include <cstring>
#include <memory>
#include <thread>
#include <vector>
#if defined(__AVX512F__)
#include <immintrin.h>
#endif
#include "xla/ffi/api/ffi.h"
namespace ffi = xla::ffi;

#if defined(__AVX512F__)
#define W(p) _mm512_cvtepi32_ps(_mm512_cvtepi8_epi32(_mm_loadu_si128((const __m128i*)(p))))
#endif

static void rows(const float* xp, const int8_t* q, const float* sc, float* y, int64_t n0, int64_t n1,
                 int64_t Kp, int64_t NG, int64_t G) {
#if defined(__AVX512F__)
  if (G % 16 == 0) {
    int64_t n = n0;
    for (; n + 4 <= n1; n += 4) {
      __m512 a0 = _mm512_setzero_ps(), a1 = a0, a2 = a0, a3 = a0;
      const int8_t* r0 = q + n * Kp; const int8_t* r1 = r0 + Kp;
      const int8_t* r2 = r1 + Kp; const int8_t* r3 = r2 + Kp;
      const float* s0 = sc + n * NG; const float* s1 = s0 + NG;
      const float* s2 = s1 + NG; const float* s3 = s2 + NG;
      for (int64_t g = 0; g < NG; ++g) {
        __m512 v0 = _mm512_setzero_ps(), v1 = v0, v2 = v0, v3 = v0;
        for (int64_t k = g * G; k < (g + 1) * G; k += 16) {
          __m512 xv = _mm512_loadu_ps(xp + k);
          v0 = _mm512_fmadd_ps(W(r0 + k), xv, v0);
          v1 = _mm512_fmadd_ps(W(r1 + k), xv, v1);
          v2 = _mm512_fmadd_ps(W(r2 + k), xv, v2);
          v3 = _mm512_fmadd_ps(W(r3 + k), xv, v3);
        }
        a0 = _mm512_fmadd_ps(v0, _mm512_set1_ps(s0[g]), a0);
        a1 = _mm512_fmadd_ps(v1, _mm512_set1_ps(s1[g]), a1);
        a2 = _mm512_fmadd_ps(v2, _mm512_set1_ps(s2[g]), a2);
        a3 = _mm512_fmadd_ps(v3, _mm512_set1_ps(s3[g]), a3);
      }
      y[n] = _mm512_reduce_add_ps(a0); y[n + 1] = _mm512_reduce_add_ps(a1);
      y[n + 2] = _mm512_reduce_add_ps(a2); y[n + 3] = _mm512_reduce_add_ps(a3);
    }
    n0 = n;
  }
#endif
  for (int64_t n = n0; n < n1; ++n) {
    const int8_t* row = q + n * Kp;
    float acc = 0.f;
    for (int64_t g = 0; g < NG; ++g) {
      float s = 0.f;
      for (int64_t k = g * G; k < (g + 1) * G; ++k) s += (float)row[k] * xp[k];
      acc += s * sc[n * NG + g];
    }
    y[n] = acc;
  }
}

// One call's work, shared with the pool's helper tasks (which may start after the call has returned: they
// hold the state through a shared_ptr and find no chunk left).
struct Job {
  const int8_t* q; const float* sc; float* y;
  int64_t O, Kp, NG, G, B, chunk, nchunks;
  std::vector<float> xp;  // B rows of x, zero-padded to Kp
  std::atomic<int64_t> next{0}, done{0};
};

// Claim chunks of output rows until none is left (all batch rows of a chunk while its weights are hot).
static void work(Job* j) {
  for (;;) {
    const int64_t c = j->next.fetch_add(1, std::memory_order_relaxed);
    if (c >= j->nchunks) return;
    const int64_t n0 = c * j->chunk, n1 = std::min(j->O, n0 + j->chunk);
    for (int64_t b = 0; b < j->B; ++b)
      rows(j->xp.data() + b * j->Kp, j->q, j->sc, j->y + b * j->O, n0, n1, j->Kp, j->NG, j->G);
    j->done.fetch_add(1, std::memory_order_release);
  }
}

static ffi::Error Impl(ffi::ThreadPool pool, ffi::Buffer<ffi::F32> x, ffi::Buffer<ffi::S8> q,
                       ffi::Buffer<ffi::F32> scale, ffi::ResultBuffer<ffi::F32> y, int64_t threads) {
  auto qd = q.dimensions();
  auto xd = x.dimensions();
  if (qd.size() != 2 || scale.dimensions().size() != 2 || xd.size() != 2)
    return ffi::Error(ffi::ErrorCode::kInvalidArgument, "int8 gemv: x, q, scale must be 2-D");
  const int64_t O = qd[0], Kp = qd[1], NG = scale.dimensions()[1], K = xd[1], B = xd[0];
  if (NG <= 0 || Kp % NG != 0 || K > Kp || scale.dimensions()[0] != O)
    return ffi::Error(ffi::ErrorCode::kInvalidArgument, "int8 gemv: inconsistent shapes");
  auto job = std::make_shared<Job>();
  job->q = q.typed_data(); job->sc = scale.typed_data(); job->y = y->typed_data();
  job->O = O; job->Kp = Kp; job->NG = NG; job->G = Kp / NG; job->B = B;
  job->xp.assign(B * Kp, 0.f);
  for (int64_t b = 0; b < B; ++b)
    std::memcpy(job->xp.data() + b * Kp, x.typed_data() + b * K, K * sizeof(float));
  // Workers: the caller plus helpers on XLA's intra-op pool (threads <= 0: the pool's size). Chunks are
  // multiples of 4 rows (the 4-row blocks of `rows` fall where they fall single-threaded: same results),
  // at least kMinChunkBytes of weights each, about 8 per worker so that a late or descheduled helper holds
  // little work; small products run in the caller alone.
  constexpr int64_t kMinChunkBytes = 64 * 1024;
  int64_t workers = threads > 0 ? threads : pool.num_threads();
  workers = std::max<int64_t>(1, std::min<int64_t>(workers, O / 4));
  int64_t chunk = O, nchunks = 1;
  if (workers > 1) {
    chunk = std::max<int64_t>((O / (8 * workers) + 3) / 4 * 4, (kMinChunkBytes / Kp + 3) / 4 * 4);
    chunk = std::max<int64_t>(chunk, 4);
    nchunks = (O + chunk - 1) / chunk;
    if (nchunks < 2) { chunk = O; nchunks = 1; }
  }
  job->chunk = chunk; job->nchunks = nchunks;
  if (nchunks > 1) {
    for (int64_t t = 1; t < std::min(workers, nchunks); ++t) pool.Schedule([job] { work(job.get()); });
  }
  work(job.get());
  // Every chunk is claimed; wait only for the ones a helper is running now (never for a queued task).
  for (int spins = 0; job->done.load(std::memory_order_acquire) < nchunks; ++spins) {
    if (spins < 4096) {
#if defined(__x86_64__)
      __builtin_ia32_pause();
#endif
    } else {
      std::this_thread::yield();
    }
  }
  return ffi::Error::Success();
}

XLA_FFI_DEFINE_HANDLER_SYMBOL(JaxgestInt8Gemv, Impl,
                              ffi::Ffi::Bind()
                                  .Ctx<ffi::ThreadPool>()
                                  .Arg<ffi::Buffer<ffi::F32>>()
                                  .Arg<ffi::Buffer<ffi::S8>>()
                                  .Arg<ffi::Buffer<ffi::F32>>()
                                  .Ret<ffi::Buffer<ffi::F32>>()
                                  .Attr<int64_t>("threads"));
"""


def _cpu_flags() -> str:
    try:
        for line in pathlib.Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("flags"):
                return line
    except OSError:
        pass
    return platform.processor()


def _compiler() -> Optional[str]:
    for name in (os.environ.get("CXX"), "g++", "c++", "clang++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def cache_dir() -> pathlib.Path:
    return pathlib.Path(os.environ.get("JAXGEST_CACHE_DIR") or pathlib.Path.home() / ".cache" / "jaxgest")


def build(compiler: Optional[str] = None) -> Optional[pathlib.Path]:
    """The compiled kernel (built now if not cached), or None when it cannot be built."""
    compiler = compiler or _compiler()
    if compiler is None or platform.system() != "Linux":
        return None
    import jaxlib

    flags = ["-O3", "-march=native", "-std=c++17", "-shared", "-fPIC", "-w", "-I", jax.ffi.include_dir()]
    key = hashlib.sha256("\n".join([SOURCE, jaxlib.__version__, _cpu_flags(), compiler] + flags).encode())
    out = cache_dir() / "ffi" / f"int8_gemv-{key.hexdigest()[:16]}.so"
    if out.exists():
        return out
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=out.parent) as tmp:
            src = pathlib.Path(tmp) / "int8_gemv.cc"
            src.write_text(SOURCE)
            lib = pathlib.Path(tmp) / out.name
            subprocess.run([compiler, *flags, str(src), "-o", str(lib)], check=True, capture_output=True,
                           timeout=300)
            os.replace(lib, out)  # atomic: concurrent first uses do not see a partial file
    except (OSError, subprocess.SubprocessError):
        return None
    return out


@functools.lru_cache(maxsize=None)
def available() -> bool:
    """True when the kernel is compiled and registered as the XLA CPU target :data:`TARGET`."""
    if os.environ.get("JAXGEST_INT8_KERNEL", "1") == "0" or jax.default_backend() != "cpu":
        return False
    path = build()
    if path is None:
        return False
    import ctypes

    try:
        lib = ctypes.cdll.LoadLibrary(str(path))
        jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(lib.JaxgestInt8Gemv), platform="cpu")
    except (OSError, AttributeError, ValueError):
        return False
    return True


def threads() -> int:
    """Workers per call (traced into the call): ``$JAXGEST_INT8_THREADS``, default 0 = the size of XLA's
    intra-op pool (every core of the process); 1 = the caller's thread only."""
    try:
        return max(0, int(os.environ.get("JAXGEST_INT8_THREADS", "0")))
    except ValueError:
        return 0


def gemv(x: jax.Array, q: jax.Array, scale: jax.Array, *, num_threads: Optional[int] = None) -> jax.Array:
    """``x (rows, in) float32`` times the int8 kernel ``q (out, in_padded)`` with group ``scale``:
    ``(rows, out)`` float32 (call only when :func:`available`). ``num_threads``: workers (default
    :func:`threads`; 0 = XLA's intra-op pool size); the result does not depend on it."""
    n = threads() if num_threads is None else max(0, int(num_threads))
    return jax.ffi.ffi_call(TARGET, jax.ShapeDtypeStruct((x.shape[0], q.shape[0]), jnp.float32))(
        x.astype(jnp.float32), q, scale, threads=np.int64(n))
