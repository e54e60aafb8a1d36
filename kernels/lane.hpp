// The lane type: one environment copy per lane. Kernels are templates on a
// lane type L, which is either a plain float/double (the scalar reference:
// one copy) or xsimd::batch<T> (all lanes of one SIMD register). Only this
// header knows about xsimd; kernels use the operators and the functions below.
//
// Every function here rounds identically in the scalar and the SIMD
// instantiation (IEEE +,-,*,/,sqrt; explicit fused multiply-add; sin/cos by
// the same polynomial), so SIMD lanes reproduce the scalar reference bit for
// bit. Build with -ffp-contract=off so the compiler adds no fusions of its own.
#pragma once

#include <xsimd/xsimd.hpp>

#include <cmath>
#include <cstddef>
#include <type_traits>

// For the small helpers that move a body's whole 6x6 blocks: inlined, their
// operands stay in registers rather than passing through a return slot in
// memory (which compilers otherwise fill with a memcpy call).
#define LOCKSTEP_INLINE inline __attribute__((always_inline))

namespace lockstep::lane {

using simd_arch = xsimd::default_arch;
template <class T>
using simd = xsimd::batch<T, simd_arch>;

template <class L>
struct traits {  // the scalar reference: one lane
  using scalar = L;
  using mask = bool;
  static constexpr std::size_t width = 1;
};
template <class T, class A>
struct traits<xsimd::batch<T, A>> {
  using scalar = T;
  using mask = xsimd::batch_bool<T, A>;
  static constexpr std::size_t width = xsimd::batch<T, A>::size;
};

template <class L>
using scalar_t = typename traits<L>::scalar;
template <class L>
using mask_t = typename traits<L>::mask;
template <class L>
inline constexpr std::size_t width_v = traits<L>::width;
template <class L>
inline constexpr bool is_scalar_v = std::is_floating_point_v<L>;

// Memory: `p` points at `width` consecutive copies of one field.
template <class L>
inline L load(const scalar_t<L>* p) {
  if constexpr (is_scalar_v<L>) return *p;
  else return L::load_aligned(p);
}
template <class L>
inline void store(const L& x, scalar_t<L>* p) {
  if constexpr (is_scalar_v<L>) *p = x;
  else x.store_aligned(p);
}
template <class L>
inline L broadcast(scalar_t<L> x) { return L(x); }

// a*b + c, fused (one rounding) wherever the target has FMA, on every
// instantiation alike: the scalar reference fuses exactly when the SIMD lanes
// do. (xsimd 8.1 leaves AVX-512 fma unfused, hence the intrinsics.)
template <class L>
inline L fmadd(const L& a, const L& b, const L& c) {
  if constexpr (is_scalar_v<L>) {
#if defined(__FMA__)
    return std::fma(a, b, c);
#else
    return a * b + c;
#endif
  } else {
#if defined(__AVX512F__)
    if constexpr (std::is_same_v<simd_arch, xsimd::avx512bw> || std::is_same_v<simd_arch, xsimd::avx512dq> ||
                  std::is_same_v<simd_arch, xsimd::avx512cd> || std::is_same_v<simd_arch, xsimd::avx512f>) {
      if constexpr (std::is_same_v<scalar_t<L>, float>) return L(_mm512_fmadd_ps(a, b, c));
      else return L(_mm512_fmadd_pd(a, b, c));
    }
#endif
    return xsimd::fma(a, b, c);
  }
}
// c - a*b, with the same rounding rule as fmadd.
template <class L>
inline L fnmadd(const L& a, const L& b, const L& c) {
  return fmadd(L(-a), b, c);
}

template <class L>
inline L sqrt(const L& x) {
  if constexpr (is_scalar_v<L>) return std::sqrt(x);
  else return xsimd::sqrt(x);
}
template <class L>
inline L abs(const L& x) {
  if constexpr (is_scalar_v<L>) return std::fabs(x);
  else return xsimd::abs(x);
}
// min and max as the x86 instructions define them, also for NaN: the
// second operand unless the comparison holds (so both lane types agree).
template <class L>
inline L min(const L& a, const L& b) {
  if constexpr (is_scalar_v<L>) return a < b ? a : b;
  else return xsimd::min(a, b);
}
template <class L>
inline L max(const L& a, const L& b) {
  if constexpr (is_scalar_v<L>) return a > b ? a : b;
  else return xsimd::max(a, b);
}
// Round to the nearest integer, ties to even (the current rounding mode).
template <class L>
inline L round_even(const L& x) {
  if constexpr (is_scalar_v<L>) return std::nearbyint(x);
  else return xsimd::nearbyint(x);
}
// Lane-wise choice, never a branch on lane data.
template <class L>
inline L select(const mask_t<L>& m, const L& a, const L& b) {
  if constexpr (is_scalar_v<L>) return m ? a : b;
  else return xsimd::select(m, a, b);
}
// True in lanes that hold a finite number.
template <class L>
inline mask_t<L> is_finite(const L& x) {
  if constexpr (is_scalar_v<L>) return std::isfinite(x);
  else return xsimd::isfinite(x);
}
template <class L>
inline bool all(const mask_t<L>& m) {
  if constexpr (is_scalar_v<L>) return m;
  else return xsimd::all(m);
}
template <class L>
inline bool any(const mask_t<L>& m) {
  if constexpr (is_scalar_v<L>) return m;
  else return xsimd::any(m);
}
template <class L>
inline L clamp(const L& x, const L& lo, const L& hi) {
  return min(max(x, lo), hi);
}

// e^x for x in about [-87, 88] (float) or [-708, 709] (double), to about
// 1 ulp: x = n ln2 + r with |r| <= ln2/2 (Cody-Waite), e^r by a polynomial
// (Cephes' expf minimax for float, the Taylor series to r^13 for double,
// whose remainder is below 1e-17), then an exact scaling by 2^n.
template <class L>
inline L exp(const L& x) {
  using T = scalar_t<L>;
  const L n = round_even(x * L(T(1.44269504088896340736)));  // x / ln 2
  L r, p;
  if constexpr (std::is_same_v<T, float>) {
    r = fnmadd(n, L(0.693359375f), x);
    r = fnmadd(n, L(-2.12194440e-4f), r);
    p = fmadd(fmadd(fmadd(fmadd(fmadd(L(1.9875691500e-4f), r, L(1.3981999507e-3f)), r, L(8.3334519073e-3f)), r,
                            L(4.1665795894e-2f)), r, L(1.6666665459e-1f)), r, L(5.0000001201e-1f));
    p = fmadd(p, r * r, r + L(1.0f));
  } else {
    r = fnmadd(n, L(6.93145751953125e-1), x);
    r = fnmadd(n, L(1.42860682030941723212e-6), r);
    p = L(1.0 / 6227020800.0);  // 1/13!
    const double inverse_factorials[13] = {1.0 / 479001600.0, 1.0 / 39916800.0, 1.0 / 3628800.0, 1.0 / 362880.0,
                                           1.0 / 40320.0, 1.0 / 5040.0, 1.0 / 720.0, 1.0 / 120.0, 1.0 / 24.0,
                                           1.0 / 6.0, 0.5, 1.0, 1.0};
    for (double c : inverse_factorials) p = fmadd(p, r, L(c));
  }
  if constexpr (is_scalar_v<L>) return std::ldexp(p, static_cast<int>(n));
  else return xsimd::ldexp(p, xsimd::to_int(n));
}

// sin and cos of x together, to about 1 ulp for |x| < 1e4 (joint angles;
// larger arguments lose accuracy in the Cody-Waite reduction). Cephes'
// minimax polynomials on [-pi/4, pi/4] after reducing by multiples of pi/2.
// Where the reduction fails (|x| beyond about 1e7 in float, 1e15 in
// double, where an ulp of x is a radian or more) its remainder is clamped
// to the polynomials' interval, so that (s, c) stays on the unit circle:
// the angle is lost there, but a rotation stays a rotation.
template <class L>
inline void sincos(const L& x, L& s, L& c) {
  using T = scalar_t<L>;
  const L quadrant = round_even(x * L(T(0.63661977236758134308)));  // x / (pi/2)
  // x - quadrant * pi/2 in three parts (Cody-Waite), exact products by fma.
  L r;
  if constexpr (std::is_same_v<T, float>) {
    r = fnmadd(quadrant, L(1.5703125f), x);
    r = fnmadd(quadrant, L(4.837512969970703125e-4f), r);
    r = fnmadd(quadrant, L(7.54978995489188216e-8f), r);
  } else {
    r = fnmadd(quadrant, L(1.57079625129699707031), x);
    r = fnmadd(quadrant, L(7.54978941586159635336e-8), r);
    r = fnmadd(quadrant, L(5.39030285815811905290e-15), r);
  }
  // pi/4 and a little: a reduction that works never reaches it; NaN passes
  const L bound(T(0.79));
  r = select(abs(r) > bound, select(r > L(T(0)), bound, -bound), r);
  const L r2 = r * r;
  L sin_r, cos_r;
  if constexpr (std::is_same_v<T, float>) {
    sin_r = fmadd(fmadd(fmadd(L(-1.9515295891e-4f), r2, L(8.3321608736e-3f)), r2,
                        L(-1.6666654611e-1f)), r2 * r, r);
    cos_r = fmadd(fmadd(fmadd(L(2.443315711809948e-5f), r2, L(-1.388731625493765e-3f)), r2,
                        L(4.166664568298827e-2f)), r2 * r2, fnmadd(L(0.5f), r2, L(1.0f)));
  } else {
    sin_r = fmadd(fmadd(fmadd(fmadd(fmadd(fmadd(L(1.58962301576546568060e-10), r2,
        L(-2.50507477628578072866e-8)), r2, L(2.75573136213857245213e-6)), r2,
        L(-1.98412698295895385996e-4)), r2, L(8.33333333332211858878e-3)), r2,
        L(-1.66666666666666307295e-1)), r2 * r, r);
    cos_r = fmadd(fmadd(fmadd(fmadd(fmadd(fmadd(L(-1.13585365213876817300e-11), r2,
        L(2.08757008419747316778e-9)), r2, L(-2.75573141792967388112e-7)), r2,
        L(2.48015872888517045348e-5)), r2, L(-1.38888888888730564116e-3)), r2,
        L(4.16666666666665929218e-2)), r2 * r2, fnmadd(L(0.5), r2, L(1.0)));
  }
  // Quadrant k: (sin, cos) = (s, c), (c, -s), (-s, -c), (-c, s).
  const L k = quadrant - L(T(4)) * round_even((quadrant - L(T(1.5))) * L(T(0.25)));  // k in {0..3}
  const auto swap = (k == L(T(1))) || (k == L(T(3)));
  const L s0 = select(swap, cos_r, sin_r);
  const L c0 = select(swap, sin_r, cos_r);
  s = select(k >= L(T(2)), -s0, s0);
  c = select((k == L(T(1))) || (k == L(T(2))), -c0, c0);
}

// atan2(y, x) in (-pi, pi] for finite y and x, to about 2 ulps, the same
// code on both lane types (libm's and xsimd's round differently, which made
// SIMD lanes differ from the scalar reference). Cephes' atan: with
// t = min(|y|, |x|) / max(|y|, |x|) in [0, 1], t above tan(pi/8) is reduced
// by atan t = pi/4 + atan((t - 1)/(t + 1)); then atan of the reduced t by
// Cephes' minimax polynomial (float) or P/Q rational function (double);
// then pi/2 - a where |y| > |x|, pi - a where x < 0, and y's sign (a -0 y
// counts as +0). atan2(0, 0) is 0. Angles near pi/2, pi/4 and pi are formed
// from two-part constants, so their rounding stays under an ulp.
template <class L>
inline L atan2(const L& y, const L& x) {
  using T = scalar_t<L>;
  const L ay = abs(y), ax = abs(x);
  const L num = min(ay, ax), den = max(ay, ax);
  const L zero(T(0)), one(T(1));
  const L t0 = select(den > zero, num / select(den > zero, den, one), zero);
  const auto reduce = t0 > L(T(0.41421356237309504880));  // tan(pi/8)
  const L t = select(reduce, (t0 - one) / (t0 + one), t0);
  const L z = t * t;
  L p;
  if constexpr (std::is_same_v<T, float>) {
    p = fmadd(fmadd(fmadd(L(8.05374449538e-2f), z, L(-1.38776856032e-1f)), z, L(1.99777106478e-1f)), z,
              L(-3.33329491539e-1f));
    p = p * z;
  } else {
    const L P = fmadd(fmadd(fmadd(fmadd(L(-8.750608600031904122785e-1), z, L(-1.615753718733365076637e1)), z,
                                  L(-7.500855792314704667340e1)), z, L(-1.228866684490136173410e2)), z,
                      L(-6.485021904942025371773e1));
    const L Q = fmadd(fmadd(fmadd(fmadd(z + L(2.485846490142306297962e1), z, L(1.650270098316988542046e2)), z,
                                  L(4.328810604912902668951e2)), z, L(4.853903996359136964868e2)), z,
                      L(1.945506571482613964425e2));
    p = z * P / Q;
  }
  // pi/4, pi/2 and pi as hi + lo: hi the nearest T, lo the rest.
  constexpr bool f = std::is_same_v<T, float>;
  constexpr T pi_4_hi = f ? T(0.785398185f) : T(0.78539816339744828);
  constexpr T pi_4_lo = f ? T(-2.1855695e-08f) : T(3.061616997868383e-17);
  constexpr T pi_2_hi = f ? T(1.57079637f) : T(1.5707963267948966);
  constexpr T pi_2_lo = f ? T(-4.371139e-08f) : T(6.123233995736766e-17);
  constexpr T pi_hi = f ? T(3.14159274f) : T(3.1415926535897931);
  constexpr T pi_lo = f ? T(-8.742278e-08f) : T(1.2246467991473532e-16);
  // atan t = t + t p (+ pi/4 where reduced), the small parts summed first.
  const L a = select(reduce, L(pi_4_hi) + (fmadd(t, p, L(pi_4_lo)) + t), fmadd(t, p, t));
  const L b = select(ay > ax, L(pi_2_hi) - (a - L(pi_2_lo)), a);
  const L c = select(x < zero, L(pi_hi) - (b - L(pi_lo)), b);
  return select(y < zero, -c, c);
}

}  // namespace lockstep::lane
