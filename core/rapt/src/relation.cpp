#include "cell/rapt/relation.hpp"

#include <fmt/format.h>

#include <Eigen/SVD>
#include <algorithm>
#include <cmath>

namespace cell::rapt {

const char* to_string(RelType t) noexcept {
  switch (t) {
    case RelType::kAgpp:
      return "AGPP";
    case RelType::kFits:
      return "FITS";
    case RelType::kAgpc:
      return "AGPC";
    case RelType::kAgps:
      return "AGPS";
    case RelType::kAgss:
      return "AGSS";
    case RelType::kParax:
      return "PARAX";
    case RelType::kLin:
      return "LIN";
    case RelType::kLinlin:
      return "LINLIN";
    case RelType::kRot:
      return "ROT";
    case RelType::kFix:
      return "FIX";
  }
  return "?";
}

Dof dof(RelType t) noexcept {
  switch (t) {
    case RelType::kAgpp:
      return {2, 1};
    case RelType::kFits:
      return {1, 1};
    case RelType::kAgpc:
      return {2, 2};
    case RelType::kAgps:
      return {2, 3};
    case RelType::kAgss:
      return {0, 3};
    case RelType::kParax:
      return {3, 1};
    case RelType::kLin:
      return {1, 0};
    case RelType::kLinlin:
      return {2, 0};
    case RelType::kRot:
      return {0, 1};
    case RelType::kFix:
      return {0, 0};
  }
  return {};
}

Relation reversed(const Relation& r) {
  Relation out = r;
  std::swap(out.a, out.b);
  std::swap(out.a_T_fa, out.b_T_fb);
  if (r.type == RelType::kAgpc || r.type == RelType::kAgps) {
    out.plane_on_b = !r.plane_on_b;
  }
  return out;
}

Pose fixed_pose(const Relation& r) { return r.a_T_fa * r.b_T_fb.inverse(); }

namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;

/// True for the seven types whose S_r is Trans(V) Rx(Theta) [M] (a coset of a subgroup).
bool group_type(RelType t) {
  return t != RelType::kAgpc && t != RelType::kAgps && t != RelType::kAgss;
}
/// Types whose S_r ends with the flip M.
bool flipped(RelType t) {
  return t == RelType::kFits || t == RelType::kAgpp || t == RelType::kParax;
}
bool rotates(RelType t) {
  return t == RelType::kRot || t == RelType::kFits || t == RelType::kAgpp || t == RelType::kParax;
}

// --- primitive constraints on X = a_T_b = (R, t) ----------------------------------------------

struct RotC {
  enum Kind : std::uint8_t { kFull, kDirEq, kDirPerp } kind;
  Matrix3d full = Matrix3d::Identity();  ///< kFull: R
  Vector3d v = Vector3d::Zero();         ///< a direction of B
  Vector3d w = Vector3d::Zero();         ///< a direction of A: kDirEq R v = w; kDirPerp (Rv).w = 0
};

struct PtC {
  enum Kind : std::uint8_t { kEq, kOnLine, kOnPlane, kOnPlaneB, kOnSphere } kind;
  Vector3d p = Vector3d::Zero();  ///< point of B (kOnPlaneB: point of A)
  Vector3d c = Vector3d::Zero();  ///< point of A (kOnPlaneB: point of B's plane)
  Vector3d n = Vector3d::Zero();  ///< line direction / plane normal (kOnPlaneB: in B)
  double r = 0.0;                 ///< kOnSphere radius
};

struct Prims {
  std::vector<RotC> rot;
  std::vector<PtC> pts;
};

void add_primitives(const Relation& r, Prims& out) {
  const Matrix3d ra = r.a_T_fa.linear();
  const Matrix3d rb = r.b_T_fb.linear();
  const Vector3d ua = ra.col(0);
  const Vector3d vb = rb.col(0);
  const Vector3d oa = r.a_T_fa.translation();
  const Vector3d ob = r.b_T_fb.translation();
  switch (r.type) {
    case RelType::kFix:
      out.rot.push_back({RotC::kFull, ra * rb.transpose()});
      out.pts.push_back({PtC::kEq, ob, oa});
      break;
    case RelType::kLin:
      out.rot.push_back({RotC::kFull, ra * rb.transpose()});
      out.pts.push_back({PtC::kOnLine, ob, oa, ua});
      break;
    case RelType::kLinlin:
      out.rot.push_back({RotC::kFull, ra * rb.transpose()});
      out.pts.push_back({PtC::kOnPlane, ob, oa, ua});
      break;
    case RelType::kRot:
      out.rot.push_back({RotC::kDirEq, Matrix3d::Identity(), vb, ua});
      out.pts.push_back({PtC::kEq, ob, oa});
      break;
    case RelType::kFits:
      out.rot.push_back({RotC::kDirEq, Matrix3d::Identity(), vb, -ua});
      out.pts.push_back({PtC::kOnLine, ob, oa, ua});
      break;
    case RelType::kAgpp:
      out.rot.push_back({RotC::kDirEq, Matrix3d::Identity(), vb, -ua});
      out.pts.push_back({PtC::kOnPlane, ob, oa, ua});
      break;
    case RelType::kParax:
      out.rot.push_back({RotC::kDirEq, Matrix3d::Identity(), vb, -ua});
      break;
    case RelType::kAgpc:
      // The cylinder's axis is perpendicular to the plane normal, and its origin lies on the
      // plane moved out along the normal by the radius.
      out.rot.push_back({RotC::kDirPerp, Matrix3d::Identity(), vb, ua});
      if (!r.plane_on_b) {
        out.pts.push_back({PtC::kOnPlane, ob, oa + r.offset * ua, ua});
      } else {
        out.pts.push_back({PtC::kOnPlaneB, oa, ob + r.offset * vb, vb});
      }
      break;
    case RelType::kAgps:
      if (!r.plane_on_b) {
        out.pts.push_back({PtC::kOnPlane, ob, oa + r.offset * ua, ua});
      } else {
        out.pts.push_back({PtC::kOnPlaneB, oa, ob + r.offset * vb, vb});
      }
      break;
    case RelType::kAgss:
      out.pts.push_back({PtC::kOnSphere, ob, oa, Vector3d::Zero(), r.offset});
      break;
  }
}

// --- result construction -----------------------------------------------------------------------

Relation make_relation(RelType type, const Relation& like, const Pose& x_star, const Pose& fa) {
  Relation out;
  out.type = type;
  out.a = like.a;
  out.b = like.b;
  out.a_T_fa = fa;
  out.b_T_fb = flipped(type) ? Pose(x_star.inverse() * fa * flip_x()) : Pose(x_star.inverse() * fa);
  return out;
}

SolveResult ok(Relation r) {
  SolveResult s;
  s.outcome = Outcome::kOk;
  s.relation = std::move(r);
  return s;
}

SolveResult fail(Outcome o, std::string detail, double mm = 0.0, double rad = 0.0) {
  SolveResult s;
  s.outcome = o;
  s.detail = std::move(detail);
  s.residual_mm = mm;
  s.residual_rad = rad;
  return s;
}

double angle_between_dirs(const Vector3d& a, const Vector3d& b) {
  return std::atan2(a.cross(b).norm(), a.dot(b));
}

// --- translation with a fixed rotation -------------------------------------------------------

/// Solves the point constraints for t given R; classifies the solution set.
SolveResult solve_translation(const Matrix3d& r,
                              const Prims& prims,
                              const Relation& like,
                              const Tolerances& tol) {
  std::vector<Vector3d> rows;
  std::vector<double> rhs;
  auto add_row = [&](const Vector3d& n, double value) {
    rows.push_back(n);
    rhs.push_back(value);
  };
  bool sphere = false;
  for (const PtC& c : prims.pts) {
    switch (c.kind) {
      case PtC::kEq: {
        const Vector3d target = c.c - r * c.p;
        for (int i = 0; i < 3; ++i) {
          add_row(Vector3d::Unit(i), target[i]);
        }
        break;
      }
      case PtC::kOnLine: {
        const Vector3d e1 = any_perpendicular(c.n);
        const Vector3d e2 = c.n.cross(e1);
        const Vector3d target = c.c - r * c.p;
        add_row(e1, e1.dot(target));
        add_row(e2, e2.dot(target));
        break;
      }
      case PtC::kOnPlane:
        add_row(c.n, c.n.dot(c.c - r * c.p));
        break;
      case PtC::kOnPlaneB: {
        const Vector3d m = r * c.n;
        add_row(m, m.dot(c.p - r * c.c));
        break;
      }
      case PtC::kOnSphere:
        sphere = true;
        break;
    }
  }
  Vector3d t0 = Vector3d::Zero();
  int rank = 0;
  Matrix3d v = Matrix3d::Identity();
  if (!rows.empty()) {
    Eigen::MatrixXd a(static_cast<Eigen::Index>(rows.size()), 3);
    Eigen::VectorXd b(static_cast<Eigen::Index>(rows.size()));
    for (std::size_t i = 0; i < rows.size(); ++i) {
      a.row(static_cast<Eigen::Index>(i)) = rows[i].transpose();
      b[static_cast<Eigen::Index>(i)] = rhs[i];
    }
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(a, Eigen::ComputeThinU | Eigen::ComputeFullV);
    const Eigen::VectorXd& sv = svd.singularValues();
    for (Eigen::Index i = 0; i < sv.size(); ++i) {
      if (sv[i] > 1e-6) {
        ++rank;
      }
    }
    v = svd.matrixV();
    for (int i = 0; i < rank; ++i) {
      t0 += v.col(i) * (svd.matrixU().col(i).dot(b) / sv[i]);
    }
    const double res = (a * t0 - b).cwiseAbs().maxCoeff();
    if (res > tol.linear_mm) {
      return fail(Outcome::kIncompatible, fmt::format("the positions disagree by {:.4g} mm", res),
                  res, 0.0);
    }
  }
  Pose x = Pose::Identity();
  x.linear() = r;
  x.translation() = t0;
  if (sphere) {
    for (const PtC& c : prims.pts) {
      if (c.kind != PtC::kOnSphere) {
        continue;
      }
      const Vector3d q = r * c.p + x.translation() - c.c;
      if (rank == 3) {
        const double res = std::abs(q.norm() - c.r);
        if (res > tol.linear_mm) {
          return fail(Outcome::kIncompatible,
                      fmt::format("the sphere centres are {:.4g} mm off their distance", res), res);
        }
        continue;
      }
      if (rank == 2) {
        const Vector3d d = v.col(2);
        const double bq = q.dot(d);
        const double disc = bq * bq - (q.squaredNorm() - c.r * c.r);
        if (disc < -tol.linear_mm * std::max(1.0, c.r)) {
          return fail(Outcome::kIncompatible, "the sphere distance cannot be reached");
        }
        if (disc > tol.linear_mm * tol.linear_mm) {
          return fail(Outcome::kTwoSolutions, "two positions satisfy the sphere distance");
        }
        x.translation() += -bq * d;
        rank = 3;
        continue;
      }
      return fail(Outcome::kInexpressible,
                  "a sphere distance with less than two fixed "
                  "translations is not one of the ten types");
    }
  }
  switch (rank) {
    case 3:
      return ok(make_relation(RelType::kFix, like, x, x));
    case 2:
      return ok(make_relation(RelType::kLin, like, x, frame_from_x(t0, v.col(2))));
    case 1:
      return ok(make_relation(RelType::kLinlin, like, x, frame_from_x(t0, v.col(0))));
    default:
      return fail(Outcome::kInexpressible,
                  "a fixed orientation with a free translation is not one of the ten types");
  }
}

// --- rotation ------------------------------------------------------------------------------

/// Angular residual of a rotation against every rotation constraint.
double rotation_residual(const Matrix3d& r, const std::vector<RotC>& rot) {
  double worst = 0.0;
  for (const RotC& c : rot) {
    switch (c.kind) {
      case RotC::kFull:
        worst = std::max(worst, rotation_angle(c.full, r));
        break;
      case RotC::kDirEq:
        worst = std::max(worst, angle_between_dirs(r * c.v, c.w));
        break;
      case RotC::kDirPerp:
        worst = std::max(worst, std::abs(std::asin(std::clamp((r * c.v).dot(c.w), -1.0, 1.0))));
        break;
    }
  }
  return worst;
}

/// Solves A cos(th) + B sin(th) + C = 0; returns 0, 1 or 2 angles.
std::vector<double> solve_trig(double a, double b, double c, double tol) {
  const double h = std::hypot(a, b);
  if (h < 1e-12) {
    return {};
  }
  const double ratio = -c / h;
  if (ratio > 1.0 + tol || ratio < -1.0 - tol) {
    return {};
  }
  const double base = std::atan2(b, a);
  const double delta = std::acos(std::clamp(ratio, -1.0, 1.0));
  if (delta < tol) {
    return {base};
  }
  return {base + delta, base - delta};
}

SolveResult solve_family(const Vector3d& v,
                         const Vector3d& w,
                         const Prims& prims,
                         const Relation& like,
                         const Tolerances& tol);

SolveResult solve(const Prims& prims, const Relation& like, const Tolerances& tol) {
  const RotC* full = nullptr;
  std::vector<const RotC*> eqs;
  for (const RotC& c : prims.rot) {
    if (c.kind == RotC::kFull && full == nullptr) {
      full = &c;
    } else if (c.kind == RotC::kDirEq) {
      eqs.push_back(&c);
    }
  }
  Matrix3d r;
  if (full != nullptr) {
    r = full->full;
  } else if (!eqs.empty()) {
    const RotC* second = nullptr;
    for (const RotC* c : eqs) {
      if (!parallel(c->v, eqs.front()->v, 1e-6)) {
        second = c;
        break;
      }
    }
    if (second == nullptr) {
      // Every axis constraint is about one direction: check their signs agree, then the
      // rotation about that direction is still free.
      for (const RotC* c : eqs) {
        const double sv = c->v.dot(eqs.front()->v) > 0 ? 1.0 : -1.0;
        const double res = angle_between_dirs(sv * c->w, eqs.front()->w);
        if (res > tol.angular_rad) {
          return fail(Outcome::kIncompatible,
                      fmt::format("two axes that are parallel on one body are {:.4g} deg apart "
                                  "on the other",
                                  res * 180.0 / M_PI),
                      0.0, res);
        }
      }
      return solve_family(eqs.front()->v, eqs.front()->w, prims, like, tol);
    }
    const double res = std::abs(angle_between_dirs(eqs.front()->v, second->v) -
                                angle_between_dirs(eqs.front()->w, second->w));
    if (res > tol.angular_rad) {
      return fail(Outcome::kIncompatible,
                  fmt::format("the angle between the axes differs by {:.4g} deg between the two "
                              "bodies",
                              res * 180.0 / M_PI),
                  0.0, res);
    }
    r = rotation_from_pairs(eqs.front()->v, second->v, eqs.front()->w, second->w);
  } else {
    return fail(Outcome::kInexpressible,
                "no relation fixes an axis direction: the orientation keeps two or three "
                "rotational freedoms, which is not one of the ten types");
  }
  const double res = rotation_residual(r, prims.rot);
  if (res > tol.angular_rad) {
    return fail(Outcome::kIncompatible,
                fmt::format("the orientations disagree by {:.4g} deg", res * 180.0 / M_PI), 0.0,
                res);
  }
  return solve_translation(r, prims, like, tol);
}

/// The rotation R(th) = Rot(w, th) * R0 with R0 v = w, when every axis constraint is about v/w.
SolveResult solve_family(const Vector3d& v,
                         const Vector3d& w,
                         const Prims& prims,
                         const Relation& like,
                         const Tolerances& tol) {
  const Matrix3d r0 = rotation_between(v, w);
  // Perpendicularity constraints (AGPC) restrict th.
  std::vector<double> candidates;
  bool pinned = false;
  for (const RotC& c : prims.rot) {
    if (c.kind != RotC::kDirPerp) {
      continue;
    }
    const Vector3d u = r0 * c.v;
    const Vector3d upar = u.dot(w) * w;
    const Vector3d uperp = u - upar;
    const double a = uperp.dot(c.w);
    const double b = w.cross(uperp).dot(c.w);
    const double cc = upar.dot(c.w);
    if (std::hypot(a, b) < 1e-9) {
      if (std::abs(cc) > std::sin(tol.angular_rad)) {
        return fail(Outcome::kIncompatible,
                    "an axis cannot be perpendicular to the face normal "
                    "whatever the rotation",
                    0.0, std::abs(std::asin(std::clamp(cc, -1.0, 1.0))));
      }
      continue;  // satisfied for every th (x_a_parallel / x_b_parallel)
    }
    const std::vector<double> th = solve_trig(a, b, cc, 1e-9);
    if (!pinned) {
      candidates = th;
      pinned = true;
    } else {
      std::vector<double> keep;
      for (const double t : candidates) {
        const Matrix3d rt = Eigen::AngleAxisd(t, w).toRotationMatrix() * r0;
        if (std::abs((rt * c.v).dot(c.w)) <= std::sin(tol.angular_rad)) {
          keep.push_back(t);
        }
      }
      candidates = keep;
    }
    if (candidates.empty()) {
      return fail(Outcome::kIncompatible, "no rotation makes the edge axis lie in the face");
    }
  }
  if (pinned) {
    std::vector<SolveResult> found;
    for (const double t : candidates) {
      const Matrix3d rt = Eigen::AngleAxisd(t, w).toRotationMatrix() * r0;
      SolveResult s = solve_translation(rt, prims, like, tol);
      if (s.outcome == Outcome::kOk) {
        found.push_back(std::move(s));
      } else if (s.outcome != Outcome::kIncompatible) {
        return s;
      }
    }
    if (found.empty()) {
      return fail(Outcome::kIncompatible, "no rotation satisfies every relation");
    }
    if (found.size() > 1) {
      return fail(Outcome::kTwoSolutions, "two orientations satisfy the relations");
    }
    return std::move(found.front());
  }
  // The rotation about w is free: classify the point constraints by symmetry about w.
  struct Axis {
    Vector3d b_point;  // a point of B on the B axis (direction v)
    Vector3d a_point;  // a point of A on the A axis (direction w)
  };
  std::vector<Axis> axes;
  std::vector<double> along;  // required w . t
  for (const PtC& c : prims.pts) {
    switch (c.kind) {
      case PtC::kEq:
        axes.push_back({c.p, c.c});
        along.push_back(w.dot(c.c) - v.dot(c.p));
        break;
      case PtC::kOnLine:
        if (!parallel(c.n, w, 1e-9)) {
          return fail(Outcome::kInexpressible,
                      "a line constraint not along the common axis "
                      "leaves a rotation that is not one of the types");
        }
        axes.push_back({c.p, c.c});
        break;
      case PtC::kOnPlane:
        if (!parallel(c.n, w, 1e-9)) {
          return fail(Outcome::kInexpressible,
                      "a plane not perpendicular to the common axis "
                      "leaves a rotation that is not one of the types");
        }
        along.push_back(w.dot(c.c) - v.dot(c.p));
        break;
      case PtC::kOnPlaneB: {
        if (!parallel(c.n, v, 1e-9)) {
          return fail(Outcome::kInexpressible,
                      "a plane not perpendicular to the common axis "
                      "leaves a rotation that is not one of the types");
        }
        // (R n).(p - t - R c) = 0 with R n = s w (s = +-1): w.t = w.p - v.c (the signs cancel).
        along.push_back(w.dot(c.p) - v.dot(c.c));
        break;
      }
      case PtC::kOnSphere:
        return fail(Outcome::kInexpressible,
                    "a sphere distance with a free rotation is not one "
                    "of the ten types");
    }
  }
  for (std::size_t i = 1; i < along.size(); ++i) {
    const double res = std::abs(along[i] - along.front());
    if (res > tol.linear_mm) {
      return fail(Outcome::kIncompatible, fmt::format("parallel faces are {:.4g} mm apart", res),
                  res);
    }
  }
  auto perp_w = [&](const Vector3d& x) { return Vector3d(x - x.dot(w) * w); };
  auto perp_v = [&](const Vector3d& x) { return Vector3d(x - x.dot(v) * v); };
  // Several axis constraints: either they describe one common axis, or two distinct parallel
  // axes on each body, which pin the rotation (e.g. FITS + FITS with parallel axes -> LIN).
  for (std::size_t i = 1; i < axes.size(); ++i) {
    const Vector3d ob = perp_v(axes[i].b_point - axes.front().b_point);
    const Vector3d oa = perp_w(axes[i].a_point - axes.front().a_point);
    if (ob.norm() <= tol.linear_mm && oa.norm() <= tol.linear_mm) {
      continue;
    }
    const double res = std::abs(ob.norm() - oa.norm());
    if (res > tol.linear_mm) {
      return fail(Outcome::kIncompatible,
                  fmt::format("parallel axes are {:.4g} mm apart on one body and {:.4g} mm on the "
                              "other",
                              ob.norm(), oa.norm()),
                  res);
    }
    const Vector3d rb = r0 * ob;
    const double th = std::atan2(rb.cross(oa).dot(w), rb.dot(oa));
    const Matrix3d rt = Eigen::AngleAxisd(th, w).toRotationMatrix() * r0;
    return solve_translation(rt, prims, like, tol);
  }
  Pose x = Pose::Identity();
  x.linear() = r0;
  const bool has_axis = !axes.empty();
  const bool has_along = !along.empty();
  Vector3d origin = Vector3d::Zero();
  if (has_axis) {
    x.translation() = axes.front().a_point - r0 * axes.front().b_point;
    origin = axes.front().a_point;
  }
  if (has_along) {
    x.translation() += (along.front() - w.dot(x.translation())) * w;
  }
  const Pose fa = frame_from_x(origin, w);
  if (has_axis) {
    return ok(make_relation(has_along ? RelType::kRot : RelType::kFits, like, x, fa));
  }
  return ok(make_relation(has_along ? RelType::kAgpp : RelType::kParax, like, x, fa));
}

/// The coset description a_T_b in H * X* of a group-type relation, H in a's frame.
struct Coset {
  Pose x_star = Pose::Identity();
  bool rotation = false;
  Vector3d axis_point = Vector3d::Zero();  ///< a point of the rotation axis (a's frame)
  Vector3d axis_dir = Vector3d::UnitX();
  std::vector<Vector3d> translations;  ///< a basis of the free translations (a's frame)
};

Coset coset_of(const Relation& r) {
  Coset c;
  c.x_star = flipped(r.type) ? Pose(r.a_T_fa * flip_x() * r.b_T_fb.inverse())
                             : Pose(r.a_T_fa * r.b_T_fb.inverse());
  const Matrix3d ra = r.a_T_fa.linear();
  c.rotation = rotates(r.type);
  c.axis_point = r.a_T_fa.translation();
  c.axis_dir = ra.col(0);
  switch (r.type) {
    case RelType::kLin:
    case RelType::kFits:
      c.translations = {ra.col(0)};
      break;
    case RelType::kLinlin:
    case RelType::kAgpp:
      c.translations = {ra.col(1), ra.col(2)};
      break;
    case RelType::kParax:
      c.translations = {ra.col(0), ra.col(1), ra.col(2)};
      break;
    default:
      break;
  }
  return c;
}

/// An orthonormal basis of the span of `vs`.
std::vector<Vector3d> span_basis(const std::vector<Vector3d>& vs) {
  std::vector<Vector3d> basis;
  for (const Vector3d& v : vs) {
    Vector3d u = v;
    for (const Vector3d& b : basis) {
      u -= u.dot(b) * b;
    }
    if (u.norm() > 1e-6) {
      basis.push_back(u.normalized());
    }
  }
  return basis;
}

}  // namespace

SolveResult intersect(const Relation& r1, const Relation& r2_in, const Tolerances& tol) {
  const Relation r2 = (r2_in.a == r1.a && r2_in.b == r1.b) ? r2_in : reversed(r2_in);
  Prims prims;
  add_primitives(r1, prims);
  add_primitives(r2, prims);
  SolveResult s = solve(prims, r1, tol);
  if (s.outcome == Outcome::kOk) {
    s.relation.sources = r1.sources;
    s.relation.sources.insert(s.relation.sources.end(), r2.sources.begin(), r2.sources.end());
    // A looser input is a superset of the truth, so the intersection may be one too.
    s.relation.looser = r1.looser || r2.looser;
  }
  return s;
}

SolveResult compose(const Relation& r12, const Relation& r23, const Tolerances& tol) {
  if (!group_type(r12.type) || !group_type(r23.type)) {
    return fail(Outcome::kInexpressible,
                "only FIX, LIN, LINLIN, ROT, FITS, AGPP and PARAX "
                "compose along a chain here");
  }
  const Coset c1 = coset_of(r12);
  const Coset c2_local = coset_of(r23);
  // Conjugate the second subgroup into the first node's frame: H2' = X1* H2 X1*^-1.
  Coset c2 = c2_local;
  c2.axis_point = c1.x_star * c2_local.axis_point;
  c2.axis_dir = c1.x_star.linear() * c2_local.axis_dir;
  for (Vector3d& t : c2.translations) {
    t = c1.x_star.linear() * t;
  }
  const Pose x_star = c1.x_star * c2_local.x_star;
  std::vector<Vector3d> trans = c1.translations;
  trans.insert(trans.end(), c2.translations.begin(), c2.translations.end());
  const int union_t = static_cast<int>(span_basis(trans).size());
  bool rot = c1.rotation || c2.rotation;
  Vector3d w = c1.rotation ? c1.axis_dir : c2.axis_dir;
  Vector3d q = c1.rotation ? c1.axis_point : c2.axis_point;
  bool shared_rotation = false;
  if (c1.rotation && c2.rotation) {
    if (!parallel(c1.axis_dir, c2.axis_dir, tol.angular_rad)) {
      return fail(Outcome::kInexpressible,
                  "rotations about two non-parallel axes combine into a rotation with two or "
                  "three freedoms, which is not one of the ten types");
    }
    // Rotations about two distinct parallel lines generate the translations perpendicular to
    // the axis.
    const Vector3d d = c2.axis_point - c1.axis_point;
    if ((d - d.dot(w) * w).norm() > tol.linear_mm) {
      trans.push_back(any_perpendicular(w));
      trans.push_back(w.cross(any_perpendicular(w)));
    } else {
      shared_rotation = true;
    }
  }
  std::vector<Vector3d> basis = span_basis(trans);
  if (rot) {
    // The generated group is invariant under the rotation: any translation component
    // perpendicular to the axis sweeps the whole perpendicular plane.
    bool perp = false;
    bool along = false;
    for (const Vector3d& b : basis) {
      if ((b - b.dot(w) * w).norm() > 1e-6) {
        perp = true;
      }
      if (std::abs(b.dot(w)) > 1e-6) {
        along = true;
      }
    }
    if (perp && !along) {
      // A line perpendicular to w plus the rotation: the plane; a plane tilted to w would
      // include w as well (handled by `along`).
      basis = span_basis({any_perpendicular(w), w.cross(any_perpendicular(w))});
    } else if (perp && along) {
      basis = {Vector3d::UnitX(), Vector3d::UnitY(), Vector3d::UnitZ()};
    }
  }
  const int dim_t = static_cast<int>(basis.size());
  // Exactness (Table 2's '*'): dim(H1 H2') = dim H1 + dim H2' - dim(H1 n H2').
  const auto dim_of = [](const Coset& c) {
    return static_cast<int>(c.translations.size()) + (c.rotation ? 1 : 0);
  };
  const std::vector<Vector3d> b1 = span_basis(c1.translations);
  const std::vector<Vector3d> b2 = span_basis(c2.translations);
  const int common_t = static_cast<int>(b1.size() + b2.size()) - union_t;
  const bool plane1 = c1.translations.size() >= 2;
  const bool plane2 = c2.translations.size() >= 2;
  const int common_r =
      (c1.rotation && c2.rotation && (shared_rotation || (plane1 && plane2))) ? 1 : 0;
  const int product_dim = dim_of(c1) + dim_of(c2) - std::max(0, common_t) - common_r;
  RelType type;
  Pose fa;
  if (rot) {
    if (dim_t == 0) {
      type = RelType::kRot;
    } else if (dim_t == 1) {
      type = RelType::kFits;
    } else if (dim_t == 2) {
      type = RelType::kAgpp;
    } else {
      type = RelType::kParax;
    }
    fa = frame_from_x(q, w);
  } else if (dim_t == 0) {
    type = RelType::kFix;
    fa = x_star;
  } else if (dim_t == 1) {
    type = RelType::kLin;
    fa = frame_from_x(x_star.translation(), basis.front());
  } else if (dim_t == 2) {
    type = RelType::kLinlin;
    fa = frame_from_x(x_star.translation(), basis.front().cross(basis.back()).normalized());
  } else {
    // Free translation with a fixed orientation: loosen to PARAX about the first relation's
    // X axis (Table 2 marks these '*').
    type = RelType::kParax;
    fa = frame_from_x(x_star.translation(), r12.a_T_fa.linear().col(0));
  }
  const Dof d = dof(type);
  const int result_dim = d.translational + d.rotational;
  Relation out = make_relation(type, r12, x_star, fa);
  out.a = r12.a;
  out.b = r23.b;
  out.looser = result_dim > product_dim || r12.looser || r23.looser;
  out.sources = r12.sources;
  out.sources.insert(out.sources.end(), r23.sources.begin(), r23.sources.end());
  return ok(std::move(out));
}

std::pair<double, double> residual(const Relation& r, const Pose& a_T_b) {
  Prims prims;
  add_primitives(r, prims);
  const Matrix3d rot = a_T_b.linear();
  const Vector3d t = a_T_b.translation();
  const double ang = rotation_residual(rot, prims.rot);
  double lin = 0.0;
  for (const PtC& c : prims.pts) {
    switch (c.kind) {
      case PtC::kEq:
        lin = std::max(lin, (rot * c.p + t - c.c).norm());
        break;
      case PtC::kOnLine: {
        const Vector3d d = rot * c.p + t - c.c;
        lin = std::max(lin, (d - d.dot(c.n) * c.n).norm());
        break;
      }
      case PtC::kOnPlane:
        lin = std::max(lin, std::abs(c.n.dot(rot * c.p + t - c.c)));
        break;
      case PtC::kOnPlaneB: {
        const Vector3d m = rot * c.n;
        lin = std::max(lin, std::abs(m.dot(c.p - t - rot * c.c)));
        break;
      }
      case PtC::kOnSphere:
        lin = std::max(lin, std::abs((rot * c.p + t - c.c).norm() - c.r));
        break;
    }
  }
  return {ang, lin};
}

}  // namespace cell::rapt
