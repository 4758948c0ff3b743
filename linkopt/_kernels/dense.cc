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
// Every handler refuses n > kMaxN, mismatched shapes and an unknown mode with an
// ffi::Error; none allocates. Single-threaded, plain loops written as axpys so
// -O3 vectorises them without -ffast-math (no reassociated reductions, except the
// explicit 4-accumulator dot).
//
// kVersion is the ABI of these handlers (names, operands, attributes, semantics):
// increment it with any such change; linkopt/_kernels/__init__.py refuses an extension
// of another version.
#define PY_SSIZE_T_CLEAN
#include <Python.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <string>

#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr long kVersion = 1;
constexpr int64_t kMaxN = 512;
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

// l = lower Cholesky factor of the lower triangle of a (n x n, row-major); a and l may
// be the same buffer. Right-looking: after column k is final, the trailing lower
// triangle gets a[i, k+1..i] -= L[i,k] * L[k+1..i, k], with L[:, k] copied to the
// contiguous buffer col (n entries). NaN in L[i, c] for all c >= the first
// non-positive (or NaN) pivot, i >= c.
void chol_one(const double* a, double* __restrict l, int64_t n, double* __restrict col) {
  for (int64_t i = 0; i < n; ++i) {
    if (a != l)
      for (int64_t j = 0; j <= i; ++j) l[i * n + j] = a[i * n + j];
    for (int64_t j = i + 1; j < n; ++j) l[i * n + j] = 0.0;
  }
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

ffi::Error CholeskyImpl(ffi::Buffer<ffi::F64> a, ffi::ResultBuffer<ffi::F64> out) {
  int64_t n, batch;
  if (auto e = square_dims(a, &n, &batch); e.failure()) return e;
  if (auto e = same_dims(a.dimensions(), out->dimensions()); e.failure()) return e;
  double col[kMaxN];
  const double* src = a.typed_data();
  double* dst = out->typed_data();
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
  const double* lp = l.typed_data();
  const double* bp = b.typed_data();
  double* xp = out->typed_data();
  if (xp != bp) std::memcpy(xp, bp, sizeof(double) * batch * n * k);
  if (k == 0) return ffi::Error::Success();
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
  const double* lp = l.typed_data();
  double* xp = out->typed_data();
  if (xp == lp && n > 0)
    return ffi::Error::InvalidArgument("lower_inverse cannot write over its operand");
  for (int64_t i = 0; i < batch; ++i) lower_inverse_one(lp + i * n * n, xp + i * n * n, n);
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

// ---- the Python extension module linkopt._kernels._dense ---------------------------

#ifndef LK_SOURCE_SHA256
#define LK_SOURCE_SHA256 ""
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
      !add_capsule(dict, "lower_inverse", LkLowerInverse)) {
    Py_DECREF(dict);
    return nullptr;
  }
  return dict;
}

PyObject* version(PyObject*, PyObject*) { return PyLong_FromLong(kVersion); }

PyObject* max_n(PyObject*, PyObject*) { return PyLong_FromLongLong(kMaxN); }

PyObject* ffi_api_version(PyObject*, PyObject*) {
  return Py_BuildValue("(ii)", XLA_FFI_API_MAJOR, XLA_FFI_API_MINOR);
}

PyObject* source_sha256(PyObject*, PyObject*) {
  return PyUnicode_FromString(LK_SOURCE_SHA256);
}

PyMethodDef methods[] = {
    {"capsules", capsules, METH_NOARGS,
     "{'cholesky', 'tri_solve', 'lower_inverse'} -> a PyCapsule of each XLA FFI "
     "handler, for jax.ffi.register_ffi_target(name, capsule, platform='cpu')."},
    {"version", version, METH_NOARGS, "The ABI version of the handlers (an int)."},
    {"max_n", max_n, METH_NOARGS, "The largest matrix order n the handlers accept."},
    {"ffi_api_version", ffi_api_version, METH_NOARGS,
     "(major, minor) of the XLA FFI headers the handlers were built with."},
    {"source_sha256", source_sha256, METH_NOARGS,
     "SHA-256 of the dense.cc text this module was built from ('' if unknown)."},
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
