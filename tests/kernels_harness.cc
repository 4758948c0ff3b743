// A harness for linkopt/_kernels/dense.cc without JAX or Python: it includes dense.cc
// (LK_NO_PYTHON: the handlers' *Impl functions, not the module) and calls every
// handler's implementation directly on XLA_FFI_Buffer structs it fills itself, the way
// XLA passes operands: orders 0, 1, 2, 5, 6, 7, 35, 89, 90, 91, 160, 161, 512, 513,
// batches 0-9, random positive definite, singular, indefinite, NaN, Inf, huge and tiny
// matrices, operands at an address off the usual 16/32/64-byte alignment, empty
// operands with null data, results written over an operand, refused shapes, six
// threads at once, normal_equations on random two-body rows for every order that is a
// multiple of 7, and band_factor, band_solve, band_normal and arrow_normal on random
// block bands (0-40 block rows, 1-6 blocks a row, batches 0-3, one factor for a batch
// of right-hand sides). tests/test_kernel_sanitizers.py builds it under AddressSanitizer and
// UndefinedBehaviorSanitizer (-fno-sanitize-recover: any report ends it with a failure).
// Besides the sanitizers' reports it checks that a handler refuses what it must, and
// that every matrix of a batch gets bitwise the result it gets alone (the handlers'
// group paths). Prints one summary line; exit status 0 only if everything held.
#define LK_NO_PYTHON 1
#include "dense.cc"

#include <atomic>
#include <chrono>
#include <cstdio>
#include <random>
#include <thread>
#include <vector>

namespace {

std::atomic<int> failures{0};

void fail(const char* what, int64_t n, int64_t batch) {
  if (failures++ < 20) std::fprintf(stderr, "FAILED: %s (n = %ld, batch = %ld)\n",
                                     what, static_cast<long>(n), static_cast<long>(batch));
}

// An operand: doubles on the heap, exactly as many as its shape holds (AddressSanitizer
// reports a read or write past either end), its data pointer null when it is empty, or
// one double past a 64-byte boundary when misaligned.
struct Operand {
  std::vector<int64_t> dims;
  double* base = nullptr;
  double* data = nullptr;
  int64_t size = 0;
  XLA_FFI_Buffer buffer{};

  Operand(std::vector<int64_t> shape, bool misaligned) : dims(std::move(shape)) {
    size = 1;
    for (int64_t d : dims) size *= d;
    if (size > 0) {  // exactly the bytes it needs from a 64-byte boundary on
      const int64_t offset = misaligned ? 1 : 0;
      void* p = nullptr;
      if (posix_memalign(&p, 64, sizeof(double) * (size + offset)) != 0) std::abort();
      base = static_cast<double*>(p);
      data = base + offset;
      std::memset(data, 0, sizeof(double) * size);
    }
    buffer.struct_size = sizeof(XLA_FFI_Buffer);
    buffer.extension_start = nullptr;
    buffer.dtype = XLA_FFI_DataType_F64;
    buffer.data = data;
    buffer.rank = static_cast<int64_t>(dims.size());
    buffer.dims = dims.data();
  }
  ~Operand() { std::free(base); }
  Operand(const Operand&) = delete;
  Operand& operator=(const Operand&) = delete;

  ffi::Buffer<ffi::F64> arg() { return ffi::Buffer<ffi::F64>(&buffer); }
  ffi::ResultBuffer<ffi::F64> ret() { return ffi::Buffer<ffi::F64>(&buffer); }
  // A result of the same shape written over this operand.
  ffi::ResultBuffer<ffi::F64> alias() { return ffi::Buffer<ffi::F64>(&buffer); }
};

enum Kind { kSpd, kSingular, kIndefinite, kWithNaN, kWithInf, kHuge, kTiny, kKinds };

// Matrix `kind` of order n at m (row-major), from rng: symmetric, with a diagonal that
// makes it positive definite (dominant), singular (a zero row and column), indefinite
// (one negative diagonal entry), or holding a NaN or an Inf, or scaled by 1e±300.
void fill_matrix(Kind kind, int64_t n, double* m, std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  for (int64_t i = 0; i < n; ++i) {
    for (int64_t j = 0; j < i; ++j) m[i * n + j] = m[j * n + i] = normal(rng);
    m[i * n + i] = 1.0 + static_cast<double>(n);
  }
  if (n == 0) return;
  const int64_t h = n / 2;
  if (kind == kSingular)
    for (int64_t i = 0; i < n; ++i) m[i * n + h] = m[h * n + i] = 0.0;
  if (kind == kIndefinite) m[h * n + h] = -1.0 - static_cast<double>(n);
  if (kind == kWithNaN) m[(n - 1) * n + n / 3] = std::numeric_limits<double>::quiet_NaN();
  if (kind == kWithInf) m[(n / 3) * n + n / 3] = std::numeric_limits<double>::infinity();
  const double scale = kind == kHuge ? 1e300 : kind == kTiny ? 1e-300 : 1.0;
  for (int64_t i = 0; i < n * n; ++i) m[i] *= scale;
}

void fill(Operand& op, std::mt19937_64& rng) {
  std::normal_distribution<double> normal;
  for (int64_t i = 0; i < op.size; ++i) op.data[i] = normal(rng);
}

std::vector<int64_t> shape(int64_t batch, bool batched, std::vector<int64_t> tail) {
  std::vector<int64_t> dims;
  if (batched) dims.push_back(batch);
  dims.insert(dims.end(), tail.begin(), tail.end());
  return dims;
}

void copy(double* to, const double* from, int64_t count) {
  if (count > 0) std::memcpy(to, from, sizeof(double) * count);
}

bool same_bits(const double* a, const double* b, int64_t count) {
  return count == 0 || std::memcmp(a, b, sizeof(double) * count) == 0;
}

// normal_equations for a state of order n (a multiple of 7) and random two-body rows:
// each matrix of the batch bitwise as alone, JᵀJ symmetric, refused pairs refused.
void normal_case(int64_t n, int64_t batch, bool batched, bool misaligned,
                 std::mt19937_64& rng) {
  if (n % 7 != 0 || n > kMaxN) return;
  const int64_t bodies = n / 7, m = 5 * bodies + 1;
  std::vector<int32_t> pairs(2 * m);
  std::uniform_int_distribution<int32_t> body(-1, static_cast<int32_t>(bodies) - 1);
  for (auto& p : pairs) p = body(rng);
  Operand rows(shape(batch, batched, {m, 14}), misaligned), c(shape(batch, batched, {m}), misaligned);
  Operand h(shape(batch, batched, {n, n}), misaligned), g(shape(batch, batched, {n}), misaligned);
  fill(rows, rng);
  fill(c, rng);
  const ffi::Span<const int32_t> span(pairs.data(), pairs.size());
  if (NormalEquationsImpl(rows.arg(), c.arg(), h.ret(), g.ret(), span).failure())
    fail("normal_equations", n, batch);
  for (int64_t b = 0; b < batch && batched; ++b) {
    Operand r1({1, m, 14}, false), c1({1, m}, false), h1({1, n, n}, false), g1({1, n}, false);
    copy(r1.data, rows.data + b * m * 14, m * 14);
    copy(c1.data, c.data + b * m, m);
    if (NormalEquationsImpl(r1.arg(), c1.arg(), h1.ret(), g1.ret(), span).failure() ||
        !same_bits(h1.data, h.data + b * n * n, n * n) ||
        !same_bits(g1.data, g.data + b * n, n))
      fail("normal_equations of a batch is each matrix's", n, batch);
    for (int64_t i = 0; i < n; ++i)
      for (int64_t j = 0; j < i; ++j)
        if (h1.data[i * n + j] != h1.data[j * n + i]) fail("JᵀJ symmetric", n, batch);
  }
  std::vector<int32_t> bad(pairs);
  if (!bad.empty()) bad[0] = static_cast<int32_t>(bodies);
  const ffi::Span<const int32_t> wrong(bad.data(), bad.size() - (bad.empty() ? 0 : 1));
  if (n > 0 && NormalEquationsImpl(rows.arg(), c.arg(), h.ret(), g.ret(), wrong).success())
    fail("normal_equations with bad pairs", n, batch);
}

// band_factor and band_solve on nb block rows of w1 blocks (random blocks, the diagonal
// ones dominant: positive definite, or one indefinite when `indefinite`): each matrix of
// a batch bitwise as alone, one factor (batch dimension 1) for a batch of right-hand
// sides bitwise as each alone, band_normal's assembly of random rows, and refused
// operands refused.
void band_case(int64_t nb, int64_t w1, int64_t batch, bool indefinite, bool misaligned,
               std::mt19937_64& rng) {
  const int64_t size = nb * w1 * 49;
  Operand band({batch, nb, w1, 7, 7}, misaligned), d({batch}, misaligned);
  fill(band, rng);
  for (int64_t b = 0; b < batch; ++b) {
    d.data[b] = 1e-3 * static_cast<double>(b);
    for (int64_t i = 0; i < nb; ++i)
      for (int64_t q = 0; q < 7; ++q)
        band.data[b * size + i * w1 * 49 + q * 8] = 10.0 * static_cast<double>(w1);
    if (indefinite && nb > 0) band.data[b * size + (nb / 2) * w1 * 49] = -1.0;
  }
  Operand l({batch, nb, w1, 7, 7}, misaligned);
  if (BandFactorImpl(band.arg(), d.arg(), l.ret()).failure()) fail("band_factor", nb, batch);
  Operand rhs({batch, nb, 7}, misaligned), x({batch, nb, 7}, misaligned);
  fill(rhs, rng);
  for (int32_t mode = 0; mode <= 2; ++mode)
    if (BandSolveImpl(l.arg(), rhs.arg(), x.ret(), mode).failure())
      fail("band_solve", nb, batch);
  for (int64_t b = 0; b < batch; ++b) {
    Operand band1({1, nb, w1, 7, 7}, false), d1({1}, false), l1({1, nb, w1, 7, 7}, false);
    copy(band1.data, band.data + b * size, size);
    d1.data[0] = d.data[b];
    if (BandFactorImpl(band1.arg(), d1.arg(), l1.ret()).failure() ||
        !same_bits(l1.data, l.data + b * size, size))
      fail("band_factor of a batch is each matrix's", nb, batch);
    // one factor for every right-hand side of the batch: as each alone
    Operand many({batch, nb, 7}, misaligned), one({1, nb, 7}, false), x1({1, nb, 7}, false);
    if (BandSolveImpl(l1.arg(), rhs.arg(), many.ret(), 2).failure())
      fail("band_solve of one factor for a batch", nb, batch);
    for (int64_t c = 0; c < batch; ++c) {
      copy(one.data, rhs.data + c * nb * 7, nb * 7);
      if (BandSolveImpl(l1.arg(), one.arg(), x1.ret(), 2).failure() ||
          !same_bits(x1.data, many.data + c * nb * 7, nb * 7))
        fail("band_solve of a batch is each right-hand side's", nb, batch);
    }
  }
  if (BandSolveImpl(l.arg(), rhs.arg(), x.ret(), 3).success()) fail("band_solve mode 3", nb, batch);
  Operand short_rhs({batch, nb + 1, 7}, false), short_x({batch, nb + 1, 7}, false);
  if (BandSolveImpl(l.arg(), short_rhs.arg(), short_x.ret(), 0).success())
    fail("band_solve with b of another block count", nb, batch);
  Operand six({batch, nb, w1, 7, 6}, false), six_out({batch, nb, w1, 7, 6}, false);
  if (BandFactorImpl(six.arg(), d.arg(), six_out.ret()).success())
    fail("band_factor of 7 x 6 blocks", nb, batch);
  Operand d2({batch + 1}, false);
  if (BandFactorImpl(band.arg(), d2.arg(), l.ret()).success())
    fail("band_factor with d of another batch", nb, batch);

  // band_normal: random rows on block rows at most w1 - 1 apart, each of a batch as alone
  if (nb == 0) return;
  const int64_t m = 3 * nb + 1;
  std::vector<int32_t> pairs(2 * m);
  std::uniform_int_distribution<int32_t> place(-1, static_cast<int32_t>(nb) - 1);
  for (int64_t r = 0; r < m; ++r) {
    pairs[2 * r] = place(rng);
    pairs[2 * r + 1] = place(rng);
    if (pairs[2 * r] >= 0 && pairs[2 * r + 1] >= 0 &&
        std::abs(pairs[2 * r] - pairs[2 * r + 1]) >= w1)
      pairs[2 * r + 1] = pairs[2 * r];
  }
  const ffi::Span<const int32_t> span(pairs.data(), pairs.size());
  Operand rows({batch, m, 14}, misaligned), c({batch, m}, misaligned);
  Operand h({batch, nb, w1, 7, 7}, misaligned), g({batch, nb, 7}, misaligned);
  fill(rows, rng);
  fill(c, rng);
  if (BandNormalImpl(rows.arg(), c.arg(), h.ret(), g.ret(), span).failure())
    fail("band_normal", nb, batch);
  for (int64_t b = 0; b < batch; ++b) {
    Operand r1({1, m, 14}, false), c1({1, m}, false), h1({1, nb, w1, 7, 7}, false),
        g1({1, nb, 7}, false);
    copy(r1.data, rows.data + b * m * 14, m * 14);
    copy(c1.data, c.data + b * m, m);
    if (BandNormalImpl(r1.arg(), c1.arg(), h1.ret(), g1.ret(), span).failure() ||
        !same_bits(h1.data, h.data + b * size, size) ||
        !same_bits(g1.data, g.data + b * nb * 7, nb * 7))
      fail("band_normal of a batch is each one's", nb, batch);
  }
  std::vector<int32_t> bad(pairs);
  bad[0] = static_cast<int32_t>(nb);
  if (BandNormalImpl(rows.arg(), c.arg(), h.ret(), g.ret(),
                     ffi::Span<const int32_t>(bad.data(), bad.size())).success())
    fail("band_normal with a block row out of range", nb, batch);
  if (nb > w1) {
    bad = pairs;
    bad[0] = 0;
    bad[1] = static_cast<int32_t>(w1);
    if (BandNormalImpl(rows.arg(), c.arg(), h.ret(), g.ret(),
                       ffi::Span<const int32_t>(bad.data(), bad.size())).success())
      fail("band_normal with a pair outside the band", nb, batch);
  }

  // arrow_normal with 1 or 2 of the nb bodies as hubs (last): any body pairs with a
  // hub; each of a batch as alone, the corner's two triangles each other's transpose
  for (int64_t hubs = 1; hubs <= 2 && hubs < nb; ++hubs) {
    const int64_t n = nb - hubs;
    for (int64_t r = 0; r < m; ++r)
      if (pairs[2 * r] >= 0 && pairs[2 * r + 1] >= 0 && pairs[2 * r] < n &&
          pairs[2 * r + 1] < n && std::abs(pairs[2 * r] - pairs[2 * r + 1]) >= w1)
        pairs[2 * r + 1] = pairs[2 * r];
    const ffi::Span<const int32_t> places(pairs.data(), pairs.size());
    const int64_t bsize = n * w1 * 49, csize = n * hubs * 49, dsize = hubs * hubs * 49;
    Operand band2({batch, n, w1, 7, 7}, misaligned), border({batch, n, hubs, 7, 7}, false),
        corner({batch, hubs, hubs, 7, 7}, misaligned), g2({batch, nb, 7}, false);
    if (ArrowNormalImpl(rows.arg(), c.arg(), band2.ret(), border.ret(), corner.ret(),
                        g2.ret(), places).failure())
      fail("arrow_normal", nb, batch);
    for (int64_t b = 0; b < batch; ++b) {
      Operand r1({1, m, 14}, false), c1({1, m}, false), a1({1, n, w1, 7, 7}, false),
          e1({1, n, hubs, 7, 7}, false), d1({1, hubs, hubs, 7, 7}, false),
          g1({1, nb, 7}, false);
      copy(r1.data, rows.data + b * m * 14, m * 14);
      copy(c1.data, c.data + b * m, m);
      if (ArrowNormalImpl(r1.arg(), c1.arg(), a1.ret(), e1.ret(), d1.ret(), g1.ret(),
                          places).failure() ||
          !same_bits(a1.data, band2.data + b * bsize, bsize) ||
          !same_bits(e1.data, border.data + b * csize, csize) ||
          !same_bits(d1.data, corner.data + b * dsize, dsize) ||
          !same_bits(g1.data, g2.data + b * nb * 7, nb * 7))
        fail("arrow_normal of a batch is each one's", nb, batch);
      for (int64_t i = 0; i < hubs; ++i)
        for (int64_t j = 0; j < hubs; ++j)
          for (int64_t k = 0; k < 49; ++k)
            if (d1.data[(i * hubs + j) * 49 + k] !=
                d1.data[(j * hubs + i) * 49 + (k % 7) * 7 + k / 7])
              fail("arrow_normal's corner symmetric", nb, batch);
    }
    Operand small({batch, n, hubs, 7, 6}, false);
    if (ArrowNormalImpl(rows.arg(), c.arg(), band2.ret(), small.ret(), corner.ret(),
                        g2.ret(), places).success())
      fail("arrow_normal with a border of 7 x 6 blocks", nb, batch);
  }
}

// Every handler on one (n, batch, kind); `batched`: a leading batch dimension (else a
// single matrix, batch 1).
void run_case(int64_t n, int64_t batch, Kind kind, bool batched, bool misaligned,
              std::mt19937_64& rng) {
  const bool refused = n > kMaxN;
  Operand a(shape(batch, batched, {n, n}), misaligned);
  if (!refused)
    for (int64_t b = 0; b < batch && n > 0; ++b) fill_matrix(kind, n, a.data + b * n * n, rng);

  // cholesky, and each matrix alone: the same bits
  Operand l(shape(batch, batched, {n, n}), misaligned);
  if (CholeskyImpl(a.arg(), l.ret()).failure() != refused) fail("cholesky", n, batch);
  if (!refused && n <= kLanesMaxN && batched)
    for (int64_t b = 0; b < batch; ++b) {
      Operand one({1, n, n}, false), out({1, n, n}, false);
      copy(one.data, a.data + b * n * n, n * n);
      if (CholeskyImpl(one.arg(), out.ret()).failure() ||
          !same_bits(out.data, l.data + b * n * n, n * n))
        fail("cholesky of a batch is each matrix's", n, batch);
    }
  if (refused) for (int64_t i = 0; i < l.size; ++i) l.data[i] = 1.0;

  // tri_solve, modes 0-2, k = 0, 1, 3, into a new result and over the right-hand side
  for (int64_t k : {0, 1, 3})
    for (int32_t mode = -1; mode <= 3; ++mode) {
      Operand rhs(shape(batch, batched, {n, k}), misaligned);
      Operand x(shape(batch, batched, {n, k}), misaligned);
      fill(rhs, rng);
      const bool bad = refused || mode < 0 || mode > 2;
      if (TriSolveImpl(l.arg(), rhs.arg(), x.ret(), mode).failure() != bad)
        fail("tri_solve", n, batch);
      if (TriSolveImpl(l.arg(), rhs.arg(), rhs.alias(), mode).failure() != bad)
        fail("tri_solve over b", n, batch);
      if (!bad && !same_bits(x.data, rhs.data, x.size))
        fail("tri_solve over b is tri_solve", n, batch);
    }
  Operand wrong(shape(batch, batched, {n + 1, 2}), misaligned);
  Operand wrong_x(shape(batch, batched, {n + 1, 2}), misaligned);
  if (TriSolveImpl(l.arg(), wrong.arg(), wrong_x.ret(), 0).success())
    fail("tri_solve of a wrong b", n, batch);

  // lower_inverse: a new result; over its operand refused unless empty
  Operand inv(shape(batch, batched, {n, n}), misaligned);
  if (LowerInverseImpl(l.arg(), inv.ret()).failure() != refused) fail("lower_inverse", n, batch);
  const bool empty = n == 0 || batch == 0;
  if (LowerInverseImpl(l.arg(), l.alias()).failure() != (refused || !empty))
    fail("lower_inverse over its operand", n, batch);

  // damped_solve, into a new result and over b, and each matrix alone
  Operand d(shape(batch, batched, {}), misaligned);
  for (int64_t i = 0; i < d.size; ++i) d.data[i] = kind == kIndefinite ? -0.5 : 0.25 * i;
  Operand rhs(shape(batch, batched, {n}), misaligned);
  Operand x(shape(batch, batched, {n}), misaligned);
  fill(rhs, rng);
  const bool damped_refused = n > kLanesMaxN;
  if (DampedSolveImpl(a.arg(), d.arg(), rhs.arg(), x.ret()).failure() != damped_refused)
    fail("damped_solve", n, batch);
  if (!damped_refused && batched)
    for (int64_t b = 0; b < batch; ++b) {
      Operand a1({1, n, n}, false), d1({1}, false), b1({1, n}, false), x1({1, n}, false);
      copy(a1.data, a.data + b * n * n, n * n);
      d1.data[0] = d.data[b];
      copy(b1.data, rhs.data + b * n, n);
      if (DampedSolveImpl(a1.arg(), d1.arg(), b1.arg(), x1.ret()).failure() ||
          !same_bits(x1.data, x.data + b * n, n))
        fail("damped_solve of a batch is each matrix's", n, batch);
    }
  if (DampedSolveImpl(a.arg(), d.arg(), rhs.arg(), rhs.alias()).failure() != damped_refused)
    fail("damped_solve over b", n, batch);
  if (!damped_refused && !same_bits(x.data, rhs.data, x.size))
    fail("damped_solve over b is damped_solve", n, batch);

  // smallest_right, k = 1, 6 and the widest, and a refused k
  for (int64_t k : {int64_t{1}, int64_t{6}, std::min<int64_t>(n, kSmallestMaxK), n + 1,
                    kSmallestMaxK + 1}) {
    if (k < 1) continue;
    Operand start(shape(batch, batched, {n, k}), misaligned);
    Operand v(shape(batch, batched, {n}), misaligned);
    fill(start, rng);
    const bool bad = refused || k > n || k > kSmallestMaxK;
    const int32_t iterations = static_cast<int32_t>(k % 4) + 1;
    if (SmallestRightImpl(a.arg(), start.arg(), v.ret(), iterations, 8, 1e-12).failure() !=
        bad)
      fail("smallest_right", n, batch);
    if (!bad && batched && n <= 91)
      for (int64_t b = 0; b < batch; ++b) {
        Operand a1({1, n, n}, false), s1({1, n, k}, false), v1({1, n}, false);
        copy(a1.data, a.data + b * n * n, n * n);
        copy(s1.data, start.data + b * n * k, n * k);
        if (SmallestRightImpl(a1.arg(), s1.arg(), v1.ret(), iterations, 8, 1e-12)
                .failure() ||
            !same_bits(v1.data, v.data + b * n, n))
          fail("smallest_right of a batch is each matrix's", n, batch);
      }
  }
  normal_case(n, batch, batched, misaligned, rng);
  Operand start(shape(batch, batched, {n, 1}), misaligned), v(shape(batch, batched, {n}), misaligned);
  if (n > 0 && !refused &&
      SmallestRightImpl(a.arg(), start.arg(), v.ret(), -1, 8, 0.0).success())
    fail("smallest_right with negative iterations", n, batch);
}

}  // namespace

int main() {
  std::mt19937_64 rng(20261206);
  const int64_t orders[] = {0, 1, 2, 5, 6, 7, 35, 89, 90, 91, 160, 161, 512, 513};
  int cases = 0;
  for (int64_t n : orders) {
    const auto begin = std::chrono::steady_clock::now();
    for (int64_t batch = 0; batch <= 9; ++batch) {
      // every kind up to order 35; above, one kind per batch size (all kinds over the
      // ten batch sizes), and at order 512 and above, batches 0, 1, 5 and 9 only
      for (int kind = 0; kind < kKinds; ++kind) {
        if (n > 35 && kind != static_cast<int>((batch + n) % kKinds)) continue;
        if (n >= 512 && batch != 0 && batch != 1 && batch != 5 && (batch != 9 || n == 512))
          continue;
        run_case(n, batch, static_cast<Kind>(kind), true, (batch + kind) % 2 == 1, rng);
        ++cases;
      }
    }
    const std::chrono::duration<double> took = std::chrono::steady_clock::now() - begin;
    std::printf("order %ld: %.2f s\n", static_cast<long>(n), took.count());
  }
  for (int64_t n : orders) {  // a single matrix, no batch dimension
    run_case(n, 1, kSpd, false, false, rng);
    ++cases;
  }
  for (int64_t nb : {0, 1, 2, 5, 40})
    for (int64_t w1 : {1, 2, 3, 6})
      for (int64_t batch : {0, 1, 3}) {
        band_case(nb, w1, batch, (nb + w1) % 2 == 1, (w1 + batch) % 2 == 1, rng);
        ++cases;
      }
  // six threads at once, each on its own operands
  std::vector<std::thread> threads;
  for (int t = 0; t < 6; ++t)
    threads.emplace_back([t] {
      std::mt19937_64 local(t);
      for (int64_t n : {7, 35, 91}) run_case(n, 9, static_cast<Kind>(t % kKinds), true, t % 2, local);
    });
  for (auto& thread : threads) thread.join();
  std::printf("%d cases, %d failures\n", cases + 18, failures.load());
  return failures == 0 ? 0 : 1;
}
