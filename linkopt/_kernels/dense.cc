// Batched small dense linear algebra as XLA FFI handlers (CPU), and the `_dense`
// extension module that hands them to Python as capsules.
//
// Handlers (float64, row-major; every leading dimension is a batch dimension):
//   LkCholesky      a (..., n, n)            -> lower Cholesky factor L (reads the lower
//                                               triangle; NaN from the first
//                                               non-positive pivot on)
//   LkTriSolve      L (..., n, n), b (..., n, k), attribute `mode` (int32):
//                   0: L x = b, 1: Lᵀ x = b, 2: L Lᵀ x = b          -> x (..., n, k)
//   LkLowerInverse  L (..., n, n)            -> L⁻¹ (lower triangle of L read)
//   LkDampedSolve   a (..., n, n), d (...), b (..., n) -> (a + d I)⁻¹ b: LkCholesky of
//                   a + d I and LkTriSolve mode 2 in one call (n <= kLanesMaxN)
//   LkSmallestRight a (..., n, n) = JᵀJ, start (..., n, k), attributes `iterations`,
//                   `sweeps` (int32), `shift` (f64) -> the right singular vector of J's
//                   smallest singular value (..., n) by block inverse iteration and
//                   Rayleigh–Ritz (smallest_right; k <= kSmallestMaxK)
//   LkNormalEquations rows (..., m, 14), c (..., m), attribute `pairs` (int32, 2 m)
//                   -> JᵀJ (..., n, n), Jᵀc (..., n) of the J whose row r holds
//                   rows[r, :7] in the 7 columns of body pairs[2r] and rows[r, 7:]
//                   in those of body pairs[2r + 1] (-1: none), n = 7 x bodies
//   LkBandFactor    band (..., B, w + 1, 7, 7), d (...) -> the lower block Cholesky
//                   factor of band + d I in the same block-band storage (band[i][k] =
//                   H[i, i - k]; linkopt/_engine/band_factor.py; NaN from a failing
//                   pivot on)
//   LkBandSolve     L (..., B, w + 1, 7, 7) of LkBandFactor, b (..., B, 7), attribute
//                   `mode` (int32) as LkTriSolve's -> x (..., B, 7); each batch
//                   dimension of L and b is 1 or the result's (one factor, many b)
//   LkBandNormal    rows (..., m, 14), c (..., m), attribute `pairs` (int32, 2 m)
//                   -> JᵀJ (..., B, w + 1, 7, 7) in LkBandFactor's storage, Jᵀc
//                   (..., B, 7): LkNormalEquations with pairs naming block rows (their
//                   distance under w + 1)
//   LkArrowNormal   the same with h hub bodies last -> the others' band (..., n, w + 1,
//                   7, 7), border (..., n, h, 7, 7) = H[hub j, body i], corner (..., h,
//                   h, 7, 7) (both triangles), Jᵀc (..., n + h, 7)
// Every handler refuses n > kMaxN (LkDampedSolve n > kLanesMaxN, LkSmallestRight
// k > kSmallestMaxK), mismatched shapes and an unknown mode with an ffi::Error; none
// allocates but for the scratch of large orders (with_scratch); an empty operand (n or
// the batch 0) returns at once.
// Single-threaded, plain loops written as axpys so -O3 vectorises them without
// -ffast-math (no reassociated reductions, except the explicit 4-accumulator dot);
// LkCholesky and LkDampedSolve work on two or four matrices of a batch at a time
// (chol_lanes).
//
// kVersion is the ABI of these handlers (names, operands, attributes, semantics):
// increment it with any such change; linkopt/_kernels/__init__.py refuses an extension
// of another version.
//
// IEEE arithmetic is part of the results (bitwise the same for any batch grouping, NaN
// from a failing pivot): fast math is refused here, whatever flags a build adds.
// LK_NO_PYTHON leaves out the Python module (tests/kernels_harness.cc includes this file
// and calls the handlers' *Impl functions directly, under the sanitizers).
#if defined(__FAST_MATH__) || defined(_M_FP_FAST) || \
    (defined(__FINITE_MATH_ONLY__) && __FINITE_MATH_ONLY__)
#error "dense.cc must not be built with fast math (-ffast-math, -Ofast, /fp:fast, icx's default): it relies on IEEE NaN and rounding"
#endif

#ifndef LK_NO_PYTHON
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#endif

#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <initializer_list>
#include <limits>
#include <string>

#if defined(_WIN32)
#include <malloc.h>  // _aligned_malloc
#endif

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr long kVersion = 5;
constexpr int64_t kMaxN = 512;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// l = lower Cholesky factor of the lower triangle of a (n x n, row-major); a and l may
// be the same buffer. Right-looking: after column k is final, the trailing lower
// triangle gets a[i, k+1..i] -= L[i,k] * L[k+1..i, k], with L[:, k] copied to the
// contiguous buffer col (n entries). NaN in L[i, c] for all c >= the first
// non-positive (or NaN) pivot, i >= c.
void chol_in_place(double* __restrict l, int64_t n, double* __restrict col);

void chol_one(const double* a, double* __restrict l, int64_t n, double* __restrict col) {
  if (a != l)
    for (int64_t i = 0; i < n; ++i)
      for (int64_t j = 0; j <= i; ++j) l[i * n + j] = a[i * n + j];
  chol_in_place(l, n, col);
}

// chol_one with a = l: the lower triangle of l holds a.
void chol_in_place(double* __restrict l, int64_t n, double* __restrict col) {
  for (int64_t i = 0; i < n; ++i)
    for (int64_t j = i + 1; j < n; ++j) l[i * n + j] = 0.0;
  for (int64_t k = 0; k < n; ++k) {
    double d = l[k * n + k];
    if (!(d > 0.0)) {  // non-positive or NaN pivot: NaN from column k on
      for (int64_t i = k; i < n; ++i)
        for (int64_t j = k; j <= i; ++j) l[i * n + j] = kNaN;
      return;
    }
    d = std::sqrt(d);
    l[k * n + k] = d;
    for (int64_t i = k + 1; i < n; ++i) {
      const double v = l[i * n + k] / d;  // division, as dense.cholesky (col / pivot)
      l[i * n + k] = v;
      col[i] = v;
    }
    for (int64_t i = k + 1; i < n; ++i) {
      const double lik = col[i];
      double* __restrict row = l + i * n;
      for (int64_t j = k + 1; j <= i; ++j) row[j] -= lik * col[j];
    }
  }
}

inline double dot(const double* __restrict x, const double* __restrict y, int64_t m) {
  double s0 = 0, s1 = 0, s2 = 0, s3 = 0;
  int64_t j = 0;
  for (; j + 4 <= m; j += 4) {
    s0 += x[j] * y[j];
    s1 += x[j + 1] * y[j + 1];
    s2 += x[j + 2] * y[j + 2];
    s3 += x[j + 3] * y[j + 3];
  }
  for (; j < m; ++j) s0 += x[j] * y[j];
  return (s0 + s1) + (s2 + s3);
}

// In place: x (n x k, row-major) <- L^{-1} x.
void forward(const double* __restrict l, double* __restrict x, int64_t n, int64_t k) {
  if (k == 1) {
    for (int64_t i = 0; i < n; ++i) x[i] = (x[i] - dot(l + i * n, x, i)) / l[i * n + i];
    return;
  }
  for (int64_t i = 0; i < n; ++i) {
    double* __restrict xi = x + i * k;
    const double* li = l + i * n;
    for (int64_t j = 0; j < i; ++j) {
      const double c = li[j];
      const double* __restrict xj = x + j * k;
      for (int64_t c2 = 0; c2 < k; ++c2) xi[c2] -= c * xj[c2];
    }
    const double d = li[i];
    for (int64_t c2 = 0; c2 < k; ++c2) xi[c2] /= d;
  }
}

// In place: x (n x k) <- L^{-T} x. Column-oriented back substitution: once row i of x
// is final, subtract L[i, :i]^T x[i, :] from the rows above (contiguous row of L).
void backward_t(const double* __restrict l, double* __restrict x, int64_t n, int64_t k) {
  if (k == 1) {
    for (int64_t i = n - 1; i >= 0; --i) {
      const double* __restrict li = l + i * n;
      const double xi = x[i] / li[i];
      x[i] = xi;
      for (int64_t j = 0; j < i; ++j) x[j] -= li[j] * xi;
    }
    return;
  }
  for (int64_t i = n - 1; i >= 0; --i) {
    const double* li = l + i * n;
    double* __restrict xi = x + i * k;
    const double d = li[i];
    for (int64_t c2 = 0; c2 < k; ++c2) xi[c2] /= d;
    for (int64_t j = 0; j < i; ++j) {
      const double c = li[j];
      double* __restrict xj = x + j * k;
      for (int64_t c2 = 0; c2 < k; ++c2) xj[c2] -= c * xi[c2];
    }
  }
}

// x = L^{-1} (lower triangular; only the lower triangle of L read; x not aliasing l).
void lower_inverse_one(const double* __restrict l, double* __restrict x, int64_t n) {
  std::memset(x, 0, sizeof(double) * n * n);
  for (int64_t i = 0; i < n; ++i) {
    double* __restrict xi = x + i * n;
    const double* li = l + i * n;
    xi[i] = 1.0;
    for (int64_t j = 0; j < i; ++j) {  // row j of X is nonzero in columns 0..j
      const double c = li[j];
      const double* __restrict xj = x + j * n;
      for (int64_t c2 = 0; c2 <= j; ++c2) xi[c2] -= c * xj[c2];
    }
    const double d = li[i];
    for (int64_t c2 = 0; c2 <= i; ++c2) xi[c2] /= d;
  }
}

// ---- several matrices at a time ------------------------------------------------------
//
// A batch is factored a group of matrices at a time, side by side: element (i, j) of the
// group is one vector of L lanes (GCC/Clang vector extensions), in a packed lower
// triangle (row i from tri(i) on). L = 2 (an SSE2 register on x86-64) everywhere; L = 4
// (AVX2) in functions compiled for it and called only where the CPU has it
// (__builtin_cpu_supports), so the module still runs on any x86-64-v2 CPU. Every
// operation of chol_lanes, forward_lanes and backward_t_lanes is the one chol_one,
// forward and backward_t apply to each matrix, in the same order (no reassociation, no
// FMA: setup.py builds with -ffp-contract=off), so results are bitwise the same for any
// L; the compiler vectorises across the group instead of along short, unaligned rows.
// A lane whose factor fails (a non-positive or NaN pivot) is recomputed by the
// one-matrix code, which writes its NaN pattern. These paths take n <= kLanesMaxN;
// larger orders run the one-matrix code.

constexpr int64_t tri(int64_t i) { return i * (i + 1) / 2; }

// The largest order of the group paths and of the damped solve (a Stewart platform's
// 13 bodies are 91 coordinates).
constexpr int64_t kLanesMaxN = 160;

// Doubles of a group path's scratch: a packed group of four and its right-hand sides,
// or one full n x n matrix.
constexpr int64_t lanes_scratch(int64_t n) {
  return 4 * tri(n) + 4 * n > n * n ? 4 * tri(n) + 4 * n : n * n;
}

// Scratch of one call: 64-byte aligned doubles, on the stack up to kStackScratch
// doubles (128 KiB, the orders up to 89 of the group paths), else on the heap.
// with_scratch(doubles, f) returns f(scratch); the stack array lives only in the frame
// of stack_scratch (never inlined), so a call whose scratch is on the heap, or that
// needs none, keeps a small frame (threads with small stacks, e.g. musl's 128 KiB).
constexpr int64_t kStackScratch = 16384;

#if defined(__GNUC__) || defined(__clang__)
#define LK_NOINLINE __attribute__((noinline))
#elif defined(_MSC_VER)
#define LK_NOINLINE __declspec(noinline)
#else
#define LK_NOINLINE
#endif

// 64-byte aligned heap memory (null when it fails), freed by free_aligned: the C
// library's own aligned allocation (std::aligned_alloc is missing from MSVC and from
// libc++ for older macOS targets).
double* alloc_aligned(int64_t doubles) {
  const size_t bytes = ((static_cast<size_t>(doubles) * sizeof(double) + 63) / 64) * 64;
#if defined(_WIN32)
  return static_cast<double*>(_aligned_malloc(bytes, 64));
#else
  void* p = nullptr;
  return posix_memalign(&p, 64, bytes) == 0 ? static_cast<double*>(p) : nullptr;
#endif
}

void free_aligned(double* p) {
#if defined(_WIN32)
  _aligned_free(p);
#else
  std::free(p);
#endif
}

template <class F>
LK_NOINLINE ffi::Error stack_scratch(F& f) {
  alignas(64) double stack[kStackScratch];
  return f(stack);
}

template <class F>
LK_NOINLINE ffi::Error heap_scratch(int64_t doubles, F& f) {
  double* heap = alloc_aligned(doubles);
  if (heap == nullptr) return ffi::Error::Internal("out of memory");
  ffi::Error result = f(heap);
  free_aligned(heap);
  return result;
}

template <class F>
ffi::Error with_scratch(int64_t doubles, F&& f) {
  return doubles <= kStackScratch ? stack_scratch(f) : heap_scratch(doubles, f);
}

#if defined(__GNUC__) || defined(__clang__)
#define LK_LANES 1
#define LK_INLINE inline __attribute__((always_inline))
#if defined(__x86_64__)
#define LK_AVX2 1
#endif
#else
#define LK_INLINE inline
#endif

#ifdef LK_LANES
typedef double V2 __attribute__((vector_size(16)));
#ifdef LK_AVX2
typedef double V4 __attribute__((vector_size(32)));
#endif

template <class V>
constexpr int lanes() {
  return sizeof(V) / sizeof(double);
}

// Bit w set where lane w of the pivot v is not positive (or is NaN).
template <class V>
LK_INLINE unsigned failed(const V& v) {
  unsigned bad = 0;
  for (int w = 0; w < lanes<V>(); ++w)
    if (!(v[w] > 0.0)) bad |= 1u << w;
  return bad;
}

template <class V>
LK_INLINE void sqrt_lanes(const V& v, V& root) {
  for (int w = 0; w < lanes<V>(); ++w) root[w] = std::sqrt(v[w]);
}

// p <- the lower triangles of the lanes<V>() consecutive n x n matrices from a on,
// side by side, with d[w] added to the diagonal of matrix w when Damped.
template <bool Damped, class V>
LK_INLINE void pack(const double* a, int64_t n, V* __restrict p, const double* d) {
  const int64_t nn = n * n;
  for (int64_t i = 0; i < n; ++i) {
    V* __restrict row = p + tri(i);
    for (int64_t j = 0; j <= i; ++j)
      for (int w = 0; w < lanes<V>(); ++w) row[j][w] = a[w * nn + i * n + j];
    if (Damped)
      for (int w = 0; w < lanes<V>(); ++w) row[i][w] = a[w * nn + i * n + i] + d[w];
  }
}

// l (n x n, row-major) <- lane w of the packed factor p, zero above the diagonal.
template <class V>
LK_INLINE void unpack_lane(const V* p, int64_t n, int w, double* __restrict l) {
  for (int64_t i = 0; i < n; ++i) {
    const V* row = p + tri(i);
    double* __restrict out = l + i * n;
    for (int64_t j = 0; j <= i; ++j) out[j] = row[j][w];
    for (int64_t j = i + 1; j < n; ++j) out[j] = 0.0;
  }
}

// In place: the lower Cholesky factors of the packed group p (chol_one's operations
// per lane: element (i, j) is a[i, j] - L[i, 0] L[j, 0] - ... - L[i, j-1] L[j, j-1],
// subtracted in that order, then divided by L[j, j], or its square root on the
// diagonal). Left-looking, two columns j, j + 1 at a time and four rows at a time: eight
// independent sums. Returns the lanes with a failing pivot (bit w for lane w); their
// values are then meaningless.
template <class V>
LK_INLINE unsigned chol_lanes(V* __restrict p, int64_t n) {
  unsigned bad = 0;
  int64_t j = 0;
  for (; j + 2 <= n; j += 2) {
    V* __restrict rj = p + tri(j);
    V* __restrict rk = p + tri(j + 1);
    V sjj = rj[j], skj = rk[j], skk = rk[j + 1];
    for (int64_t k = 0; k < j; ++k) {
      sjj -= rj[k] * rj[k];
      skj -= rk[k] * rj[k];
      skk -= rk[k] * rk[k];
    }
    bad |= failed(sjj);
    V dj, dk;
    sqrt_lanes(sjj, dj);
    rj[j] = dj;
    const V lkj = skj / dj;
    rk[j] = lkj;
    skk -= lkj * lkj;
    bad |= failed(skk);
    sqrt_lanes(skk, dk);
    rk[j + 1] = dk;
    int64_t i = j + 2;
    for (; i + 4 <= n; i += 4) {
      V* __restrict r0 = p + tri(i);
      V* __restrict r1 = p + tri(i + 1);
      V* __restrict r2 = p + tri(i + 2);
      V* __restrict r3 = p + tri(i + 3);
      V a0 = r0[j], a1 = r1[j], a2 = r2[j], a3 = r3[j];
      V b0 = r0[j + 1], b1 = r1[j + 1], b2 = r2[j + 1], b3 = r3[j + 1];
      for (int64_t k = 0; k < j; ++k) {
        const V x = rj[k], y = rk[k];
        const V q0 = r0[k], q1 = r1[k], q2 = r2[k], q3 = r3[k];
        a0 -= q0 * x;
        a1 -= q1 * x;
        a2 -= q2 * x;
        a3 -= q3 * x;
        b0 -= q0 * y;
        b1 -= q1 * y;
        b2 -= q2 * y;
        b3 -= q3 * y;
      }
      a0 /= dj;
      a1 /= dj;
      a2 /= dj;
      a3 /= dj;
      r0[j] = a0;
      r1[j] = a1;
      r2[j] = a2;
      r3[j] = a3;
      r0[j + 1] = (b0 - a0 * lkj) / dk;
      r1[j + 1] = (b1 - a1 * lkj) / dk;
      r2[j + 1] = (b2 - a2 * lkj) / dk;
      r3[j + 1] = (b3 - a3 * lkj) / dk;
    }
    for (; i < n; ++i) {
      V* __restrict r0 = p + tri(i);
      V a0 = r0[j], b0 = r0[j + 1];
      for (int64_t k = 0; k < j; ++k) {
        a0 -= r0[k] * rj[k];
        b0 -= r0[k] * rk[k];
      }
      a0 /= dj;
      r0[j] = a0;
      r0[j + 1] = (b0 - a0 * lkj) / dk;
    }
  }
  if (j < n) {  // n odd: the last diagonal element
    V* __restrict rj = p + tri(j);
    V s = rj[j];
    for (int64_t k = 0; k < j; ++k) s -= rj[k] * rj[k];
    bad |= failed(s);
    sqrt_lanes(s, rj[j]);
  }
  return bad;
}

// In place: x <- L^{-1} x for the packed group L (forward's operations for k = 1,
// including dot's four sums).
template <class V>
LK_INLINE void forward_lanes(const V* __restrict p, V* __restrict x, int64_t n) {
  for (int64_t i = 0; i < n; ++i) {
    const V* __restrict li = p + tri(i);
    V s0 = {}, s1 = {}, s2 = {}, s3 = {};
    int64_t j = 0;
    for (; j + 4 <= i; j += 4) {
      s0 += li[j] * x[j];
      s1 += li[j + 1] * x[j + 1];
      s2 += li[j + 2] * x[j + 2];
      s3 += li[j + 3] * x[j + 3];
    }
    for (; j < i; ++j) s0 += li[j] * x[j];
    x[i] = (x[i] - ((s0 + s1) + (s2 + s3))) / li[i];
  }
}

// In place: x <- L^{-T} x for the packed group L (backward_t's operations for k = 1).
template <class V>
LK_INLINE void backward_t_lanes(const V* __restrict p, V* __restrict x, int64_t n) {
  for (int64_t i = n - 1; i >= 0; --i) {
    const V* __restrict li = p + tri(i);
    const V xi = x[i] / li[i];
    x[i] = xi;
    for (int64_t j = 0; j < i; ++j) x[j] -= li[j] * xi;
  }
}

// The lanes<V>() consecutive matrices from a on: their factors to l (n x n each),
// except where the factor fails (the returned lanes, not written).
template <class V>
LK_INLINE unsigned chol_group(const double* a, double* l, int64_t n, double* scratch) {
  V* p = reinterpret_cast<V*>(scratch);
  pack<false>(a, n, p, nullptr);
  const unsigned bad = chol_lanes(p, n);
  for (int w = 0; w < lanes<V>(); ++w)
    if (!(bad >> w & 1u)) unpack_lane(p, n, w, l + w * n * n);
  return bad;
}

// x = (a + d I)^{-1} b for the lanes<V>() consecutive matrices from a on (and their d,
// b, x), except where the factor fails (the returned lanes, x not written).
template <class V>
LK_INLINE unsigned damped_group(const double* a, const double* d, const double* b,
                                double* x, int64_t n, double* scratch) {
  V* p = reinterpret_cast<V*>(scratch);
  V* y = p + tri(n);
  pack<true>(a, n, p, d);
  for (int64_t k = 0; k < n; ++k)
    for (int w = 0; w < lanes<V>(); ++w) y[k][w] = b[w * n + k];
  const unsigned bad = chol_lanes(p, n);
  forward_lanes(p, y, n);
  backward_t_lanes(p, y, n);
  for (int w = 0; w < lanes<V>(); ++w)
    if (!(bad >> w & 1u))
      for (int64_t k = 0; k < n; ++k) x[w * n + k] = y[k][w];
  return bad;
}

unsigned chol_group2(const double* a, double* l, int64_t n, double* scratch) {
  return chol_group<V2>(a, l, n, scratch);
}

unsigned damped_group2(const double* a, const double* d, const double* b, double* x,
                       int64_t n, double* scratch) {
  return damped_group<V2>(a, d, b, x, n, scratch);
}

#ifdef LK_AVX2
__attribute__((target("avx2"))) unsigned chol_group4(const double* a, double* l,
                                                     int64_t n, double* scratch) {
  return chol_group<V4>(a, l, n, scratch);
}

__attribute__((target("avx2"))) unsigned damped_group4(const double* a, const double* d,
                                                       const double* b, double* x,
                                                       int64_t n, double* scratch) {
  return damped_group<V4>(a, d, b, x, n, scratch);
}

bool has_avx2() {
  static const bool yes = __builtin_cpu_supports("avx2");
  return yes;
}
#endif
#endif  // LK_LANES

#ifdef LK_LANES
// LkNormalEquations of the lanes<V>() consecutive matrices from rows on (their c, h,
// g), the same operations as normal_one lane by lane (so bitwise its results), on
// the lower triangle packed side by side in scratch (tri(n) + n vectors).
template <class V>
LK_INLINE void normal_group(const double* rows, const double* c, const int32_t* pairs,
                            int64_t m, int64_t n, double* h, double* g, double* scratch) {
  constexpr int L = lanes<V>();
  V* p = reinterpret_cast<V*>(scratch);
  V* gv = p + tri(n);
  for (int64_t i = 0; i < tri(n) + n; ++i)
    for (int w = 0; w < L; ++w) p[i][w] = 0.0;
  for (int64_t r = 0; r < m; ++r) {
    V a[14], cr;
    for (int w = 0; w < L; ++w) {
      for (int k = 0; k < 14; ++k) a[k][w] = rows[(w * m + r) * 14 + k];
      cr[w] = c[w * m + r];
    }
    const int64_t b0 = pairs[2 * r], b1 = pairs[2 * r + 1];
    for (int s = 0; s < 2; ++s) {
      const int64_t bs = s == 0 ? b0 : b1;
      if (bs < 0) continue;
      const V* as = a + 7 * s;
      for (int k = 0; k < 7; ++k) gv[bs * 7 + k] += as[k] * cr;
      for (int k = 0; k < 7; ++k) {
        V* __restrict row = p + tri(bs * 7 + k) + bs * 7;
        for (int l = 0; l <= k; ++l) row[l] += as[k] * as[l];
      }
    }
    if (b0 < 0 || b1 < 0) continue;
    if (b0 == b1) {
      for (int k = 0; k < 7; ++k) {
        V* __restrict row = p + tri(b0 * 7 + k) + b0 * 7;
        for (int l = 0; l <= k; ++l) row[l] += a[k] * a[7 + l] + a[7 + k] * a[l];
      }
      continue;
    }
    const bool first_high = b0 > b1;
    const V* ah = first_high ? a : a + 7;
    const V* al = first_high ? a + 7 : a;
    const int64_t hi = first_high ? b0 : b1, lo = first_high ? b1 : b0;
    for (int k = 0; k < 7; ++k) {
      V* __restrict row = p + tri(hi * 7 + k) + lo * 7;
      for (int l = 0; l < 7; ++l) row[l] += ah[k] * al[l];
    }
  }
  for (int w = 0; w < L; ++w) {
    double* __restrict hw = h + w * n * n;
    for (int64_t i = 0; i < n; ++i) {
      const V* row = p + tri(i);
      for (int64_t j = 0; j <= i; ++j) hw[i * n + j] = hw[j * n + i] = row[j][w];
      g[w * n + i] = gv[i][w];
    }
  }
}

void normal_group2(const double* rows, const double* c, const int32_t* pairs, int64_t m,
                   int64_t n, double* h, double* g, double* scratch) {
  normal_group<V2>(rows, c, pairs, m, n, h, g, scratch);
}

#ifdef LK_AVX2
__attribute__((target("avx2"))) void normal_group4(const double* rows, const double* c,
                                                   const int32_t* pairs, int64_t m,
                                                   int64_t n, double* h, double* g,
                                                   double* scratch) {
  normal_group<V4>(rows, c, pairs, m, n, h, g, scratch);
}
#endif
#endif  // LK_LANES

// n and the batch size of a (..., n, n) operand, n <= kMaxN.
ffi::Error square_dims(const ffi::Buffer<ffi::F64>& a, int64_t* n, int64_t* batch) {
  auto dims = a.dimensions();
  const size_t r = dims.size();
  if (r < 2 || dims[r - 1] != dims[r - 2])
    return ffi::Error::InvalidArgument("expected a matrix operand of shape (..., n, n)");
  *n = dims[r - 1];
  if (*n > kMaxN)
    return ffi::Error::InvalidArgument("matrix order n = " + std::to_string(*n) +
                                       " exceeds the kernels' limit of " +
                                       std::to_string(kMaxN));
  *batch = 1;
  for (size_t i = 0; i + 2 < r; ++i) *batch *= dims[i];
  return ffi::Error::Success();
}

// The result has the shape of the operand (a wrong result shape would be written
// past its end).
ffi::Error same_dims(ffi::Span<const int64_t> a, ffi::Span<const int64_t> b) {
  if (a.size() != b.size())
    return ffi::Error::InvalidArgument("result rank differs from the operand's");
  for (size_t i = 0; i < a.size(); ++i)
    if (a[i] != b[i])
      return ffi::Error::InvalidArgument("result shape differs from the operand's");
  return ffi::Error::Success();
}

#ifdef LK_LANES
// LkCholesky of a batch, its groups by chol_group4/2 (scratch: lanes_scratch(n)).
ffi::Error cholesky_lanes(const double* src, double* dst, int64_t n, int64_t batch,
                          double* scratch) {
  double col[kLanesMaxN];
  const int64_t nn = n * n;
  int64_t b = 0;
  // the lanes of a group whose factor failed: chol_one writes their NaN pattern
  auto redo = [&](unsigned bad, int count) {
    for (int w = 0; w < count; ++w)
      if (bad >> w & 1u) chol_one(src + (b + w) * nn, dst + (b + w) * nn, n, col);
    b += count;
  };
#ifdef LK_AVX2
  if (has_avx2())
    while (b + 4 <= batch) redo(chol_group4(src + b * nn, dst + b * nn, n, scratch), 4);
#endif
  while (b + 2 <= batch) redo(chol_group2(src + b * nn, dst + b * nn, n, scratch), 2);
  for (; b < batch; ++b) chol_one(src + b * nn, dst + b * nn, n, col);
  return ffi::Error::Success();
}
#endif

ffi::Error CholeskyImpl(ffi::Buffer<ffi::F64> a, ffi::ResultBuffer<ffi::F64> out) {
  int64_t n, batch;
  if (auto e = square_dims(a, &n, &batch); e.failure()) return e;
  if (auto e = same_dims(a.dimensions(), out->dimensions()); e.failure()) return e;
  if (n == 0 || batch == 0) return ffi::Error::Success();
  const double* src = a.typed_data();
  double* dst = out->typed_data();
#ifdef LK_LANES
  if (n <= kLanesMaxN)
    return with_scratch(lanes_scratch(n), [&](double* scratch) {
      return cholesky_lanes(src, dst, n, batch, scratch);
    });
#endif
  double col[kMaxN];
  for (int64_t b = 0; b < batch; ++b) chol_one(src + b * n * n, dst + b * n * n, n, col);
  return ffi::Error::Success();
}

ffi::Error TriSolveImpl(ffi::Buffer<ffi::F64> l, ffi::Buffer<ffi::F64> b,
                        ffi::ResultBuffer<ffi::F64> out, int32_t mode) {
  if (mode < 0 || mode > 2)
    return ffi::Error::InvalidArgument("mode must be 0 (L x = b), 1 (L^T x = b) or "
                                       "2 (L L^T x = b), not " + std::to_string(mode));
  int64_t n, batch;
  if (auto e = square_dims(l, &n, &batch); e.failure()) return e;
  auto ld = l.dimensions();
  auto bd = b.dimensions();
  if (bd.size() != ld.size() || bd[bd.size() - 2] != n)
    return ffi::Error::InvalidArgument("expected b of shape (..., n, k) for L of shape "
                                       "(..., n, n), with the same batch dimensions");
  for (size_t i = 0; i + 2 < ld.size(); ++i)
    if (bd[i] != ld[i])
      return ffi::Error::InvalidArgument("batch dimensions of L and b differ");
  if (auto e = same_dims(b.dimensions(), out->dimensions()); e.failure()) return e;
  const int64_t k = bd[bd.size() - 1];
  if (n == 0 || batch == 0 || k == 0) return ffi::Error::Success();
  const double* lp = l.typed_data();
  const double* bp = b.typed_data();
  double* xp = out->typed_data();
  if (xp != bp) std::memcpy(xp, bp, sizeof(double) * batch * n * k);
  for (int64_t i = 0; i < batch; ++i) {
    const double* li = lp + i * n * n;
    double* xi = xp + i * n * k;
    if (mode == 0 || mode == 2) forward(li, xi, n, k);
    if (mode == 1 || mode == 2) backward_t(li, xi, n, k);
  }
  return ffi::Error::Success();
}

ffi::Error LowerInverseImpl(ffi::Buffer<ffi::F64> l, ffi::ResultBuffer<ffi::F64> out) {
  int64_t n, batch;
  if (auto e = square_dims(l, &n, &batch); e.failure()) return e;
  if (auto e = same_dims(l.dimensions(), out->dimensions()); e.failure()) return e;
  if (n == 0 || batch == 0) return ffi::Error::Success();
  const double* lp = l.typed_data();
  double* xp = out->typed_data();
  if (xp == lp)
    return ffi::Error::InvalidArgument("lower_inverse cannot write over its operand");
  for (int64_t i = 0; i < batch; ++i) lower_inverse_one(lp + i * n * n, xp + i * n * n, n);
  return ffi::Error::Success();
}

// LkDampedSolve of a batch (n >= 1, scratch: lanes_scratch(n)).
ffi::Error damped_batch(const double* ap, const double* dp, const double* bp, double* xp,
                        int64_t n, int64_t batch, double* scratch) {
  const int64_t nn = n * n;
  double col[kLanesMaxN];
  // one matrix: a + d I factored in scratch by chol_one, then the two solves
  auto one = [&](int64_t i) {
    const double* ai = ap + i * nn;
    for (int64_t row = 0; row < n; ++row) {
      for (int64_t c = 0; c < row; ++c) scratch[row * n + c] = ai[row * n + c];
      scratch[row * n + row] = ai[row * n + row] + dp[i];
    }
    chol_in_place(scratch, n, col);
    double* xi = xp + i * n;
    if (xi != bp + i * n) std::memcpy(xi, bp + i * n, sizeof(double) * n);
    forward(scratch, xi, n, 1);
    backward_t(scratch, xi, n, 1);
  };
  int64_t i = 0;
#ifdef LK_LANES
  // after a group's good lanes are written: one() reuses the scratch
  auto redo = [&](unsigned bad, int count) {
    for (int w = 0; w < count; ++w)
      if (bad >> w & 1u) one(i + w);
    i += count;
  };
#ifdef LK_AVX2
  if (has_avx2())
    while (i + 4 <= batch)
      redo(damped_group4(ap + i * nn, dp + i, bp + i * n, xp + i * n, n, scratch), 4);
#endif
  while (i + 2 <= batch)
    redo(damped_group2(ap + i * nn, dp + i, bp + i * n, xp + i * n, n, scratch), 2);
#endif
  for (; i < batch; ++i) one(i);
  return ffi::Error::Success();
}

// x = (a + d I)^{-1} b for each matrix of the batch: chol_one of a + d I, then forward
// and backward_t, with the same operations as LkCholesky of a + d I followed by
// LkTriSolve mode 2 (bitwise the same x); n <= kLanesMaxN.
ffi::Error DampedSolveImpl(ffi::Buffer<ffi::F64> a, ffi::Buffer<ffi::F64> d,
                           ffi::Buffer<ffi::F64> b, ffi::ResultBuffer<ffi::F64> out) {
  int64_t n, batch;
  if (auto e = square_dims(a, &n, &batch); e.failure()) return e;
  if (n > kLanesMaxN)
    return ffi::Error::InvalidArgument("matrix order n = " + std::to_string(n) +
                                       " exceeds the damped solve's limit of " +
                                       std::to_string(kLanesMaxN));
  auto ad = a.dimensions();
  auto dd = d.dimensions();
  auto bd = b.dimensions();
  const size_t r = ad.size();
  if (dd.size() + 2 != r || bd.size() + 1 != r || bd[r - 2] != n)
    return ffi::Error::InvalidArgument("expected a (..., n, n), d (...) and b (..., n) "
                                       "with the same batch dimensions");
  for (size_t i = 0; i + 2 < r; ++i)
    if (dd[i] != ad[i] || bd[i] != ad[i])
      return ffi::Error::InvalidArgument("batch dimensions of a, d and b differ");
  if (auto e = same_dims(b.dimensions(), out->dimensions()); e.failure()) return e;
  if (n == 0 || batch == 0) return ffi::Error::Success();
  return with_scratch(lanes_scratch(n), [&](double* scratch) {
    return damped_batch(a.typed_data(), d.typed_data(), b.typed_data(),
                        out->typed_data(), n, batch, scratch);
  });
}

// ---- the smallest right singular vector (linkopt._engine.singularity) ---------------
//
// smallest_right: the steps of singularity.smallest_right_vectors after the Gram matrix
// a = JᵀJ, for one matrix (T = double) or lanes<V>() side by side (T = V, the same
// operations per lane, so bitwise the one-matrix results): the lower Cholesky factor L
// of a + shift·trace(a)·I; the start block x (n x k) orthonormalised; `iterations`
// times x <- orthonormalised(A⁻¹ x), A⁻¹ x by the two triangular solves with L (the
// plain-JAX code multiplies by L⁻ᵀL⁻¹: the same in exact arithmetic); the Ritz matrix
// r = xᵀ a x; `sweeps` cyclic Jacobi sweeps of r (Golub & Van Loan Sec. 8.5, with the
// rotation of symmetric_eigh, Alg. 8.5.1, applied to rows and columns p and q of r);
// and x times the rotation column of r's smallest diagonal entry (NaN sorted last, the
// first of equal ones). Orthonormalised is Gram–Schmidt with each projection done
// twice, v / sqrt(v·v + 1e-300). Sums run in other orders than XLA's, so the result
// equals the plain-JAX code to round-off. A non-positive pivot gives NaN.
constexpr int64_t kSmallestMaxK = 32;

template <class T>
LK_INLINE double* lane_ptr(T* t) {
  return reinterpret_cast<double*>(t);
}

// v <- its square root, lane by lane (in place: a V4 passed or returned by value would
// change the ABI between AVX2 and other code, GCC's -Wpsabi).
template <class T>
LK_INLINE void lane_sqrt(T& v) {
  double* lanes_of_v = lane_ptr(&v);
  for (size_t g = 0; g < sizeof(T) / sizeof(double); ++g)
    lanes_of_v[g] = std::sqrt(lanes_of_v[g]);
}

// (c, s) of the rotation that zeroes r[p, q] (dense.symmetric_eigh's rotation: the
// identity where r[p, q] is zero), one lane at a time.
LK_INLINE void jacobi_rotation(double app, double aqq, double apq, double& c, double& s) {
  const double safe = apq == 0.0 ? 1.0 : apq;
  const double theta = (aqq - app) / (2.0 * safe);
  const double sign = theta > 0.0 ? 1.0 : (theta < 0.0 ? -1.0 : theta);
  double tan = sign / (std::fabs(theta) + std::sqrt(theta * theta + 1.0));
  if (apq == 0.0 || theta == 0.0) tan = apq == 0.0 ? 0.0 : 1.0;
  c = 1.0 / std::sqrt(tan * tan + 1.0);
  s = tan * c;
}

// Cyclic Jacobi on the symmetric k x k r (both triangles kept), rotations into v.
template <class T>
LK_INLINE void jacobi(T* __restrict r, T* __restrict v, int64_t k, int32_t sweeps) {
  constexpr int count = sizeof(T) / sizeof(double);
  for (int64_t i = 0; i < k * k; ++i) v[i] = T{} * 0.0;
  for (int64_t i = 0; i < k; ++i) v[i * k + i] = T{} * 0.0 + 1.0;
  for (int32_t sweep = 0; sweep < sweeps; ++sweep)
    for (int64_t p = 0; p < k; ++p)
      for (int64_t q = p + 1; q < k; ++q) {
        T c = T{} * 0.0, s = T{} * 0.0;  // every lane set by jacobi_rotation
        for (int g = 0; g < count; ++g)
          jacobi_rotation(lane_ptr(&r[p * k + p])[g], lane_ptr(&r[q * k + q])[g],
                          lane_ptr(&r[p * k + q])[g], lane_ptr(&c)[g], lane_ptr(&s)[g]);
        // r <- Gᵀ r G: columns p and q, then rows p and q (r stays symmetric)
        for (int64_t i = 0; i < k; ++i) {
          const T rp = r[i * k + p], rq = r[i * k + q];
          r[i * k + p] = c * rp - s * rq;
          r[i * k + q] = s * rp + c * rq;
        }
        for (int64_t j = 0; j < k; ++j) {
          const T rp = r[p * k + j], rq = r[q * k + j];
          r[p * k + j] = c * rp - s * rq;
          r[q * k + j] = s * rp + c * rq;
        }
        for (int64_t i = 0; i < k; ++i) {
          const T vp = v[i * k + p], vq = v[i * k + q];
          v[i * k + p] = c * vp - s * vq;
          v[i * k + q] = s * vp + c * vq;
        }
      }
}

template <int K, class T>
LK_INLINE void orthonormalise(T* __restrict x, int64_t n, int64_t k_) {
  const int64_t k = K ? K : k_;
  for (int64_t j = 0; j < k; ++j) {
    for (int pass = 0; pass < 2; ++pass)
      for (int64_t q = 0; q < j; ++q) {
        T d = x[q] * x[j];
        for (int64_t i = 1; i < n; ++i) d += x[i * k + q] * x[i * k + j];
        for (int64_t i = 0; i < n; ++i) x[i * k + j] -= d * x[i * k + q];
      }
    T norm = x[j] * x[j];
    for (int64_t i = 1; i < n; ++i) norm += x[i * k + j] * x[i * k + j];
    T root = norm + 1e-300;
    lane_sqrt(root);
    const T scale = 1.0 / root;
    for (int64_t i = 0; i < n; ++i) x[i * k + j] = x[i * k + j] * scale;
  }
}

// x (n x k) <- (L Lᵀ)⁻¹ x for the lower factor L (row-major n x n) and the
// reciprocals of its diagonal, inv_d (n). K: k known at compile time (0: not), so that
// a row's k sums stay in registers.
template <int K, class T>
LK_INLINE void cho_solve_block(const T* __restrict l, const T* __restrict inv_d,
                               T* __restrict x, int64_t n, int64_t k) {
  const int64_t kk = K ? K : k;
  T acc[K ? K : kSmallestMaxK];
  for (int64_t i = 0; i < n; ++i) {
    T* xi = x + i * kk;
    for (int64_t j = 0; j < kk; ++j) acc[j] = xi[j];
    for (int64_t p = 0; p < i; ++p) {
      const T lip = l[i * n + p];
      const T* xp = x + p * kk;
      for (int64_t j = 0; j < kk; ++j) acc[j] -= lip * xp[j];
    }
    const T r = inv_d[i];
    for (int64_t j = 0; j < kk; ++j) xi[j] = acc[j] * r;
  }
  for (int64_t i = n - 1; i >= 0; --i) {
    T* xi = x + i * kk;
    for (int64_t j = 0; j < kk; ++j) acc[j] = xi[j];
    for (int64_t p = i + 1; p < n; ++p) {
      const T lpi = l[p * n + i];
      const T* xp = x + p * kk;
      for (int64_t j = 0; j < kk; ++j) acc[j] -= lpi * xp[j];
    }
    const T r = inv_d[i];
    for (int64_t j = 0; j < kk; ++j) xi[j] = acc[j] * r;
  }
}

// The vectors of the lanes of a (n x n) and x (n x k, the start block, overwritten) to
// out (lane g at out + g * n); w: scratch of n² + n + n k + 2 k² T.
template <int K, class T>
LK_INLINE void smallest_right(const T* __restrict a, T* __restrict x,
                              double* __restrict out, int64_t n, int64_t k_,
                              int32_t iterations, int32_t sweeps, double shift,
                              T* __restrict w) {
  constexpr int count = sizeof(T) / sizeof(double);
  const int64_t k = K ? K : k_;
  T* l = w;
  T* inv_d = l + n * n;
  T* y = inv_d + n;
  T* r = y + n * k;
  T* rv = r + k * k;
  T trace = a[0];
  for (int64_t i = 1; i < n; ++i) trace += a[i * n + i];
  const T added = shift * trace;
  for (int64_t i = 0; i < n; ++i) {
    for (int64_t j = 0; j < i; ++j) l[i * n + j] = a[i * n + j];
    l[i * n + i] = a[i * n + i] + added;
  }
  for (int64_t j = 0; j < n; ++j) {  // right-looking Cholesky, lower triangle
    T d = l[j * n + j];
    lane_sqrt(d);
    l[j * n + j] = d;
    inv_d[j] = 1.0 / d;
    for (int64_t i = j + 1; i < n; ++i) l[i * n + j] = l[i * n + j] * inv_d[j];
    for (int64_t c = j + 1; c < n; ++c) {
      const T lc = l[c * n + j];
      for (int64_t i = c; i < n; ++i) l[i * n + c] -= l[i * n + j] * lc;
    }
  }
  orthonormalise<K>(x, n, k);
  for (int32_t it = 0; it < iterations; ++it) {
    cho_solve_block<K>(l, inv_d, x, n, k);
    orthonormalise<K>(x, n, k);
  }
  for (int64_t i = 0; i < n * k; ++i) y[i] = T{} * 0.0;  // y = a x
  for (int64_t i = 0; i < n; ++i)
    for (int64_t p = 0; p < n; ++p) {
      const T m = a[i * n + p];
      for (int64_t j = 0; j < k; ++j) y[i * k + j] += m * x[p * k + j];
    }
  for (int64_t i = 0; i < k * k; ++i) r[i] = T{} * 0.0;  // r = xᵀ y
  for (int64_t p = 0; p < n; ++p)
    for (int64_t i = 0; i < k; ++i) {
      const T xi = x[p * k + i];
      for (int64_t j = 0; j < k; ++j) r[i * k + j] += xi * y[p * k + j];
    }
  jacobi(r, rv, k, sweeps);
  for (int g = 0; g < count; ++g) {
    int64_t best = -1;
    for (int64_t i = 0; i < k; ++i) {
      const double value = lane_ptr(&r[i * k + i])[g];
      if (!std::isnan(value) && (best < 0 || value < lane_ptr(&r[best * k + best])[g]))
        best = i;
    }
    if (best < 0) best = 0;
    for (int64_t p = 0; p < n; ++p) {
      double sum = lane_ptr(&x[p * k])[g] * lane_ptr(&rv[best])[g];
      for (int64_t j = 1; j < k; ++j)
        sum += lane_ptr(&x[p * k + j])[g] * lane_ptr(&rv[j * k + best])[g];
      out[g * n + p] = sum;
    }
  }
}

// Doubles of smallest_group's scratch for groups of up to four.
constexpr int64_t smallest_scratch(int64_t n, int64_t k) {
  return 4 * (n * n + n * k + n * n + n + n * k + 2 * k * k);
}

// The lanes<T>() consecutive problems from a (n x n each) and start (n x k each) on.
template <class T>
LK_INLINE void smallest_group(const double* a, const double* start, double* out,
                              int64_t n, int64_t k, int32_t iterations, int32_t sweeps,
                              double shift, double* scratch) {
  constexpr int count = sizeof(T) / sizeof(double);
  T* pa = reinterpret_cast<T*>(scratch);
  T* px = pa + n * n;
  for (int64_t i = 0; i < n * n; ++i)
    for (int g = 0; g < count; ++g) lane_ptr(&pa[i])[g] = a[g * n * n + i];
  for (int64_t i = 0; i < n * k; ++i)
    for (int g = 0; g < count; ++g) lane_ptr(&px[i])[g] = start[g * n * k + i];
  if (k == 6)  // singularity.BLOCK
    smallest_right<6>(pa, px, out, n, k, iterations, sweeps, shift, px + n * k);
  else
    smallest_right<0>(pa, px, out, n, k, iterations, sweeps, shift, px + n * k);
}

void smallest_group1(const double* a, const double* start, double* out, int64_t n,
                     int64_t k, int32_t iterations, int32_t sweeps, double shift,
                     double* scratch) {
  smallest_group<double>(a, start, out, n, k, iterations, sweeps, shift, scratch);
}

#ifdef LK_LANES
void smallest_group2(const double* a, const double* start, double* out, int64_t n,
                     int64_t k, int32_t iterations, int32_t sweeps, double shift,
                     double* scratch) {
  smallest_group<V2>(a, start, out, n, k, iterations, sweeps, shift, scratch);
}

#ifdef LK_AVX2
__attribute__((target("avx2"))) void smallest_group4(const double* a,
                                                     const double* start, double* out,
                                                     int64_t n, int64_t k,
                                                     int32_t iterations, int32_t sweeps,
                                                     double shift, double* scratch) {
  smallest_group<V4>(a, start, out, n, k, iterations, sweeps, shift, scratch);
}
#endif
#endif  // LK_LANES

// LkSmallestRight of a batch (n >= 1, scratch: smallest_scratch(n, k)).
ffi::Error smallest_batch(const double* ap, const double* sp, double* op, int64_t n,
                          int64_t k, int64_t batch, int32_t iterations, int32_t sweeps,
                          double shift, double* scratch) {
  int64_t b = 0;
#ifdef LK_LANES
#ifdef LK_AVX2
  if (has_avx2())
    for (; b + 4 <= batch; b += 4)
      smallest_group4(ap + b * n * n, sp + b * n * k, op + b * n, n, k, iterations,
                      sweeps, shift, scratch);
#endif
  for (; b + 2 <= batch; b += 2)
    smallest_group2(ap + b * n * n, sp + b * n * k, op + b * n, n, k, iterations, sweeps,
                    shift, scratch);
#endif
  for (; b < batch; ++b)
    smallest_group1(ap + b * n * n, sp + b * n * k, op + b * n, n, k, iterations, sweeps,
                    shift, scratch);
  return ffi::Error::Success();
}

// out = smallest_right of each (a, start) of the batch: a (..., n, n), start
// (..., n, k) with k <= min(n, kSmallestMaxK), out (..., n).
ffi::Error SmallestRightImpl(ffi::Buffer<ffi::F64> a, ffi::Buffer<ffi::F64> start,
                             ffi::ResultBuffer<ffi::F64> out, int32_t iterations,
                             int32_t sweeps, double shift) {
  int64_t n, batch;
  if (auto e = square_dims(a, &n, &batch); e.failure()) return e;
  auto ad = a.dimensions();
  auto sd = start.dimensions();
  auto od = out->dimensions();
  const size_t rank = ad.size();
  if (sd.size() != rank || od.size() + 1 != rank || sd[rank - 2] != n ||
      od[rank - 2] != n)
    return ffi::Error::InvalidArgument("expected a (..., n, n), start (..., n, k) and "
                                       "the result (..., n)");
  for (size_t i = 0; i + 2 < rank; ++i)
    if (sd[i] != ad[i] || od[i] != ad[i])
      return ffi::Error::InvalidArgument("batch dimensions of a, start and the result "
                                         "differ");
  const int64_t k = sd[rank - 1];
  if (k < 1 || k > n || k > kSmallestMaxK)
    return ffi::Error::InvalidArgument("the start block's width k = " +
                                       std::to_string(k) + " must be in 1..min(n, " +
                                       std::to_string(kSmallestMaxK) + ")");
  if (iterations < 0 || sweeps < 0)
    return ffi::Error::InvalidArgument("iterations and sweeps must be >= 0");
  if (n == 0 || batch == 0) return ffi::Error::Success();
  const double* ap = a.typed_data();
  const double* sp = start.typed_data();
  double* op = out->typed_data();
  return with_scratch(smallest_scratch(n, k), [&](double* scratch) {
    return smallest_batch(ap, sp, op, n, k, batch, iterations, sweeps, shift, scratch);
  });
}

// LkNormalEquations of one matrix: h (n x n) = JᵀJ, g (n) = Jᵀc, row by row in the
// row order. A row adds its two 7-blocks' outer products and their products with c[r]
// to its bodies' blocks, the lower triangle only (a diagonal block's lower half, a
// cross block where it lies below the diagonal, transposed); the upper triangle is
// copied from it at the end.
void normal_one(const double* __restrict rows, const double* __restrict c,
                const int32_t* __restrict pairs, int64_t m, int64_t n,
                double* __restrict h, double* __restrict g) {
  for (int64_t i = 0; i < n * n; ++i) h[i] = 0.0;
  for (int64_t i = 0; i < n; ++i) g[i] = 0.0;
  for (int64_t r = 0; r < m; ++r) {
    const double* a = rows + r * 14;
    const int64_t b0 = pairs[2 * r], b1 = pairs[2 * r + 1];
    for (int s = 0; s < 2; ++s) {
      const int64_t bs = s == 0 ? b0 : b1;
      if (bs < 0) continue;
      const double* as = a + 7 * s;
      double* __restrict gs = g + bs * 7;
      for (int k = 0; k < 7; ++k) gs[k] += as[k] * c[r];
      double* __restrict d = h + bs * 7 * n + bs * 7;  // diagonal block, lower half
      for (int k = 0; k < 7; ++k)
        for (int l = 0; l <= k; ++l) d[k * n + l] += as[k] * a[7 * s + l];
    }
    if (b0 < 0 || b1 < 0) continue;
    // the cross block at (hi, lo), hi > lo: rows of body hi's block times lo's
    const bool first_high = b0 > b1;
    const double* ah = first_high ? a : a + 7;
    const double* al = first_high ? a + 7 : a;
    const int64_t hi = first_high ? b0 : b1, lo = first_high ? b1 : b0;
    if (hi == lo) {  // both blocks on one body: the block gets both products
      double* __restrict d = h + hi * 7 * n + hi * 7;
      for (int k = 0; k < 7; ++k)
        for (int l = 0; l <= k; ++l) d[k * n + l] += a[k] * a[7 + l] + a[7 + k] * a[l];
      continue;
    }
    double* __restrict x = h + hi * 7 * n + lo * 7;
    for (int k = 0; k < 7; ++k)
      for (int l = 0; l < 7; ++l) x[k * n + l] += ah[k] * al[l];
  }
  for (int64_t i = 0; i < n; ++i)
    for (int64_t j = i + 1; j < n; ++j) h[i * n + j] = h[j * n + i];
}

ffi::Error NormalEquationsImpl(ffi::Buffer<ffi::F64> rows, ffi::Buffer<ffi::F64> c,
                               ffi::ResultBuffer<ffi::F64> h,
                               ffi::ResultBuffer<ffi::F64> g,
                               ffi::Span<const int32_t> pairs) {
  auto rd = rows.dimensions();
  auto cd = c.dimensions();
  auto hd = h->dimensions();
  auto gd = g->dimensions();
  const size_t r = rd.size();
  if (r < 2 || rd[r - 1] != 14 || cd.size() + 1 != r || hd.size() != r ||
      gd.size() + 1 != r)
    return ffi::Error::InvalidArgument(
        "expected rows (..., m, 14), c (..., m) and results (..., n, n), (..., n)");
  const int64_t m = rd[r - 2];
  const int64_t n = hd[r - 1];
  if (cd[r - 2] != m || hd[r - 2] != n || gd[r - 2] != n || n % 7 != 0)
    return ffi::Error::InvalidArgument("row count or state size mismatch (n = 7 x bodies)");
  if (static_cast<int64_t>(pairs.size()) != 2 * m)
    return ffi::Error::InvalidArgument("attribute pairs must hold 2 m body indices");
  for (size_t i = 0; i < pairs.size(); ++i)
    if (pairs[i] < -1 || pairs[i] >= n / 7)
      return ffi::Error::InvalidArgument("a body index in pairs is out of range");
  int64_t batch = 1;
  for (size_t i = 0; i + 2 < r; ++i) {
    if (cd[i] != rd[i] || hd[i] != rd[i] || gd[i] != rd[i])
      return ffi::Error::InvalidArgument("batch dimensions differ");
    batch *= rd[i];
  }
  const double* rp = rows.typed_data();
  const double* cp = c.typed_data();
  double* hp = h->typed_data();
  double* gp = g->typed_data();
  const int32_t* pp = pairs.begin();
  int64_t b = 0;
#ifdef LK_LANES
  if (batch >= 2) {
    const int64_t wide = batch >= 4 ? 4 : 2;
    auto groups = [&](double* scratch) {
#ifdef LK_AVX2
      if (has_avx2())
        for (; b + 4 <= batch; b += 4)
          normal_group4(rp + b * m * 14, cp + b * m, pp, m, n, hp + b * n * n,
                        gp + b * n, scratch);
#endif
      for (; b + 2 <= batch; b += 2)
        normal_group2(rp + b * m * 14, cp + b * m, pp, m, n, hp + b * n * n,
                      gp + b * n, scratch);
      return ffi::Error::Success();
    };
    if (auto e = with_scratch((tri(n) + n) * wide, groups); e.failure()) return e;
  }
#endif
  for (; b < batch; ++b)
    normal_one(rp + b * m * 14, cp + b * m, pp, m, n, hp + b * n * n, gp + b * n);
  return ffi::Error::Success();
}

// ---- block-band Cholesky (linkopt._engine.band_factor) ------------------------------
//
// A symmetric matrix of B x B blocks of 7 x 7 in block-band storage: band[i][k] is
// H[i, i - k] (k = 0..w, row-major 7 x 7; blocks with i - k < 0 are not read). Its lower
// block Cholesky factor is stored the same way, L[i][0] lower triangular.

constexpr int64_t kB = 7;
constexpr int64_t kBB = 49;

// x (7 x 7) <- x L^{-T}, L lower triangular 7 x 7 (row r of the result solves
// L y = x[r]^T). Column by column, each column's seven rows independent of each other,
// so the loop over rows pipelines instead of waiting on one sum.
inline void right_solve_lt(const double* __restrict l, double* __restrict x) {
  for (int64_t c = 0; c < kB; ++c) {
    const double d = l[c * kB + c];
    for (int64_t r = 0; r < kB; ++r) x[r * kB + c] /= d;
    for (int64_t c2 = c + 1; c2 < kB; ++c2) {
      const double f = l[c2 * kB + c];
      for (int64_t r = 0; r < kB; ++r) x[r * kB + c2] -= f * x[r * kB + c];
    }
  }
}

// s (7 x 7) -= a b^T for 7 x 7 blocks a, b: as axpys over the rows of b^T, which the
// compiler vectorises (a dot product per entry would wait on each of its sums).
inline void sub_abt(const double* __restrict a, const double* __restrict b,
                    double* __restrict s) {
  double bt[kBB];
  for (int64_t c = 0; c < kB; ++c)
    for (int64_t q = 0; q < kB; ++q) bt[q * kB + c] = b[c * kB + q];
  for (int64_t r = 0; r < kB; ++r) {
    double* __restrict sr = s + r * kB;
    for (int64_t q = 0; q < kB; ++q) {
      const double f = a[r * kB + q];
      const double* __restrict bq = bt + q * kB;
      for (int64_t c = 0; c < kB; ++c) sr[c] -= f * bq[c];
    }
  }
}

// l (nb x w1 blocks) <- the lower block Cholesky factor of band + d I (nb x w1 blocks).
// A failing pivot leaves NaN in its block row's diagonal block from its column on, and
// every later block that depends on it NaN through the arithmetic.
void band_factor_one(const double* __restrict a, double d, double* __restrict l,
                     int64_t nb, int64_t w1) {
  const int64_t w = w1 - 1;
  const int64_t row = w1 * kBB;
  double col[kB];
  for (int64_t i = 0; i < nb; ++i) {
    const double* ai = a + i * row;
    double* li = l + i * row;
    for (int64_t k = w; k >= 1; --k) {  // L[i, j], j = i - k ascending
      double* s = li + k * kBB;
      const int64_t j = i - k;
      if (j < 0) {
        std::memset(s, 0, sizeof(double) * kBB);
        continue;
      }
      std::memcpy(s, ai + k * kBB, sizeof(double) * kBB);
      const double* lj = l + j * row;
      for (int64_t m = w; m > k; --m)  // L[i, i - m] L[j, i - m]^T, i - m < j
        if (i - m >= 0) sub_abt(li + m * kBB, lj + (m - k) * kBB, s);
      right_solve_lt(lj, s);
    }
    double* diag = li;
    std::memcpy(diag, ai, sizeof(double) * kBB);
    for (int64_t q = 0; q < kB; ++q) diag[q * kB + q] += d;
    for (int64_t k = 1; k <= w; ++k)
      if (i - k >= 0) sub_abt(li + k * kBB, li + k * kBB, diag);
    chol_in_place(diag, kB, col);
  }
}

// In place: x (nb x 7) <- L^{-1} x for the band factor l (nb x w1 blocks).
void band_forward(const double* __restrict l, double* __restrict x, int64_t nb,
                  int64_t w1) {
  const int64_t row = w1 * kBB;
  for (int64_t i = 0; i < nb; ++i) {
    const double* li = l + i * row;
    double* __restrict xi = x + i * kB;
    for (int64_t k = 1; k < w1 && k <= i; ++k) {
      const double* blk = li + k * kBB;
      const double* xj = x + (i - k) * kB;
      for (int64_t r = 0; r < kB; ++r) {
        double t = 0.0;
        for (int64_t q = 0; q < kB; ++q) t += blk[r * kB + q] * xj[q];
        xi[r] -= t;
      }
    }
    for (int64_t r = 0; r < kB; ++r) {
      double s = xi[r];
      for (int64_t q = 0; q < r; ++q) s -= li[r * kB + q] * xi[q];
      xi[r] = s / li[r * kB + r];
    }
  }
}

// In place: x (nb x 7) <- L^{-T} x for the band factor l (nb x w1 blocks).
void band_backward(const double* __restrict l, double* __restrict x, int64_t nb,
                   int64_t w1) {
  const int64_t row = w1 * kBB;
  for (int64_t i = nb - 1; i >= 0; --i) {
    double* __restrict xi = x + i * kB;
    for (int64_t k = 1; k < w1 && i + k < nb; ++k) {  // L[i + k, i]^T x[i + k]
      const double* blk = l + (i + k) * row + k * kBB;
      const double* xj = x + (i + k) * kB;
      for (int64_t q = 0; q < kB; ++q) {
        const double c = xj[q];
        for (int64_t r = 0; r < kB; ++r) xi[r] -= blk[q * kB + r] * c;
      }
    }
    const double* li = l + i * row;
    for (int64_t r = kB - 1; r >= 0; --r) {
      double s = xi[r];
      for (int64_t q = r + 1; q < kB; ++q) s -= li[q * kB + r] * xi[q];
      xi[r] = s / li[r * kB + r];
    }
  }
}

// The block count nb, blocks per row w1 and batch of a (..., nb, w1, 7, 7) operand.
ffi::Error band_dims(ffi::Span<const int64_t> dims, int64_t* nb, int64_t* w1,
                     int64_t* batch) {
  const size_t r = dims.size();
  if (r < 4 || dims[r - 1] != kB || dims[r - 2] != kB || dims[r - 3] < 1)
    return ffi::Error::InvalidArgument(
        "expected a band operand of shape (..., B, w + 1, 7, 7)");
  *nb = dims[r - 4];
  *w1 = dims[r - 3];
  *batch = 1;
  for (size_t i = 0; i + 4 < r; ++i) *batch *= dims[i];
  return ffi::Error::Success();
}

ffi::Error BandFactorImpl(ffi::Buffer<ffi::F64> band, ffi::Buffer<ffi::F64> d,
                          ffi::ResultBuffer<ffi::F64> out) {
  int64_t nb, w1, batch;
  if (auto e = band_dims(band.dimensions(), &nb, &w1, &batch); e.failure()) return e;
  if (auto e = same_dims(band.dimensions(), out->dimensions()); e.failure()) return e;
  auto dd = d.dimensions();
  auto bd = band.dimensions();
  if (dd.size() + 4 != bd.size())
    return ffi::Error::InvalidArgument("expected d of shape (...), the band's batch");
  for (size_t i = 0; i < dd.size(); ++i)
    if (dd[i] != bd[i])
      return ffi::Error::InvalidArgument("batch dimensions of the band and d differ");
  if (nb == 0 || batch == 0) return ffi::Error::Success();
  const int64_t size = nb * w1 * kBB;
  for (int64_t b = 0; b < batch; ++b)
    band_factor_one(band.typed_data() + b * size, d.typed_data()[b],
                    out->typed_data() + b * size, nb, w1);
  return ffi::Error::Success();
}

// LkBandSolve: the batch dimensions of L and b each 1 or the result's (vmap's
// expand_dims: one factor serves many right-hand sides without copies).
ffi::Error BandSolveImpl(ffi::Buffer<ffi::F64> l, ffi::Buffer<ffi::F64> b,
                         ffi::ResultBuffer<ffi::F64> out, int32_t mode) {
  if (mode < 0 || mode > 2)
    return ffi::Error::InvalidArgument("mode must be 0 (L x = b), 1 (L^T x = b) or "
                                       "2 (L L^T x = b), not " + std::to_string(mode));
  int64_t nb, w1, lbatch;
  if (auto e = band_dims(l.dimensions(), &nb, &w1, &lbatch); e.failure()) return e;
  auto ld = l.dimensions();
  auto bd = b.dimensions();
  auto od = out->dimensions();
  const size_t rank = bd.size();
  if (rank < 2 || rank + 2 != ld.size() || bd[rank - 1] != kB || bd[rank - 2] != nb)
    return ffi::Error::InvalidArgument(
        "expected b of shape (..., B, 7) for L of shape (..., B, w + 1, 7, 7), with as "
        "many batch dimensions");
  if (od.size() != rank || od[rank - 1] != kB || od[rank - 2] != nb)
    return ffi::Error::InvalidArgument("result shape differs from b's");
  int64_t batch = 1;
  for (size_t i = 0; i + 2 < rank; ++i) {
    if ((ld[i] != od[i] && ld[i] != 1) || (bd[i] != od[i] && bd[i] != 1))
      return ffi::Error::InvalidArgument(
          "a batch dimension of L or b is neither 1 nor the result's");
    batch *= od[i];
  }
  if (nb == 0 || batch == 0) return ffi::Error::Success();
  const int64_t lsize = nb * w1 * kBB;
  const int64_t xsize = nb * kB;
  for (int64_t flat = 0; flat < batch; ++flat) {
    int64_t rest = flat, lofs = 0, bofs = 0, lstride = 1, bstride = 1;
    for (size_t i = rank - 2; i-- > 0;) {
      const int64_t digit = rest % od[i];
      rest /= od[i];
      if (ld[i] != 1) lofs += digit * lstride;
      if (bd[i] != 1) bofs += digit * bstride;
      lstride *= ld[i];
      bstride *= bd[i];
    }
    const double* li = l.typed_data() + lofs * lsize;
    double* xi = out->typed_data() + flat * xsize;
    const double* bi = b.typed_data() + bofs * xsize;
    if (xi != bi) std::memmove(xi, bi, sizeof(double) * xsize);
    if (mode == 0 || mode == 2) band_forward(li, xi, nb, w1);
    if (mode == 1 || mode == 2) band_backward(li, xi, nb, w1);
  }
  return ffi::Error::Success();
}

// JᵀJ and Jᵀc of the J whose row r holds rows[r, :7] in the 7 columns of body place
// pairs[2r] and rows[r, 7:] in those of pairs[2r + 1] (-1: none), the places numbered
// as the band's order with h hubs last: the n = nb - h others' blocks in band storage
// (band, n x w1 blocks; two of them |pairs[2r] - pairs[2r + 1]| < w1 apart, checked
// by the caller), the hubs' in border (n x h blocks, border[i][j] = H[hub j, body i])
// and corner (h x h blocks, both triangles); g (nb x 7). h = 0: no border or corner.
struct ArrowOut {
  double* band;
  double* border;
  double* corner;
  double* g;
};

inline void add_outer(double* __restrict blk, const double* x, const double* y) {
  for (int64_t i = 0; i < kB; ++i) {
    const double xi = x[i];
    for (int64_t j = 0; j < kB; ++j) blk[i * kB + j] += xi * y[j];
  }
}

// H[p, q] += x y^T (and H[q, p] its transpose, where stored), p >= q.
inline void add_lower(const ArrowOut& out, int64_t n, int64_t w1, int64_t h, int64_t p,
                      int64_t q, const double* x, const double* y) {
  if (p < n) {
    add_outer(out.band + (p * w1 + (p - q)) * kBB, x, y);
  } else if (q < n) {
    add_outer(out.border + (q * h + (p - n)) * kBB, x, y);
  } else {
    add_outer(out.corner + ((p - n) * h + (q - n)) * kBB, x, y);
    if (p != q) add_outer(out.corner + ((q - n) * h + (p - n)) * kBB, y, x);
  }
}

void arrow_normal_one(const double* __restrict rows, const double* __restrict c,
                      const int32_t* pairs, int64_t m, int64_t nb, int64_t w1,
                      int64_t h, const ArrowOut& out) {
  const int64_t n = nb - h;
  std::memset(out.band, 0, sizeof(double) * n * w1 * kBB);
  if (h > 0) {
    std::memset(out.border, 0, sizeof(double) * n * h * kBB);
    std::memset(out.corner, 0, sizeof(double) * h * h * kBB);
  }
  std::memset(out.g, 0, sizeof(double) * nb * kB);
  for (int64_t r = 0; r < m; ++r) {
    const double* a = rows + r * 14;
    const double* b = a + kB;
    const double cr = c[r];
    const int64_t pa = pairs[2 * r], pb = pairs[2 * r + 1];
    if (pa >= 0) {
      for (int64_t i = 0; i < kB; ++i) out.g[pa * kB + i] += a[i] * cr;
      add_lower(out, n, w1, h, pa, pa, a, a);
    }
    if (pb >= 0) {
      for (int64_t i = 0; i < kB; ++i) out.g[pb * kB + i] += b[i] * cr;
      add_lower(out, n, w1, h, pb, pb, b, b);
    }
    if (pa < 0 || pb < 0) continue;
    if (pa == pb) {  // a b^T + b a^T, each entry one sum: the block stays symmetric
      double sym[kBB];
      for (int64_t i = 0; i < kB; ++i)
        for (int64_t j = 0; j < kB; ++j) sym[i * kB + j] = a[i] * b[j] + b[i] * a[j];
      double* blk = pa < n ? out.band + pa * w1 * kBB
                           : out.corner + ((pa - n) * h + (pa - n)) * kBB;
      for (int64_t k = 0; k < kBB; ++k) blk[k] += sym[k];
    } else if (pa > pb) {
      add_lower(out, n, w1, h, pa, pb, a, b);
    } else {
      add_lower(out, n, w1, h, pb, pa, b, a);
    }
  }
}

// The checks of LkBandNormal and LkArrowNormal: rows (..., m, 14), c (..., m), g
// (..., nb, 7) and the storage's leading (batch) dimensions alike; the pairs' places
// in range and, both outside the hubs, inside the band.
ffi::Error normal_dims(ffi::Span<const int64_t> rd, ffi::Span<const int64_t> cd,
                       ffi::Span<const int64_t> gd,
                       std::initializer_list<ffi::Span<const int64_t>> storage,
                       ffi::Span<const int32_t> pairs, int64_t nb, int64_t w1,
                       int64_t h, int64_t* m, int64_t* batch) {
  const size_t r = rd.size();
  if (r < 2 || rd[r - 1] != 14 || cd.size() + 1 != r || gd.size() != r ||
      gd[r - 1] != kB || gd[r - 2] != nb)
    return ffi::Error::InvalidArgument(
        "expected rows (..., m, 14), c (..., m) and Jᵀc (..., B, 7)");
  *m = rd[r - 2];
  if (cd[r - 2] != *m) return ffi::Error::InvalidArgument("row count mismatch");
  if (static_cast<int64_t>(pairs.size()) != 2 * *m)
    return ffi::Error::InvalidArgument("attribute pairs must hold 2 m block rows");
  const int64_t n = nb - h;
  for (int64_t i = 0; i < *m; ++i) {
    const int64_t pa = pairs[2 * i], pb = pairs[2 * i + 1];
    if (pa < -1 || pa >= nb || pb < -1 || pb >= nb)
      return ffi::Error::InvalidArgument("a block row in pairs is out of range");
    if (pa >= 0 && pb >= 0 && pa < n && pb < n && (pa > pb ? pa - pb : pb - pa) >= w1)
      return ffi::Error::InvalidArgument("a pair in pairs lies outside the band");
  }
  *batch = 1;
  for (size_t i = 0; i + 2 < r; ++i) {
    bool same = cd[i] == rd[i] && gd[i] == rd[i];
    for (auto dims : storage) same = same && dims.size() == r + 2 && dims[i] == rd[i];
    if (!same) return ffi::Error::InvalidArgument("batch dimensions differ");
    *batch *= rd[i];
  }
  return ffi::Error::Success();
}

ffi::Error BandNormalImpl(ffi::Buffer<ffi::F64> rows, ffi::Buffer<ffi::F64> c,
                          ffi::ResultBuffer<ffi::F64> band, ffi::ResultBuffer<ffi::F64> g,
                          ffi::Span<const int32_t> pairs) {
  int64_t nb, w1, batch, m;
  if (auto e = band_dims(band->dimensions(), &nb, &w1, &batch); e.failure()) return e;
  if (auto e = normal_dims(rows.dimensions(), c.dimensions(), g->dimensions(),
                           {band->dimensions()}, pairs, nb, w1, 0, &m, &batch);
      e.failure())
    return e;
  for (int64_t b = 0; b < batch; ++b) {
    const ArrowOut out{band->typed_data() + b * nb * w1 * kBB, nullptr, nullptr,
                       g->typed_data() + b * nb * kB};
    arrow_normal_one(rows.typed_data() + b * m * 14, c.typed_data() + b * m,
                     pairs.begin(), m, nb, w1, 0, out);
  }
  return ffi::Error::Success();
}

// LkArrowNormal: band (..., n, w1, 7, 7), border (..., n, h, 7, 7), corner (..., h, h,
// 7, 7), g (..., n + h, 7).
ffi::Error ArrowNormalImpl(ffi::Buffer<ffi::F64> rows, ffi::Buffer<ffi::F64> c,
                           ffi::ResultBuffer<ffi::F64> band,
                           ffi::ResultBuffer<ffi::F64> border,
                           ffi::ResultBuffer<ffi::F64> corner,
                           ffi::ResultBuffer<ffi::F64> g,
                           ffi::Span<const int32_t> pairs) {
  int64_t n, w1, batch, m;
  if (auto e = band_dims(band->dimensions(), &n, &w1, &batch); e.failure()) return e;
  auto bd = border->dimensions();
  auto cd = corner->dimensions();
  const size_t r = bd.size();
  if (r < 4 || bd[r - 1] != kB || bd[r - 2] != kB || bd[r - 4] != n || cd.size() != r ||
      cd[r - 1] != kB || cd[r - 2] != kB || cd[r - 3] != bd[r - 3] || cd[r - 4] != bd[r - 3])
    return ffi::Error::InvalidArgument(
        "expected border (..., n, h, 7, 7) and corner (..., h, h, 7, 7) for a band of "
        "n block rows");
  const int64_t h = bd[r - 3];
  if (auto e = normal_dims(rows.dimensions(), c.dimensions(), g->dimensions(),
                           {band->dimensions(), bd, cd}, pairs, n + h, w1, h, &m, &batch);
      e.failure())
    return e;
  for (int64_t b = 0; b < batch; ++b) {
    const ArrowOut out{band->typed_data() + b * n * w1 * kBB,
                       border->typed_data() + b * n * h * kBB,
                       corner->typed_data() + b * h * h * kBB,
                       g->typed_data() + b * (n + h) * kB};
    arrow_normal_one(rows.typed_data() + b * m * 14, c.typed_data() + b * m,
                     pairs.begin(), m, n + h, w1, h, out);
  }
  return ffi::Error::Success();
}
}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkCholesky, CholeskyImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>());

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkTriSolve, TriSolveImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<int32_t>("mode"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkLowerInverse, LowerInverseImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>());

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkDampedSolve, DampedSolveImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>());

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkSmallestRight, SmallestRightImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<int32_t>("iterations")
                                  .Attr<int32_t>("sweeps")
                                  .Attr<double>("shift"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkNormalEquations, NormalEquationsImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<ffi::Span<const int32_t>>("pairs"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkBandFactor, BandFactorImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>());

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkBandSolve, BandSolveImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<int32_t>("mode"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkBandNormal, BandNormalImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<ffi::Span<const int32_t>>("pairs"));

XLA_FFI_DEFINE_HANDLER_SYMBOL(LkArrowNormal, ArrowNormalImpl,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Arg<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Ret<ffi::Buffer<ffi::F64>>()
                                  .Attr<ffi::Span<const int32_t>>("pairs"));

// ---- the Python extension module linkopt._kernels._dense ---------------------------

#ifndef LK_NO_PYTHON

#ifndef LK_SOURCE_SHA256
#define LK_SOURCE_SHA256 ""
#endif
// The jaxlib whose FFI headers built this module (setup.py), "" if unknown.
#ifndef LK_JAXLIB_VERSION
#define LK_JAXLIB_VERSION ""
#endif

namespace {

// Adds name -> capsule(handler) to dict; false with an exception set on failure.
bool add_capsule(PyObject* dict, const char* name, XLA_FFI_Handler* handler) {
  PyObject* capsule = PyCapsule_New(reinterpret_cast<void*>(handler), nullptr, nullptr);
  if (capsule == nullptr) return false;
  const int rc = PyDict_SetItemString(dict, name, capsule);
  Py_DECREF(capsule);
  return rc == 0;
}

PyObject* capsules(PyObject*, PyObject*) {
  PyObject* dict = PyDict_New();
  if (dict == nullptr) return nullptr;
  if (!add_capsule(dict, "cholesky", LkCholesky) ||
      !add_capsule(dict, "tri_solve", LkTriSolve) ||
      !add_capsule(dict, "lower_inverse", LkLowerInverse) ||
      !add_capsule(dict, "damped_solve", LkDampedSolve) ||
      !add_capsule(dict, "smallest_right", LkSmallestRight) ||
      !add_capsule(dict, "normal_equations", LkNormalEquations) ||
      !add_capsule(dict, "band_factor", LkBandFactor) ||
      !add_capsule(dict, "band_solve", LkBandSolve) ||
      !add_capsule(dict, "band_normal", LkBandNormal) ||
      !add_capsule(dict, "arrow_normal", LkArrowNormal)) {
    Py_DECREF(dict);
    return nullptr;
  }
  return dict;
}

PyObject* version(PyObject*, PyObject*) { return PyLong_FromLong(kVersion); }

PyObject* max_n(PyObject*, PyObject*) { return PyLong_FromLongLong(kMaxN); }

PyObject* damped_max_n(PyObject*, PyObject*) { return PyLong_FromLongLong(kLanesMaxN); }

PyObject* smallest_max_k(PyObject*, PyObject*) { return PyLong_FromLongLong(kSmallestMaxK); }

PyObject* ffi_api_version(PyObject*, PyObject*) {
  return Py_BuildValue("(ii)", XLA_FFI_API_MAJOR, XLA_FFI_API_MINOR);
}

PyObject* source_sha256(PyObject*, PyObject*) {
  return PyUnicode_FromString(LK_SOURCE_SHA256);
}

PyObject* jaxlib_version(PyObject*, PyObject*) {
  return PyUnicode_FromString(LK_JAXLIB_VERSION);
}

PyMethodDef methods[] = {
    {"capsules", capsules, METH_NOARGS,
     "{'cholesky', 'tri_solve', 'lower_inverse', 'damped_solve', 'smallest_right', "
     "'normal_equations'} -> a "
     "PyCapsule of each "
     "XLA FFI handler, for jax.ffi.register_ffi_target(name, capsule, platform='cpu')."},
    {"version", version, METH_NOARGS, "The ABI version of the handlers (an int)."},
    {"max_n", max_n, METH_NOARGS, "The largest matrix order n the handlers accept."},
    {"damped_max_n", damped_max_n, METH_NOARGS,
     "The largest matrix order n damped_solve accepts (the others: max_n())."},
    {"smallest_max_k", smallest_max_k, METH_NOARGS,
     "The widest start block k smallest_right accepts."},
    {"ffi_api_version", ffi_api_version, METH_NOARGS,
     "(major, minor) of the XLA FFI headers the handlers were built with."},
    {"source_sha256", source_sha256, METH_NOARGS,
     "SHA-256 of the dense.cc text this module was built from ('' if unknown)."},
    {"jaxlib_version", jaxlib_version, METH_NOARGS,
     "The version of the jaxlib whose XLA FFI headers built this module ('' if "
     "unknown)."},
    {nullptr, nullptr, 0, nullptr},
};

PyModuleDef_Slot slots[] = {
#if PY_VERSION_HEX >= 0x030C0000
    {Py_mod_multiple_interpreters, Py_MOD_PER_INTERPRETER_GIL_SUPPORTED},
#endif
#if PY_VERSION_HEX >= 0x030D0000
    {Py_mod_gil, Py_MOD_GIL_NOT_USED},
#endif
    {0, nullptr},
};

PyModuleDef module_def = {
    PyModuleDef_HEAD_INIT,
    "_dense",
    "XLA FFI handlers for batched dense linear algebra (linkopt/_kernels/dense.cc).",
    0,
    methods,
    slots,
    nullptr,
    nullptr,
    nullptr,
};

}  // namespace

PyMODINIT_FUNC PyInit__dense(void) { return PyModuleDef_Init(&module_def); }

#endif  // LK_NO_PYTHON
