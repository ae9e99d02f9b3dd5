// sqrt(x^2 + y^2) for the friction projection of the fixed-size step kernels, which runs it in
// every fixed-point pass of every step (docs/method.md §5 (S7)): a call to libm's hypot cost ~111
// of the 3-DOF transient's ~740 instructions per step (benchmarks/transient_instructions.sh), most
// of it the call and the entry tests of the library function.
//
// Hypot returns the same number as std::hypot. Where the C library is glibc >= 2.35 on x86-64,
// whose hypot is C. F. Borges' algorithm (An improved algorithm for hypot(a, b), Numer. Algorithms
// 86 (2021), with the correction step that needs no FMA: Debian's libm is built for generic
// x86-64), the common case (both magnitudes in [2^-459, 2^511], neither negligible against the
// other) is that algorithm written out, with the same operations in the same order and each
// product rounded as there (Rounded); every other case, and every other C library, calls
// std::hypot. Test LocalSolver.HypotIsLibmHypot checks that the two agree bit for bit.
#pragma once

#include <cmath>

namespace squeal {

// x as a rounded double: the compiler may not fuse the product that made x into the sum that uses
// it (-mfma contracts a * b + c into one FMA, rounded once where the source rounds twice). No
// instruction is emitted.
inline __attribute__((always_inline)) double Rounded(double x)
{
#if defined(__GNUC__) && (defined(__x86_64__) || defined(__i386__))
  __asm__("" : "+x"(x));
#endif
  return x;
}

#if defined(__GLIBC__) && defined(__x86_64__) && defined(__GNUC__) && (__GLIBC__ > 2 || (__GLIBC__ == 2 && __GLIBC_MINOR__ >= 35))
  #define SQUEAL_WRITTEN_OUT_HYPOT 1
#else
  #define SQUEAL_WRITTEN_OUT_HYPOT 0
#endif

// True where Hypot writes libm's algorithm out (glibc >= 2.35, x86-64), false where it calls std::hypot.
constexpr bool HypotWrittenOut() { return SQUEAL_WRITTEN_OUT_HYPOT; }

// std::hypot(x, y), the same number (see above).
inline __attribute__((always_inline)) double Hypot(double x, double y)
{
#if SQUEAL_WRITTEN_OUT_HYPOT
  const double fx = std::abs(x), fy = std::abs(y);
  const double ax = fx < fy ? fy : fx, ay = fx < fy ? fx : fy;
  // glibc's range tests (its 2.36 bounds 2^511, 2^-459, 2^-54): NaN and infinity fail the first two.
  if (__builtin_expect(ax <= 0x1p+511 && ay >= 0x1p-459 && ay > ax * 0x1p-54, 1)) {
    double h = std::sqrt(Rounded(ax * ax) + Rounded(ay * ay)), t1, t2;
    if (h <= ay + ay) {
      const double d = h - ay;
      t1             = Rounded(ax * ((d + d) - ax));
      t2             = Rounded((d - 2.0 * (ax - ay)) * d);
    } else {
      const double d = h - ax;
      t1             = Rounded((d + d) * (ax - 2.0 * ay));
      t2             = Rounded(Rounded((4.0 * d - ay) * ay) + Rounded(d * d));
    }
    return h - (t1 + t2) / (h + h);
  }
#endif
  return std::hypot(x, y);
}

} // namespace squeal
