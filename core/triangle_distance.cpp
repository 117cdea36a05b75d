// Closest point on a triangle: the Voronoi-region method of Ericson, Real-Time Collision
// Detection (2005), section 5.1.5, made robust for degenerate triangles. The choice of corner
// follows the "troublesome triangle" note of Box2D (E. Catto, 2014): build the normal and the
// 2x2 system from the two shortest edges.
//
// For one triangle (scalar) and for each lane of a block (SIMD) alike:
//   1. rotate the corners (a, b, c) so that a is opposite the longest edge, i.e. at the largest
//      angle; ab and ac are then the two shortest edges;
//   2. a sliver or cap (sin^2 of the largest angle below kSliver, down to collinear in
//      doubles): the projection q of p onto the plane, and its edge functions, in quadruple
//      precision from the same doubles (the normal's relative error eps / sin of the largest
//      angle becomes 1e-34 / sin); q inside: the point rebuilt from its coordinates; else, or
//      when even quadruple precision finds the corners collinear (sin^2 <= 1e-34), the closest
//      of the three segments (zero-length segments give their end point);
//   3. a needle (sin^2 of the smallest angle below kSliver, the largest not near 180 degrees:
//      its normal is accurate): q and its edge functions in doubles, in quadruple precision
//      where an edge function lies within its rounding of 0 (q near an edge's line, as beyond
//      the tip); q inside: q itself, its coordinates from the quadruple edge functions; else
//      the closest segment;
//   otherwise Ericson's tests, first match wins, with d1 = ab.ap, d2 = ac.ap, e = bc.bp,
//      vb = |ac|^2 d1 - (ab.ac) d2, vc = |ab|^2 d2 - (ab.ac) d1, va = det - vb - vc:
//        vertex a   d1 <= 0 and d2 <= 0
//        vertex b   d1 >= |ab|^2 and e <= 0
//        edge ab    vc <= 0 and 0 <= d1 <= |ab|^2            t = d1 / |ab|^2
//        vertex c   d2 >= |ac|^2 and e >= |bc|^2
//        edge ac    vb <= 0 and 0 <= d2 <= |ac|^2            t = d2 / |ac|^2
//        edge bc    va <= 0 and 0 <= e <= |bc|^2             t = e / |bc|^2
//        face       (va, vb, vc) clamped at 0, divided by their sum
//   4. point = O + v*E1 + w*E2 (O a corner, E1 and E2 edges; a vertex is returned exactly) and
//      squared distance = |p - point|^2 of that returned point.
// The block runs the same formulas (the same templates, with explicit FMAs) on every lane, every
// case of step 4 computed and the first matching one selected with masks: AVX-512 (8 lanes),
// AVX2 (2 x 4) or plain scalar code, by the instruction set compiled for; its thin lanes (steps
// 2 and 3, and non-finite ones) call the scalar function. Its values are the scalar ones bit
// for bit (the tests compare them on random and degenerate lanes).
//
// What is not computed exactly (\bug):
//  - the rounding of the returned point, a few eps * |coordinates| (absolute: a mesh far from
//    the origin loses digits on small distances);
//  - a triangle collinear to quadruple precision (sin^2 of its largest angle <= 1e-34) is
//    answered by its segments, off by at most half its height (5e-18 of its length);
//  - the Gram terms are fourth powers of coordinate differences: beyond about 1e75 (or below
//    1e-75) they overflow (underflow) (meshes are limited to sizes in [1e-50, 1e50],
//    core/mesh.h).
// Cost: a sliver tested costs about a hundred software quadruple-precision operations (a mesh
// made mostly of slivers, mpi, queries about 6 times slower than with doubles alone); a needle
// only near its edges' lines.
#include "core/triangle_distance.h"

#include <cmath>

#if defined(__AVX512F__) || defined(__AVX2__)
#include <immintrin.h>
#endif

namespace meshsweeper {
namespace {

// sin^2 of the largest angle at or below which a triangle has no reliable normal in doubles
// (isDegenerateTriangle: the projection's error eps / sin of |ap| reaches the half height,
// sin / 2, of the length at sin^2 = 2 eps). The distance itself no longer stops there (step 2).
constexpr double kDegenerate = 1e-15;
// sin^2 of the smallest angle below which a triangle is thin (an angle below about 1.8
// degrees): a sliver's Gram numerators lose about eps / sin^2 of |ap| (measured: a point on a
// sliver of sin^2 1.4e-10 answered 7.6e-7 away), a needle's coordinates eps * |ap| / (short
// edge) (a needle with a short edge of 1e-6 of its long ones answered 8.6e-9 away), so the face
// case is decided on the projection onto the plane instead.
constexpr double kSliver = 1e-3;

// ---------------------------------------------------------------------------------------------
// Arithmetic shared by the scalar function and the block (T = double or a SIMD vector). Every
// product that meets a sum goes through mulAdd, an explicit fused multiply-add where the machine
// has one: the compiler's own contraction would fuse the scalar and the vector code differently
// and their results would differ by a rounding of the point (eps * |coordinates|), which is far
// above 1e-12 of a small distance.

#if defined(__AVX512F__) || defined(__AVX2__)
// Plain GCC vector types (no may_alias attribute, so they can be template arguments); they
// convert to and from __m512d / __m256d freely.
typedef double Double8 __attribute__((vector_size(64)));
typedef double Double4 __attribute__((vector_size(32)));
#endif

inline double mulAdd(double a, double b, double c) {
#ifdef __FMA__
  return std::fma(a, b, c);
#else
  return a * b + c;
#endif
}

#if defined(__AVX512F__)
inline Double8 mulAdd(Double8 a, Double8 b, Double8 c) { return _mm512_fmadd_pd(a, b, c); }
#endif
#if defined(__AVX2__)
inline Double4 mulAdd(Double4 a, Double4 b, Double4 c) {
#ifdef __FMA__
  return _mm256_fmadd_pd(a, b, c);
#else
  return a * b + c;
#endif
}
#endif

// The rare triangles whose plane double precision cannot place (slivers and caps, and points
// at the edge of a needle) are answered in quadruple precision (113-bit significand), from
// the same double inputs: software arithmetic, about a hundred operations a triangle.
#if defined(__SIZEOF_FLOAT128__)
using Quad = __float128;
#else
using Quad = long double;  // IEEE quad where the ABI makes it so (AArch64 Linux); else less
#endif
inline Quad mulAdd(Quad a, Quad b, Quad c) { return a * b + c; }

template <class T>
struct V3 {
  T x, y, z;
};

template <class T>
inline V3<T> operator-(const V3<T>& a, const V3<T>& b) {
  return {a.x - b.x, a.y - b.y, a.z - b.z};
}

template <class T>
inline T dot(const V3<T>& a, const V3<T>& b) {
  return mulAdd(a.z, b.z, mulAdd(a.y, b.y, a.x * b.x));
}

template <class T>
inline V3<T> cross(const V3<T>& a, const V3<T>& b) {
  return {mulAdd(a.y, b.z, -(a.z * b.y)), mulAdd(a.z, b.x, -(a.x * b.z)),
          mulAdd(a.x, b.y, -(a.y * b.x))};
}

// o + v*e1 + w*e2, the one formula for every returned point that is not a corner.
template <class T>
inline V3<T> pointAt(const V3<T>& o, T v, const V3<T>& e1, T w, const V3<T>& e2) {
  return {mulAdd(w, e2.x, mulAdd(v, e1.x, o.x)), mulAdd(w, e2.y, mulAdd(v, e1.y, o.y)),
          mulAdd(w, e2.z, mulAdd(v, e1.z, o.z))};
}

template <class T>
inline T squaredDistance(const V3<T>& p, const V3<T>& q) {
  const V3<T> d = p - q;
  return dot(d, d);
}

// The triangle in its rotated labelling (corner a opposite the longest edge) and the dot
// products every step needs.
template <class T>
struct Frame {
  V3<T> a, b, c;      // rotated corners
  V3<T> ab, ac, bc;   // edges
  T lab, lac, lbc;    // squared edge lengths
  T dab;              // ab.ac
  T d1, d2, e;        // ab.ap, ac.ap, bc.bp
  T det;              // |ab x ac|^2
  V3<T> n;            // ab x ac
  T vb, vc, va;       // Gram numerators (meaningful when not degenerate)
};

// Fills everything but the corners and squared lengths, which the rotation selected.
template <class T>
inline void fillFrame(const V3<T>& p, Frame<T>& f) {
  f.ab = f.b - f.a;
  f.ac = f.c - f.a;
  f.bc = f.c - f.b;
  const V3<T> ap = p - f.a;
  const V3<T> bp = p - f.b;
  f.dab = dot(f.ab, f.ac);
  f.d1 = dot(f.ab, ap);
  f.d2 = dot(f.ac, ap);
  f.e = dot(f.bc, bp);
  f.n = cross(f.ab, f.ac);
  f.det = dot(f.n, f.n);
  f.vc = mulAdd(f.lab, f.d2, -(f.dab * f.d1));
  f.vb = mulAdd(f.lac, f.d1, -(f.dab * f.d2));
  f.va = f.det - f.vb - f.vc;
}

// Not safely a triangle: sin^2 of the largest angle <= kDegenerate (or NaN).
inline bool isDegenerate(double det, double lab, double lac) {
  return !(det > kDegenerate * (lab * lac));
}

// A sliver (when not degenerate): sin^2 of the largest angle below kSliver.
inline bool isSliver(double det, double lab, double lac) { return !(det > kSliver * (lab * lac)); }

// Thin (a sliver or a needle, when not degenerate): sin^2 of the smallest angle below kSliver.
// The smallest angle lies between the longest edge (bc) and the longer of ab, ac.
inline double thinScale(double lab, double lac, double lbc) { return lbc * (lab > lac ? lab : lac); }
inline bool isThin(double det, double lab, double lac, double lbc) {
  return !(det > kSliver * thinScale(lab, lac, lbc));
}

// The projection q of p onto the triangle's plane, q = p - (n.ap / n.n) n, and the edge
// functions of q: wa = n.(bc x bq), wb = n.(ca x cq), wc = n.(ab x aq), all >= 0 when q lies in
// the triangle (wa : wb : wc are its barycentric coordinates, as va : vb : vc are). Each is
// accurate to about eps / sin of the largest angle, where the Gram numerators lose eps / sin^2.
template <class T>
struct Projection {
  V3<T> q;
  T wa, wb, wc;
};
template <class T>
inline Projection<T> projectOnPlane(const V3<T>& p, const Frame<T>& f) {
  Projection<T> r;
  const T t = dot(f.n, p - f.a) / f.det;
  r.q = {mulAdd(-t, f.n.x, p.x), mulAdd(-t, f.n.y, p.y), mulAdd(-t, f.n.z, p.z)};
  r.wa = dot(f.n, cross(f.bc, r.q - f.b));
  r.wb = dot(f.n, cross(f.a - f.c, r.q - f.c));
  r.wc = dot(f.n, cross(f.ab, r.q - f.a));
  return r;
}

inline double clamp01(double x) { return x > 1.0 ? 1.0 : (x < 0.0 ? 0.0 : x); }

// sin^2 of the largest angle at or below which quadruple precision finds no plane either: the
// corners are collinear to its rounding, and the segments answer (off by at most half the
// height, sin / 2 of the length: 5e-18 of it at this threshold).
constexpr double kQuadDegenerate = 1e-34;

// A vector in another precision (exact from double to Quad; rounded back).
template <class T, class S>
inline V3<T> convert(const V3<S>& v) {
  return {static_cast<T>(v.x), static_cast<T>(v.y), static_cast<T>(v.z)};
}

// The projection of p onto the plane of the rotated triangle f, in quadruple precision from the
// same double corners: the normal's relative error is then about 1e-34 / sin of the largest
// angle instead of 1e-16 / sin.
struct QuadPlane {
  bool degenerate = true;  // sin^2 of the largest angle <= kQuadDegenerate: no plane
  bool inside = false;     // the projection lies in the closed triangle
  V3<double> q{};          // the projection, rounded
  V3<double> rebuilt{};    // a + v ab + w ac from its coordinates (inside), rounded
  double bary[3] = {};     // its coordinates in the rotated frame (inside)
};
inline QuadPlane quadProjection(const V3<double>& p, const Frame<double>& f) {
  QuadPlane r;
  Frame<Quad> g;
  g.a = convert<Quad>(f.a);
  g.b = convert<Quad>(f.b);
  g.c = convert<Quad>(f.c);
  const V3<Quad> ab = g.b - g.a, ac = g.c - g.a, bc = g.c - g.b;
  g.lab = dot(ab, ab);
  g.lac = dot(ac, ac);
  g.lbc = dot(bc, bc);
  const V3<Quad> pq = convert<Quad>(p);
  fillFrame(pq, g);
  r.degenerate = !(g.det > static_cast<Quad>(kQuadDegenerate) * (g.lab * g.lac));
  if (r.degenerate) return r;
  const Projection<Quad> pr = projectOnPlane(pq, g);
  r.q = convert<double>(pr.q);
  const Quad zero = 0;
  const Quad sum = pr.wa + pr.wb + pr.wc;
  r.inside = pr.wa >= zero && pr.wb >= zero && pr.wc >= zero && sum > zero;
  if (!r.inside) return r;
  const Quad v = pr.wb / sum, w = pr.wc / sum;
  r.rebuilt = convert<double>(pointAt(g.a, v, g.ab, w, g.ac));
  r.bary[0] = static_cast<double>(pr.wa / sum);
  r.bary[1] = static_cast<double>(v);
  r.bary[2] = static_cast<double>(w);
  return r;
}

// Whether the signs of a needle's double edge functions (its projection inside or outside) are
// certain: each |w| against a bound on its rounding, 256 eps |n| |edge| (|q - corner| + the
// largest coordinate). Near an edge's line (within about 1e-13 of the coordinates; a point
// beyond the tip lies near two) they are not, and the quadruple precision decides.
inline bool edgeSignsCertain(const V3<double>& p, const Frame<double>& f, const Projection<double>& pr) {
  const auto maxAbs = [](const V3<double>& v) { return std::max({std::abs(v.x), std::abs(v.y), std::abs(v.z)}); };
  const auto norm1 = [](const V3<double>& v) { return std::abs(v.x) + std::abs(v.y) + std::abs(v.z); };
  const double m = std::max({maxAbs(p), maxAbs(f.a), maxAbs(f.b), maxAbs(f.c)});
  constexpr double k = 256 * 2.220446049250313e-16;
  const auto certain = [&](double w, double edge2, const V3<double>& corner) {
    const double r = norm1(pr.q - corner) + m;
    return w * w > (k * k) * f.det * edge2 * (r * r);
  };
  return certain(pr.wa, f.lbc, f.b) && certain(pr.wb, f.lac, f.c) && certain(pr.wc, f.lab, f.a);
}

// ---------------------------------------------------------------------------------------------
// Scalar: branchy region logic in the rotated frame, mapped back to the caller's labelling.

// Local feature in the rotated frame: vertices 0..2 (a, b, c), edges 3 (ab), 4 (bc), 5 (ca),
// face 6, the same layout as Feature.
constexpr int kLocalEdgeAb = 3, kLocalEdgeBc = 4, kLocalEdgeCa = 5, kLocalFace = 6;

struct LocalResult {
  V3<double> point;
  double bary[3];  // rotated frame
  int feature;     // rotated frame
};

// The caller's labelling of a result in the rotated frame (local corner i is corner (i + r) % 3).
inline void unrotate(const LocalResult& res, int r, TriangleClosest& out) {
  out.point = Vec3(res.point.x, res.point.y, res.point.z);
  for (int i = 0; i < 3; ++i) out.barycentric[(i + r) % 3] = res.bary[i];
  if (res.feature < 3) {
    out.feature = static_cast<Feature>((res.feature + r) % 3);
  } else if (res.feature < kLocalFace) {
    out.feature = static_cast<Feature>(3 + (res.feature - 3 + r) % 3);
  } else {
    out.feature = Feature::kFace;
  }
}

// The rotated corners and squared edge lengths of a triangle (the rest of the frame is
// fillFrame's); r receives the rotation: local corner i is corner (i + r) % 3.
inline Frame<double> rotatedFrame(const Vec3& ae, const Vec3& be, const Vec3& ce, int& r) {
  const V3<double> corner[3] = {{ae.x(), ae.y(), ae.z()},
                                {be.x(), be.y(), be.z()},
                                {ce.x(), ce.y(), ce.z()}};
  // Squared edge lengths: l[k] is the edge from corner k to corner k+1, opposite corner k+2.
  const V3<double> e0 = corner[1] - corner[0];
  const V3<double> e1 = corner[2] - corner[1];
  const V3<double> e2 = corner[0] - corner[2];
  const double l[3] = {dot(e0, e0), dot(e1, e1), dot(e2, e2)};
  // a is opposite the longest edge.
  r = (l[1] >= l[2] && l[1] >= l[0]) ? 0 : (l[2] >= l[0] ? 1 : 2);
  Frame<double> f;
  f.a = corner[r];
  f.b = corner[(r + 1) % 3];
  f.c = corner[(r + 2) % 3];
  f.lab = l[r];
  f.lbc = l[(r + 1) % 3];
  f.lac = l[(r + 2) % 3];
  return f;
}

template <bool kDetails>
inline double closestImpl(const Vec3& pe, const Vec3& ae, const Vec3& be, const Vec3& ce,
                          TriangleClosest* out) {
  // Every corner the same point (a mesh collapsed to one): that point, as the segments below
  // answer it, without the sliver path's quadruple precision (found by review: 50 times a
  // triangle's cost, every face of such a mesh tested since they all tie).
  if (ae == be && be == ce && ae.allFinite()) {
    const double d2 = squaredDistance(V3<double>{pe.x(), pe.y(), pe.z()}, V3<double>{ae.x(), ae.y(), ae.z()});
    if (kDetails) {
      out->squared_distance = d2;
      out->point = ae;
      out->barycentric = Vec3(1, 0, 0);
      out->feature = Feature::kVertex0;
    }
    return d2;
  }
  const V3<double> p{pe.x(), pe.y(), pe.z()};
  int r = 0;
  Frame<double> f = rotatedFrame(ae, be, ce, r);
  fillFrame(p, f);

  LocalResult res{};
  auto vertex = [&](int i, const V3<double>& q) {
    res.point = q;
    res.bary[0] = res.bary[1] = res.bary[2] = 0.0;
    res.bary[i] = 1.0;
    res.feature = i;
  };
  // Edge from local corner i to local corner j at parameter t (already in [0, 1]).
  auto edge = [&](int feature, int i, int j, double t, const V3<double>& q) {
    res.point = q;
    res.bary[0] = res.bary[1] = res.bary[2] = 0.0;
    res.bary[i] = 1.0 - t;
    res.bary[j] = t;
    res.feature = feature;
  };

  // Corners or point not finite (overflowed terms included): the segments answer.
  const bool finite = std::isfinite(f.det) && std::isfinite(f.lab) && std::isfinite(f.lac) && std::isfinite(f.lbc) &&
                      std::isfinite(f.d1) && std::isfinite(f.d2) && std::isfinite(f.e) && std::isfinite(f.dab);
  // A sliver or cap (largest angle near 180 degrees, down to collinear in doubles): its plane
  // from quadruple precision. A needle (smallest angle small, largest not near 180): its plane
  // from doubles, with quadruple precision where an edge function's sign is in doubt.
  const bool sliver = finite && isSliver(f.det, f.lab, f.lac);
  const bool needle = finite && !sliver && isThin(f.det, f.lab, f.lac, f.lbc);
  const bool thin = sliver || needle;
  QuadPlane quad;
  bool quad_done = false;
  bool thin_face = false;
  V3<double> face_point{};
  Projection<double> proj{};  // a needle's, in doubles
  if (sliver) {
    quad = quadProjection(p, f);
    quad_done = true;
    thin_face = !quad.degenerate && quad.inside;
    face_point = quad.rebuilt;
  } else if (needle) {
    proj = projectOnPlane(p, f);
    if (edgeSignsCertain(p, f, proj)) {
      thin_face = proj.wa >= 0.0 && proj.wb >= 0.0 && proj.wc >= 0.0;
      face_point = proj.q;
    } else {
      quad = quadProjection(p, f);
      quad_done = true;
      thin_face = !quad.degenerate && quad.inside;
      face_point = quad.q;
    }
  }
  // In quadruple precision a projection on an edge's line has that edge function exactly 0:
  // on two of them it is the corner (returned exactly), on one an edge.
  int thin_feature = kLocalFace;
  if (thin_face && quad_done) {
    const bool zero[3] = {quad.bary[0] == 0.0, quad.bary[1] == 0.0, quad.bary[2] == 0.0};
    const int zeros = zero[0] + zero[1] + zero[2];
    if (zeros == 2) {
      thin_feature = !zero[0] ? 0 : (!zero[1] ? 1 : 2);
      face_point = thin_feature == 0 ? f.a : (thin_feature == 1 ? f.b : f.c);
    } else if (zeros == 1) {
      thin_feature = zero[0] ? kLocalEdgeBc : (zero[1] ? kLocalEdgeCa : kLocalEdgeAb);
    }
  }
  if (thin_face) {
    // The projection lies in the thin triangle: a needle's as computed (its normal is
    // accurate), a sliver's rebuilt from its coordinates (its plane's normal is not: the point
    // stays on the triangle). Coordinates from the quadruple-precision edge functions (a
    // needle's Gram numerators cancel; its double edge functions lose eps over its short edge).
    res.point = face_point;
    if (kDetails) {
      if (!quad_done) quad = quadProjection(p, f);
      for (int i = 0; i < 3; ++i) res.bary[i] = quad.bary[i];
      if (!quad.inside) {  // a needle certain in doubles but on an edge in quad: its point's edge
        const double wa = std::max(proj.wa, 0.0), wb = std::max(proj.wb, 0.0), wc = std::max(proj.wc, 0.0);
        const double sum = wa + wb + wc;
        res.bary[0] = sum > 0 ? wa / sum : 1.0;
        res.bary[1] = sum > 0 ? wb / sum : 0.0;
        res.bary[2] = sum > 0 ? wc / sum : 0.0;
      }
      res.feature = thin_feature;
    }
  } else if (!finite || thin) {
    // Closest of the segments ab, bc, ac (first wins ties); a segment end is returned exactly.
    // For a sliver whose plane projection of p falls outside it, the closest point is on its
    // boundary.
    struct Segment {
      const V3<double>* o;
      const V3<double>* end;
      const V3<double>* dir;
      double num, len;
      int feature, i, j;
    };
    const Segment segments[3] = {{&f.a, &f.b, &f.ab, f.d1, f.lab, kLocalEdgeAb, 0, 1},
                                 {&f.b, &f.c, &f.bc, f.e, f.lbc, kLocalEdgeBc, 1, 2},
                                 {&f.a, &f.c, &f.ac, f.d2, f.lac, kLocalEdgeCa, 0, 2}};
    double best = 0.0;
    for (int s = 0; s < 3; ++s) {
      const Segment& g = segments[s];
      const double t = g.len > 0.0 ? clamp01(g.num / g.len) : 0.0;
      const V3<double> q =
          t == 0.0 ? *g.o : (t == 1.0 ? *g.end : pointAt(*g.o, t, *g.dir, 0.0, f.ac));
      const double d = squaredDistance(p, q);
      if (s == 0 || d < best) {
        best = d;
        if (kDetails) {
          if (t == 0.0) {
            vertex(g.i, q);
          } else if (t == 1.0) {
            vertex(g.j, q);
          } else {
            edge(g.feature, g.i, g.j, t, q);
          }
        }
      }
    }
    if (!kDetails) return best;
  } else if (f.d1 <= 0.0 && f.d2 <= 0.0) {
    vertex(0, f.a);
  } else if (f.d1 >= f.lab && f.e <= 0.0) {
    vertex(1, f.b);
  } else if (f.vc <= 0.0 && f.d1 >= 0.0 && f.d1 <= f.lab) {
    const double t = f.d1 / f.lab;
    edge(kLocalEdgeAb, 0, 1, t, pointAt(f.a, t, f.ab, 0.0, f.ac));
  } else if (f.d2 >= f.lac && f.e >= f.lbc) {
    vertex(2, f.c);
  } else if (f.vb <= 0.0 && f.d2 >= 0.0 && f.d2 <= f.lac) {
    const double t = f.d2 / f.lac;
    edge(kLocalEdgeCa, 0, 2, t, pointAt(f.a, 0.0, f.ab, t, f.ac));
  } else if (f.va <= 0.0 && f.e >= 0.0 && f.e <= f.lbc) {
    const double t = f.e / f.lbc;
    edge(kLocalEdgeBc, 1, 2, t, pointAt(f.b, t, f.bc, 0.0, f.ac));
  } else {
    const double va = f.va > 0.0 ? f.va : 0.0;
    const double vb = f.vb > 0.0 ? f.vb : 0.0;
    const double vc = f.vc > 0.0 ? f.vc : 0.0;
    const double s = va + vb + vc;  // > 0: det > 0 here
    const double v = vb / s;
    const double w = vc / s;
    res.point = pointAt(f.a, v, f.ab, w, f.ac);
    if (kDetails) {
      res.bary[0] = va / s;
      res.bary[1] = v;
      res.bary[2] = w;
      res.feature = kLocalFace;
    }
  }

  const double squared = squaredDistance(p, res.point);
  if (kDetails) {
    out->squared_distance = squared;
    unrotate(res, r, *out);
  }
  return squared;
}

// ---------------------------------------------------------------------------------------------
// Block: the same formulas on kWidth lanes at a time, every case computed, selected by masks.
// Ops provides V (lanes of double), M (lane mask), load/store/set1, comparisons, select and mask
// logic; arithmetic uses the vector operators.

struct ScalarOps {
  using V = double;
  using M = bool;
  static constexpr int kWidth = 1;
  static V load(const double* x) { return *x; }
  static V loadu(const double* x) { return *x; }
  static void store(double* x, V v) { *x = v; }
  static V set1(double x) { return x; }
  static M le(V a, V b) { return a <= b; }
  static M ge(V a, V b) { return a >= b; }
  static M gt(V a, V b) { return a > b; }
  static M lt(V a, V b) { return a < b; }
  static M andM(M a, M b) { return a && b; }
  static M orM(M a, M b) { return a || b; }
  static M andNot(M a, M b) { return a && !b; }  // a and not b
  static M notM(M a) { return !a; }
  static bool any(M a) { return a; }
  static V select(M m, V a, V b) { return m ? a : b; }
};

#if defined(__AVX512F__)
struct Avx512Ops {
  using V = Double8;
  using M = __mmask8;
  static constexpr int kWidth = 8;
  static V load(const double* x) { return _mm512_load_pd(x); }
  static V loadu(const double* x) { return _mm512_loadu_pd(x); }
  static void store(double* x, V v) { _mm512_storeu_pd(x, v); }
  static V set1(double x) { return _mm512_set1_pd(x); }
  static M le(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_LE_OQ); }
  static M ge(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_GE_OQ); }
  static M gt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm512_cmp_pd_mask(a, b, _CMP_LT_OQ); }
  static M andM(M a, M b) { return static_cast<M>(a & b); }
  static M orM(M a, M b) { return static_cast<M>(a | b); }
  static M andNot(M a, M b) { return static_cast<M>(a & ~b); }
  static M notM(M a) { return static_cast<M>(~a); }
  static bool any(M a) { return a != 0; }
  static V select(M m, V a, V b) { return _mm512_mask_blend_pd(m, b, a); }
};
using BlockOps = Avx512Ops;
#elif defined(__AVX2__)
struct Avx2Ops {
  using V = Double4;
  using M = Double4;
  static constexpr int kWidth = 4;
  static V load(const double* x) { return _mm256_load_pd(x); }
  static V loadu(const double* x) { return _mm256_loadu_pd(x); }
  static void store(double* x, V v) { _mm256_storeu_pd(x, v); }
  static V set1(double x) { return _mm256_set1_pd(x); }
  static M le(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LE_OQ); }
  static M ge(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GE_OQ); }
  static M gt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_GT_OQ); }
  static M lt(V a, V b) { return _mm256_cmp_pd(a, b, _CMP_LT_OQ); }
  static M andM(M a, M b) { return _mm256_and_pd(a, b); }
  static M orM(M a, M b) { return _mm256_or_pd(a, b); }
  static M andNot(M a, M b) { return _mm256_andnot_pd(b, a); }
  static M notM(M a) { return _mm256_xor_pd(a, _mm256_castsi256_pd(_mm256_set1_epi64x(-1))); }
  static bool any(M a) { return _mm256_movemask_pd(a) != 0; }
  static V select(M m, V a, V b) { return _mm256_blendv_pd(b, a, m); }
};
using BlockOps = Avx2Ops;
#else
using BlockOps = ScalarOps;
#endif

template <class Ops>
inline V3<typename Ops::V> loadCorner(const TriangleBlock8& block, int corner, int lane) {
  return {Ops::load(&block.v[corner][0][lane]), Ops::load(&block.v[corner][1][lane]),
          Ops::load(&block.v[corner][2][lane])};
}

template <class Ops>
inline V3<typename Ops::V> select3(typename Ops::M m, const V3<typename Ops::V>& a,
                                   const V3<typename Ops::V>& b) {
  return {Ops::select(m, a.x, b.x), Ops::select(m, a.y, b.y), Ops::select(m, a.z, b.z)};
}

template <class Ops, bool kDetails = false>
inline void blockLanes(const Vec3& ps, const V3<typename Ops::V>& p, const TriangleBlock8& block, int lane,
                       double* out, BlockClosest8* details = nullptr) {
  using V = typename Ops::V;
  using M = typename Ops::M;
  const V zero = Ops::set1(0.0), one = Ops::set1(1.0);
  const V3<V> corner0 = loadCorner<Ops>(block, 0, lane);
  const V3<V> corner1 = loadCorner<Ops>(block, 1, lane);
  const V3<V> corner2 = loadCorner<Ops>(block, 2, lane);
  const V3<V> e0 = corner1 - corner0;
  const V3<V> e1 = corner2 - corner1;
  const V3<V> e2 = corner0 - corner2;
  const V l0 = dot(e0, e0), l1 = dot(e1, e1), l2 = dot(e2, e2);
  // Rotation: r0 (a = corner0), r1 (a = corner1), else r2 (a = corner2).
  const M r0 = Ops::andM(Ops::ge(l1, l2), Ops::ge(l1, l0));
  const M r1 = Ops::andNot(Ops::ge(l2, l0), r0);
  Frame<V> f;
  f.a = select3<Ops>(r0, corner0, select3<Ops>(r1, corner1, corner2));
  f.b = select3<Ops>(r0, corner1, select3<Ops>(r1, corner2, corner0));
  f.c = select3<Ops>(r0, corner2, select3<Ops>(r1, corner0, corner1));
  f.lab = Ops::select(r0, l0, Ops::select(r1, l1, l2));
  f.lbc = Ops::select(r0, l1, Ops::select(r1, l2, l0));
  f.lac = Ops::select(r0, l2, Ops::select(r1, l0, l1));
  fillFrame(p, f);

  // Region tests in Ericson's order; each final mask excludes the earlier ones.
  const M c_a = Ops::andM(Ops::le(f.d1, zero), Ops::le(f.d2, zero));
  const M c_b = Ops::andM(Ops::ge(f.d1, f.lab), Ops::le(f.e, zero));
  const M c_ab = Ops::andM(Ops::le(f.vc, zero),
                           Ops::andM(Ops::ge(f.d1, zero), Ops::le(f.d1, f.lab)));
  const M c_c = Ops::andM(Ops::ge(f.d2, f.lac), Ops::ge(f.e, f.lbc));
  const M c_ac = Ops::andM(Ops::le(f.vb, zero),
                           Ops::andM(Ops::ge(f.d2, zero), Ops::le(f.d2, f.lac)));
  const M c_bc = Ops::andM(Ops::le(f.va, zero),
                           Ops::andM(Ops::ge(f.e, zero), Ops::le(f.e, f.lbc)));
  M done = c_a;
  const M is_b = Ops::andNot(c_b, done);
  done = Ops::orM(done, c_b);
  const M is_ab = Ops::andNot(c_ab, done);
  done = Ops::orM(done, c_ab);
  const M is_c = Ops::andNot(c_c, done);
  done = Ops::orM(done, c_c);
  const M is_ac = Ops::andNot(c_ac, done);
  done = Ops::orM(done, c_ac);
  const M is_bc = Ops::andNot(c_bc, done);
  done = Ops::orM(done, c_bc);
  const M is_face = Ops::notM(done);

  // Face weights, then one numerator pair and one denominator per lane: v = nv / den,
  // w = nw / den (vertices: 0 / 1).
  const V va = Ops::select(Ops::gt(f.va, zero), f.va, zero);
  const V vb = Ops::select(Ops::gt(f.vb, zero), f.vb, zero);
  const V vc = Ops::select(Ops::gt(f.vc, zero), f.vc, zero);
  const V s = va + vb + vc;
  V nv = Ops::select(is_face, vb, zero);
  nv = Ops::select(is_ab, f.d1, nv);
  nv = Ops::select(is_bc, f.e, nv);
  V nw = Ops::select(is_face, vc, zero);
  nw = Ops::select(is_ac, f.d2, nw);
  V den = Ops::select(is_face, s, one);
  den = Ops::select(is_ab, f.lab, den);
  den = Ops::select(is_ac, f.lac, den);
  den = Ops::select(is_bc, f.lbc, den);
  const V v = nv / den;
  const V w = nw / den;
  const V3<V> o = select3<Ops>(Ops::orM(is_b, is_bc), f.b, select3<Ops>(is_c, f.c, f.a));
  const V3<V> e1v = select3<Ops>(is_bc, f.bc, f.ab);
  const V3<V> point = pointAt(o, v, e1v, w, f.ac);
  V squared = squaredDistance(p, point);
  if (kDetails) {
    // closestImpl's point (a vertex exactly) and coordinates, in the rotated frame.
    const M is_a = c_a;
    const V3<V> q = select3<Ops>(is_a, f.a, select3<Ops>(is_b, f.b, select3<Ops>(is_c, f.c, point)));
    Ops::store(&details->point[0][lane], q.x);
    Ops::store(&details->point[1][lane], q.y);
    Ops::store(&details->point[2][lane], q.z);
    const V b0 = Ops::select(is_face, va / s,
                             Ops::select(is_ab, one - v, Ops::select(is_ac, one - w, Ops::select(is_a, one, zero))));
    const V b1 = Ops::select(Ops::orM(is_face, is_ab), v, Ops::select(is_bc, one - v, Ops::select(is_b, one, zero)));
    const V b2 = Ops::select(Ops::orM(is_face, is_ac), w, Ops::select(is_bc, v, Ops::select(is_c, one, zero)));
    Ops::store(&details->bary[0][lane], b0);
    Ops::store(&details->bary[1][lane], b1);
    Ops::store(&details->bary[2][lane], b2);
    V code = Ops::set1(kLocalFace);
    code = Ops::select(is_a, Ops::set1(0), code);
    code = Ops::select(is_b, Ops::set1(1), code);
    code = Ops::select(is_c, Ops::set1(2), code);
    code = Ops::select(is_ab, Ops::set1(kLocalEdgeAb), code);
    code = Ops::select(is_bc, Ops::set1(kLocalEdgeBc), code);
    code = Ops::select(is_ac, Ops::set1(kLocalEdgeCa), code);
    Ops::store(&details->feature[lane], code);
    Ops::store(&details->rotation[lane], Ops::select(r0, zero, Ops::select(r1, one, Ops::set1(2))));
  }

  // Thin lanes (slivers, needles and degenerate ones; NaN too) are rare: one test for all, and
  // those lanes take the scalar function (quadruple precision where it needs it).
  const V thin_scale = f.lbc * Ops::select(Ops::gt(f.lab, f.lac), f.lab, f.lac);
  const M thin = Ops::notM(Ops::gt(f.det, Ops::set1(kSliver) * thin_scale));
  if (kDetails) Ops::store(&details->thin[lane], Ops::select(thin, one, zero));
  if (Ops::any(thin)) {
    double flags[Ops::kWidth], values[Ops::kWidth];
    Ops::store(flags, Ops::select(thin, one, zero));
    Ops::store(values, squared);
    for (int k = 0; k < Ops::kWidth; ++k) {
      if (flags[k] == 0.0) continue;
      const int l = lane + k;
      values[k] = closestImpl<false>(ps, Vec3(block.v[0][0][l], block.v[0][1][l], block.v[0][2][l]),
                                     Vec3(block.v[1][0][l], block.v[1][1][l], block.v[1][2][l]),
                                     Vec3(block.v[2][0][l], block.v[2][1][l], block.v[2][2][l]), nullptr);
    }
    squared = Ops::loadu(values);
  }
  Ops::store(out + lane, squared);
}

}  // namespace

TriangleClosest closestPointOnTriangle(const Vec3& p, const Vec3& a, const Vec3& b,
                                       const Vec3& c) {
  TriangleClosest result;
  closestImpl<true>(p, a, b, c, &result);
  return result;
}

double squaredDistanceToTriangle(const Vec3& p, const Vec3& a, const Vec3& b, const Vec3& c) {
  return closestImpl<false>(p, a, b, c, nullptr);
}

bool isDegenerateTriangle(const Vec3& ae, const Vec3& be, const Vec3& ce) {
  int r = 0;
  const Frame<double> f = rotatedFrame(ae, be, ce, r);  // closestImpl's frame and test
  const V3<double> n = cross(f.b - f.a, f.c - f.a);
  return isDegenerate(dot(n, n), f.lab, f.lac);
}

void squaredDistancesToBlock(const Vec3& p, const TriangleBlock8& block, double out[8]) {
  using V = BlockOps::V;
  const V3<V> pv{BlockOps::set1(p.x()), BlockOps::set1(p.y()), BlockOps::set1(p.z())};
  for (int lane = 0; lane < 8; lane += BlockOps::kWidth) blockLanes<BlockOps>(p, pv, block, lane, out);
}

void closestPointsInBlock(const Vec3& p, const TriangleBlock8& block, double out[8], BlockClosest8& details) {
  using V = BlockOps::V;
  const V3<V> pv{BlockOps::set1(p.x()), BlockOps::set1(p.y()), BlockOps::set1(p.z())};
  for (int lane = 0; lane < 8; lane += BlockOps::kWidth) blockLanes<BlockOps, true>(p, pv, block, lane, out, &details);
}

TriangleClosest blockLaneClosest(const Vec3& p, const TriangleBlock8& block, const BlockClosest8& details, int lane) {
  const auto corner = [&](int k) { return Vec3(block.v[k][0][lane], block.v[k][1][lane], block.v[k][2][lane]); };
  if (details.thin[lane] != 0.0) return closestPointOnTriangle(p, corner(0), corner(1), corner(2));
  LocalResult res;
  res.point = {details.point[0][lane], details.point[1][lane], details.point[2][lane]};
  for (int i = 0; i < 3; ++i) res.bary[i] = details.bary[i][lane];
  res.feature = static_cast<int>(details.feature[lane]);
  TriangleClosest out;
  out.squared_distance = squaredDistance(V3<double>{p.x(), p.y(), p.z()}, res.point);
  unrotate(res, static_cast<int>(details.rotation[lane]), out);
  return out;
}

}  // namespace meshsweeper
