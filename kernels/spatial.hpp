// Spatial algebra on lanes (Featherstone, "Rigid Body Dynamics Algorithms",
// ch. 2), with 6-vectors ordered [linear; angular] for motions (v, w) and
// forces (f, n). Every quantity is expressed in some body's coordinates; the
// comments of each kernel say which.
#pragma once

#include "kernels/lane.hpp"

namespace lockstep {

template <class L>
struct Vec3 {
  L x, y, z;
};

// 3x3 matrix, row-major.
template <class L>
struct Mat3 {
  L m[9];
  const L& operator()(int r, int c) const { return m[3 * r + c]; }
  L& operator()(int r, int c) { return m[3 * r + c]; }
};

template <class L>
struct Vec6 {  // motion [v; w] or force [f; n]
  L e[6];
  Vec3<L> lin() const { return {e[0], e[1], e[2]}; }
  Vec3<L> ang() const { return {e[3], e[4], e[5]}; }
};

// A rigid transform between a parent frame and a child frame: the child's
// axes (columns of R) and origin p, in parent coordinates.
template <class L>
struct Transform {
  Mat3<L> R;
  Vec3<L> p;
};

// Symmetric 6x6 spatial inertia [[A, B], [B^T, C]] in one body's coordinates,
// f = A v + B w, n = B^T v + C w. A and C are symmetric, stored xx yy zz xy xz yz.
template <class L>
struct Inertia6 {
  L A[6];
  L B[9];
  L C[6];
};

namespace spatial {

template <class L> inline Vec3<L> add(const Vec3<L>& a, const Vec3<L>& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }
template <class L> inline Vec3<L> sub(const Vec3<L>& a, const Vec3<L>& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
template <class L> inline Vec3<L> scale(const L& s, const Vec3<L>& a) { return {s * a.x, s * a.y, s * a.z}; }
template <class L> inline L dot(const Vec3<L>& a, const Vec3<L>& b) {
  return lane::fmadd(a.z, b.z, lane::fmadd(a.y, b.y, a.x * b.x));
}
template <class L> inline Vec3<L> cross(const Vec3<L>& a, const Vec3<L>& b) {
  return {lane::fnmadd(a.z, b.y, a.y * b.z), lane::fnmadd(a.x, b.z, a.z * b.x), lane::fnmadd(a.y, b.x, a.x * b.y)};
}
// R a
template <class L> inline Vec3<L> rotate(const Mat3<L>& R, const Vec3<L>& a) {
  return {lane::fmadd(R.m[2], a.z, lane::fmadd(R.m[1], a.y, R.m[0] * a.x)),
          lane::fmadd(R.m[5], a.z, lane::fmadd(R.m[4], a.y, R.m[3] * a.x)),
          lane::fmadd(R.m[8], a.z, lane::fmadd(R.m[7], a.y, R.m[6] * a.x))};
}
// R^T a
template <class L> inline Vec3<L> rotate_back(const Mat3<L>& R, const Vec3<L>& a) {
  return {lane::fmadd(R.m[6], a.z, lane::fmadd(R.m[3], a.y, R.m[0] * a.x)),
          lane::fmadd(R.m[7], a.z, lane::fmadd(R.m[4], a.y, R.m[1] * a.x)),
          lane::fmadd(R.m[8], a.z, lane::fmadd(R.m[5], a.y, R.m[2] * a.x))};
}
// A B
template <class L> inline Mat3<L> mul(const Mat3<L>& A, const Mat3<L>& B) {
  Mat3<L> C;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      C(r, c) = lane::fmadd(A(r, 2), B(2, c), lane::fmadd(A(r, 1), B(1, c), A(r, 0) * B(0, c)));
  return C;
}
// Composition: parent<-child then child<-grandchild gives parent<-grandchild.
template <class L> inline Transform<L> compose(const Transform<L>& a, const Transform<L>& b) {
  return {mul(a.R, b.R), add(a.p, rotate(a.R, b.p))};
}

template <class L> inline Vec6<L> make6(const Vec3<L>& lin, const Vec3<L>& ang) {
  return {{lin.x, lin.y, lin.z, ang.x, ang.y, ang.z}};
}
template <class L> inline Vec6<L> add(const Vec6<L>& a, const Vec6<L>& b) {
  Vec6<L> c;
  for (int k = 0; k < 6; ++k) c.e[k] = a.e[k] + b.e[k];
  return c;
}
template <class L> inline Vec6<L> sub(const Vec6<L>& a, const Vec6<L>& b) {
  Vec6<L> c;
  for (int k = 0; k < 6; ++k) c.e[k] = a.e[k] - b.e[k];
  return c;
}
template <class L> inline Vec6<L> scale(const L& s, const Vec6<L>& a) {
  Vec6<L> c;
  for (int k = 0; k < 6; ++k) c.e[k] = s * a.e[k];
  return c;
}

// Motion from parent to child coordinates: w_c = R^T w, v_c = R^T (v + w x p).
template <class L> inline Vec6<L> motion_to_child(const Transform<L>& X, const Vec6<L>& m) {
  const Vec3<L> w = m.ang();
  return make6(rotate_back(X.R, add(m.lin(), cross(w, X.p))), rotate_back(X.R, w));
}
// Force from child to parent coordinates (the transpose of motion_to_child):
// f_p = R f, n_p = R n + p x R f.
template <class L> inline Vec6<L> force_to_parent(const Transform<L>& X, const Vec6<L>& f) {
  const Vec3<L> fp = rotate(X.R, f.lin());
  return make6(fp, add(rotate(X.R, f.ang()), cross(X.p, fp)));
}
// Motion cross product v x m = (w x m_v + v x m_w, w x m_w).
template <class L> inline Vec6<L> motion_cross(const Vec6<L>& v, const Vec6<L>& m) {
  const Vec3<L> w = v.ang();
  return make6(add(cross(w, m.lin()), cross(v.lin(), m.ang())), cross(w, m.ang()));
}
// Force cross product v x* f = (w x f, w x n + v x f).
template <class L> inline Vec6<L> force_cross(const Vec6<L>& v, const Vec6<L>& f) {
  const Vec3<L> w = v.ang();
  return make6(cross(w, f.lin()), add(cross(w, f.ang()), cross(v.lin(), f.lin())));
}

// --- symmetric 3x3 (xx yy zz xy xz yz) -------------------------------------
inline constexpr int kSym3[3][3] = {{0, 3, 4}, {3, 1, 5}, {4, 5, 2}};

template <class L> inline Vec3<L> sym_mul(const L* S, const Vec3<L>& a) {
  return {lane::fmadd(S[4], a.z, lane::fmadd(S[3], a.y, S[0] * a.x)),
          lane::fmadd(S[5], a.z, lane::fmadd(S[1], a.y, S[3] * a.x)),
          lane::fmadd(S[2], a.z, lane::fmadd(S[5], a.y, S[4] * a.x))};
}

// Element (r, c) of the full 6x6 matrix of an Inertia6, as an offset into
// its 21 stored values (A, then B row-major, then C): a table lookup rather
// than branches, so loops over (r, c) compile to straight loads.
inline constexpr int kSym6[6][6] = {
    {0, 3, 4, 6, 7, 8},     {3, 1, 5, 9, 10, 11},   {4, 5, 2, 12, 13, 14},
    {6, 9, 12, 15, 18, 19}, {7, 10, 13, 18, 16, 20}, {8, 11, 14, 19, 20, 17}};
static_assert(kSym6[0][3] == 6 && kSym6[5][4] == 15 + 5, "B follows A, C follows B");
template <class L> inline const L& at(const Inertia6<L>& I, int r, int c) {
  static_assert(sizeof(Inertia6<L>) == 21 * sizeof(L), "Inertia6 is 21 contiguous lanes");
  return reinterpret_cast<const L*>(&I)[kSym6[r][c]];
}
template <class L> inline L& at(Inertia6<L>& I, int r, int c) {
  return reinterpret_cast<L*>(&I)[kSym6[r][c]];
}

// Spatial inertia of a rigid body with mass m, centre of mass c and rotational
// inertia Ic about c (symmetric, xx yy zz xy xz yz), all in body coordinates:
// A = m 1, B = -m [c]x, C = Ic + m (|c|^2 1 - c c^T)   (RBDA eq. 2.63).
template <class L> inline Inertia6<L> rigid_inertia(const L& m, const Vec3<L>& c, const L* Ic) {
  Inertia6<L> I;
  const L zero(0);
  I.A[0] = m; I.A[1] = m; I.A[2] = m; I.A[3] = zero; I.A[4] = zero; I.A[5] = zero;
  const Vec3<L> mc = scale(m, c);
  I.B[0] = zero;  I.B[1] = mc.z;  I.B[2] = -mc.y;
  I.B[3] = -mc.z; I.B[4] = zero;  I.B[5] = mc.x;
  I.B[6] = mc.y;  I.B[7] = -mc.x; I.B[8] = zero;
  I.C[0] = lane::fmadd(mc.z, c.z, lane::fmadd(mc.y, c.y, Ic[0]));
  I.C[1] = lane::fmadd(mc.z, c.z, lane::fmadd(mc.x, c.x, Ic[1]));
  I.C[2] = lane::fmadd(mc.y, c.y, lane::fmadd(mc.x, c.x, Ic[2]));
  I.C[3] = lane::fnmadd(mc.x, c.y, Ic[3]);
  I.C[4] = lane::fnmadd(mc.x, c.z, Ic[4]);
  I.C[5] = lane::fnmadd(mc.y, c.z, Ic[5]);
  return I;
}

// I m for a rigid body from its parameters, without forming the 6x6 matrix:
// f = m (m_v + m_w x c), n = Ic m_w + c x f.
template <class L> inline Vec6<L> rigid_mul(const L& m, const Vec3<L>& c, const L* Ic, const Vec6<L>& a) {
  const Vec3<L> w = a.ang();
  const Vec3<L> f = scale(m, add(a.lin(), cross(w, c)));
  return make6(f, add(sym_mul(Ic, w), cross(c, f)));
}

template <class L> inline Vec6<L> mul(const Inertia6<L>& I, const Vec6<L>& a) {
  const Vec3<L> v = a.lin(), w = a.ang();
  const Vec3<L> Av = sym_mul(I.A, v);
  const Vec3<L> Cw = sym_mul(I.C, w);
  const Mat3<L>& B = reinterpret_cast<const Mat3<L>&>(I.B);
  return make6(add(Av, rotate(B, w)), add(rotate_back(B, v), Cw));
}

template <class L> inline void add_to(Inertia6<L>& I, const Inertia6<L>& J) {
  for (int k = 0; k < 6; ++k) I.A[k] = I.A[k] + J.A[k];
  for (int k = 0; k < 9; ++k) I.B[k] = I.B[k] + J.B[k];
  for (int k = 0; k < 6; ++k) I.C[k] = I.C[k] + J.C[k];
}

// R S R^T for symmetric S.
template <class L> LOCKSTEP_INLINE void rotate_sym(const Mat3<L>& R, const L* S, L* out) {
  // T = R S (full), then out = T R^T, upper triangle only.
  Mat3<L> T;
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      T(r, c) = lane::fmadd(R(r, 2), S[kSym3[2][c]], lane::fmadd(R(r, 1), S[kSym3[1][c]], R(r, 0) * S[kSym3[0][c]]));
  const int rows[6] = {0, 1, 2, 0, 0, 1}, cols[6] = {0, 1, 2, 1, 2, 2};
  for (int k = 0; k < 6; ++k) {
    const int r = rows[k], c = cols[k];
    out[k] = lane::fmadd(T(r, 2), R(c, 2), lane::fmadd(T(r, 1), R(c, 1), T(r, 0) * R(c, 0)));
  }
}

// Whether a result overwrites its destination or is added to it.
enum class Write { Set, Add };
template <Write mode, class L> LOCKSTEP_INLINE void write(L& out, const L& value) {
  if constexpr (mode == Write::Add) out = out + value;
  else out = value;
}

// The inertia seen from the parent, X^T I X with X = motion_to_child(X),
// written (or added) to out. First rotate into parent axes (A' = R A R^T,
// B' = R B R^T, C' = R C R^T), then shift the origin by p with P = [p]x:
//   A'' = A', B'' = B' - A' P, C'' = C' + P B' + (P B')^T - P A' P.
template <Write mode, class L>
LOCKSTEP_INLINE void inertia_to_parent(const Transform<L>& X, const Inertia6<L>& I, Inertia6<L>& out) {
  L A[6], C[6];
  rotate_sym(X.R, I.A, A);
  rotate_sym(X.R, I.C, C);
  Mat3<L> RB, Bp;  // R B, then B' = (R B) R^T
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      RB(r, c) = lane::fmadd(X.R(r, 2), I.B[6 + c], lane::fmadd(X.R(r, 1), I.B[3 + c], X.R(r, 0) * I.B[c]));
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c)
      Bp(r, c) = lane::fmadd(RB(r, 2), X.R(c, 2), lane::fmadd(RB(r, 1), X.R(c, 1), RB(r, 0) * X.R(c, 0)));
  const Vec3<L>& p = X.p;
  // B'' = B' - A' P, with P = [[0,-z,y],[z,0,-x],[-y,x,0]].
  auto a = [&](int r, int c) -> const L& { return A[kSym3[r][c]]; };
  Mat3<L> Bpp;
  for (int r = 0; r < 3; ++r) {
    Bpp(r, 0) = Bp(r, 0) - lane::fnmadd(a(r, 2), p.y, a(r, 1) * p.z);
    Bpp(r, 1) = Bp(r, 1) - lane::fnmadd(a(r, 0), p.z, a(r, 2) * p.x);
    Bpp(r, 2) = Bp(r, 2) - lane::fnmadd(a(r, 1), p.x, a(r, 0) * p.y);
  }
  // P M for a 3x3 M: row r of P times M.
  auto P_mul = [&](const Mat3<L>& M) {
    Mat3<L> PM;
    for (int c = 0; c < 3; ++c) {
      PM(0, c) = lane::fnmadd(p.z, M(1, c), p.y * M(2, c));
      PM(1, c) = lane::fnmadd(p.x, M(2, c), p.z * M(0, c));
      PM(2, c) = lane::fnmadd(p.y, M(0, c), p.x * M(1, c));
    }
    return PM;
  };
  // C'' = C' + P B' + (P B')^T - P A' P = C' + P (B' - A' P) + (P B')^T
  //     = C' + P B'' + (P B')^T. Symmetric, so only the upper triangle is needed.
  const Mat3<L> PBpp = P_mul(Bpp);
  const Mat3<L> PBp = P_mul(Bp);
  const int rows[6] = {0, 1, 2, 0, 0, 1}, cols[6] = {0, 1, 2, 1, 2, 2};
  for (int k = 0; k < 6; ++k) write<mode>(out.A[k], A[k]);
  for (int k = 0; k < 9; ++k) write<mode>(out.B[k], Bpp.m[k]);
  for (int k = 0; k < 6; ++k) write<mode>(out.C[k], C[k] + PBpp(rows[k], cols[k]) + PBp(cols[k], rows[k]));
}

}  // namespace spatial
}  // namespace lockstep
