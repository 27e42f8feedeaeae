#include "cell/rapt/vision.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <functional>

namespace cell::rapt {

using Eigen::Matrix3d;
using Eigen::Vector3d;

Vector3d combine_tolerance(double d, const std::vector<Vector3d>& normals) {
  // Independent reference normals (rank of the set).
  std::vector<Vector3d> basis;
  for (const Vector3d& n : normals) {
    Vector3d u = n;
    for (const Vector3d& b : basis) {
      u -= u.dot(b) * b;
    }
    if (u.norm() > 1e-6) {
      basis.push_back(u.normalized());
    }
  }
  if (basis.empty()) {
    return Vector3d::Constant(d);
  }
  if (basis.size() == 1) {  // (5.2)
    const Vector3d a = normals.front().normalized();
    return Vector3d(d * (1.0 - a.x() * a.x()), d * (1.0 - a.y() * a.y()),
                    d * (1.0 - a.z() * a.z()));
  }
  if (basis.size() == 2) {  // (5.1), with the two first independent normals
    Vector3d second = normals.front();
    for (const Vector3d& n : normals) {
      if (!parallel(n.normalized(), normals.front().normalized(), 1e-6)) {
        second = n;
        break;
      }
    }
    const Vector3d c = normals.front().cross(second).normalized();
    return (d * c).cwiseAbs();
  }
  return Vector3d::Zero();
}

namespace {

constexpr double kRadToDeg = 180.0 / 3.14159265358979323846;

/// An INVIOLATE's geometry: the world reference plane and the verified body's face.
struct AgppGeometry {
  Vector3d c0 = Vector3d::Zero();   ///< reference face origin, world
  Vector3d n0 = Vector3d::UnitX();  ///< reference face normal, world
  Vector3d pf = Vector3d::Zero();   ///< verified face origin, body
  Vector3d m = Vector3d::UnitX();   ///< verified face normal, body
};

AgppGeometry agpp_geometry(const Program& program,
                           const InviolateDecl& inv,
                           const Pose& world_T_reference) {
  const Feature& ref = program.feature(inv.reference);
  const Feature& face = program.feature(inv.verified);
  const Pose world_T_f = world_T_reference * ref.body_T_feature;
  return AgppGeometry{world_T_f.translation(), world_T_f.linear().col(0), face.origin(),
                      face.axis()};
}

/// A value flowing through a route.
struct Value {
  RelType type = RelType::kAgpp;
  AgppGeometry agpp;                  // AGPP
  Plane plane;                        // a LOOK face (kLookFace)
  Matrix3d r = Matrix3d::Identity();  // LIN, FIX
  Vector3d t0 = Vector3d::Zero();     // LIN origin / FIX translation
  Vector3d d = Vector3d::UnitX();     // LIN direction
};

/// t = t_near + alpha n1 + beta n2 with n_i . (R p_i + t - c_i) = 0.
Vector3d two_planes(const Vector3d& n1,
                    const Vector3d& c1,
                    const Vector3d& p1,
                    const Vector3d& n2,
                    const Vector3d& c2,
                    const Vector3d& p2,
                    const Matrix3d& r,
                    const Vector3d& t_near) {
  Eigen::Matrix2d a;
  a << n1.dot(n1), n1.dot(n2), n2.dot(n1), n2.dot(n2);
  const Eigen::Vector2d b(n1.dot(c1 - r * p1 - t_near), n2.dot(c2 - r * p2 - t_near));
  const Eigen::Vector2d x = a.fullPivLu().solve(b);
  return t_near + x[0] * n1 + x[1] * n2;
}

std::string look_name(const Program& program, const LookDecl& look) {
  return fmt::format("LOOK/{}, {} at {}", program.feature_name(look.edge),
                     program.cameras[static_cast<std::size_t>(look.camera)].name,
                     to_string(look.loc));
}

}  // namespace

CompiledPackage compile_package(const Program& program,
                                const NominalSolution& nominal,
                                int index,
                                const VisionOptions& options,
                                Diagnostics& diags) {
  const Package& pk = program.packages[static_cast<std::size_t>(index)];
  CompiledPackage cp;
  cp.index = index;
  cp.situation = pk.situation;
  cp.body = pk.body;
  cp.loc = pk.loc;
  const std::string bv = pk.body > 0 ? program.body(pk.body).name : "?";
  for (const LookDecl& look : pk.looks) {
    CompiledLook cl;
    cl.decl = look;
    cp.looks.push_back(cl);
  }
  if (pk.body <= 0 || pk.looks.empty()) {
    cp.cannot_fix = "the package has errors";
    return cp;
  }
  const std::optional<Pose>& pn = nominal.pose(pk.body, pk.situation);
  if (!pn) {
    cp.cannot_fix = fmt::format("the nominal position of '{}' is not determined", bv);
    return cp;
  }
  // Tolerance: local, else global, else the system default (thesis §5.5.2).
  if (pk.local_tolerance) {
    cp.tolerance_mm = *pk.local_tolerance;
    cp.tolerance_source = "local";
  } else if (const auto it = program.global_tolerance.find(pk.body);
             it != program.global_tolerance.end()) {
    cp.tolerance_mm = it->second;
    cp.tolerance_source = "global";
  } else {
    cp.tolerance_mm = options.default_tolerance_mm;
    cp.tolerance_source = "default";
  }
  // INVIOLATE references and the nominal check.
  std::vector<AgppGeometry> agpps;
  std::vector<Vector3d> normals;
  bool references_ok = true;
  for (const InviolateDecl& inv : pk.inviolates) {
    const std::optional<Pose>& ref_pose = nominal.pose(inv.reference.body, pk.situation);
    if (!ref_pose) {
      diags.error(inv.loc, fmt::format("the INVIOLATE reference '{}' is not fixed in the world in "
                                       "situation {}: the reference must belong to the world or "
                                       "to a body whose position is determined (thesis §5.3)",
                                       program.feature_name(inv.reference), pk.situation));
      references_ok = false;
      continue;
    }
    const AgppGeometry g = agpp_geometry(program, inv, *ref_pose);
    const Vector3d m_world = pn->linear() * g.m;
    const double ang = std::atan2(m_world.cross(-g.n0).norm(), m_world.dot(-g.n0));
    const double dist = std::abs(g.n0.dot(*pn * g.pf - g.c0));
    if (ang > options.tolerances.angular_rad || dist > options.tolerances.linear_mm) {
      diags.error(inv.loc, fmt::format("INVIOLATE/AGAINST, {}, {} does not hold at the nominal "
                                       "position of '{}' in situation {} (the faces are {:.4g} "
                                       "deg from opposed and {:.4g} mm apart); an INVIOLATE must "
                                       "describe the nominal situation",
                                       program.feature_name(inv.reference),
                                       program.feature_name(inv.verified), bv, pk.situation,
                                       ang * kRadToDeg, dist));
      references_ok = false;
      continue;
    }
    agpps.push_back(g);
    normals.push_back(g.n0);
  }
  cp.combined_tolerance_mm = combine_tolerance(cp.tolerance_mm, normals);
  // Predictions and windows.
  std::vector<Vector3d> look_normals(pk.looks.size(), Vector3d::Zero());
  bool looks_ok = true;
  for (std::size_t k = 0; k < pk.looks.size(); ++k) {
    CompiledLook& cl = cp.looks[k];
    const Camera& cam = program.cameras[static_cast<std::size_t>(cl.decl.camera)];
    CameraModel model{cam.world_T_camera, cam.focus};
    if (cam.general) {
      const std::optional<Pose>& cam_pose = nominal.pose(cam.body, pk.situation);
      if (!cam_pose) {
        diags.error(cl.decl.loc, fmt::format("the camera body '{}' of '{}' has no determined "
                                             "position in situation {}",
                                             program.body(cam.body).name, cam.name, pk.situation));
        looks_ok = false;
        continue;
      }
      model.world_T_camera = *cam_pose;
    }
    const Feature& edge = program.feature(cl.decl.edge);
    const auto [e1, e2] = edge.edge_end_points();
    const Vector3d q1 = *pn * e1;
    const Vector3d q2 = *pn * e2;
    auto p1 = model.project(q1);
    auto p2 = model.project(q2);
    if (!p1 || !p2) {
      diags.error(cl.decl.loc, fmt::format("{}: the edge cannot be seen at its nominal position "
                                           "in situation {}: {}",
                                           look_name(program, cl.decl), pk.situation,
                                           (!p1 ? p1.error() : p2.error()).message));
      looks_ok = false;
      continue;
    }
    cl.predicted = {*p1, *p2};
    if (auto w = suggest_window(model, q1, q2, cp.combined_tolerance_mm)) {
      cl.window = *w;
    }
    const Vector3d c = model.world_T_camera.translation();
    const Vector3d n = (q1 - c).cross(q2 - c);
    if (n.norm() < 1e-9) {
      diags.error(cl.decl.loc, fmt::format("{}: the edge points straight at the lens, so its image "
                                           "is a point and gives no face",
                                           look_name(program, cl.decl)));
      looks_ok = false;
      continue;
    }
    look_normals[k] = n.normalized();
  }
  if (!references_ok || !looks_ok) {
    cp.cannot_fix = "the package has errors";
    return cp;
  }
  // --- the route (Table 6.2) -----------------------------------------------------------------
  Route& route = cp.route;
  auto add = [&](RouteNode node) {
    route.nodes.push_back(node);
    return static_cast<int>(route.nodes.size()) - 1;
  };
  auto call = [&](const SymbolicRule& rule, int a0, int a1, int look) {
    RouteNode n;
    n.kind = RouteNode::Kind::kCall;
    n.function = rule.function;
    n.arg0 = a0;
    n.arg1 = a1;
    n.edge_look = look;
    n.type = rule.result;
    return add(n);
  };
  if (pk.inviolates.empty()) {
    cp.cannot_fix =
        "the package has no INVIOLATE: pure vision (LOOKs only) is not supported, "
        "AGPC/AGPE relations alone cannot be combined (thesis §5.3.1)";
  }
  int cur = -1;
  RelType cur_type = RelType::kAgpp;
  const AgppGeometry* cur_agpp = nullptr;  // the AGPP in force when cur_type == AGPP
  Vector3d lin_dir = Vector3d::UnitX();    // nominal LIN direction when cur_type == LIN
  const double sin_deg = std::sin(options.degenerate_angle_rad);
  for (std::size_t i = 0; i < pk.inviolates.size(); ++i) {
    RouteNode leaf;
    leaf.kind = RouteNode::Kind::kInviolate;
    leaf.index = static_cast<int>(i);
    leaf.type = RelType::kAgpp;
    const AgppGeometry& g = agpps[i];
    if (cur < 0) {
      cur = add(leaf);
      cur_agpp = &agpps[i];
      continue;
    }
    if (cur_type == RelType::kAgpp) {
      const bool par = parallel(g.n0, cur_agpp->n0, options.degenerate_angle_rad);
      const SymbolicRule* rule = symbolic_rule(RelType::kAgpp, SymbolicInput::kAgpp, par);
      cur = call(*rule, cur, add(leaf), -1);
      cur_type = rule->result;
      if (cur_type == RelType::kLin) {
        lin_dir = cur_agpp->n0.cross(g.n0).normalized();
      }
    } else if (cur_type == RelType::kLin) {
      if (std::abs(g.n0.dot(lin_dir)) < sin_deg) {
        continue;  // x_a_perpendicular: the plane contains the LIN, nothing new
      }
      const SymbolicRule* rule = symbolic_rule(RelType::kLin, SymbolicInput::kAgpp, false);
      cur = call(*rule, cur, add(leaf), -1);
      cur_type = rule->result;
    }
  }
  std::vector<bool> used(pk.looks.size(), false);
  bool progress = cur >= 0;
  while (progress && cur_type != RelType::kFix) {
    progress = false;
    for (std::size_t k = 0; k < pk.looks.size(); ++k) {
      if (used[k]) {
        continue;
      }
      CompiledLook& cl = cp.looks[k];
      const Feature& edge = program.feature(cl.decl.edge);
      const Vector3d n_face = look_normals[k];
      if (cur_type == RelType::kAgpp) {
        if (parallel(edge.axis(), cur_agpp->m, options.degenerate_angle_rad)) {
          cl.note =
              "not used with the INVIOLATE alone: the edge is parallel to the INVIOLATE "
              "face normal, AGPP+AGPE would give ROTYLIN (thesis §6.5.1)";
          continue;
        }
        if (parallel(n_face, cur_agpp->n0, options.degenerate_angle_rad)) {
          cl.note =
              "not used: its face would be parallel to the INVIOLATE reference face "
              "(thesis Fig. 6.3)";
          continue;
        }
        RouteNode face;
        face.kind = RouteNode::Kind::kLookFace;
        face.index = static_cast<int>(k);
        const SymbolicRule* rule = symbolic_rule(RelType::kAgpp, SymbolicInput::kAgpe, false);
        cur = call(*rule, cur, add(face), static_cast<int>(k));
        cur_type = rule->result;
        lin_dir = cur_agpp->n0.cross(n_face).normalized();
      } else if (cur_type == RelType::kLin) {
        if (std::abs(n_face.dot(lin_dir)) < sin_deg) {
          cl.note =
              "not used: its face contains the LIN direction, so it cannot fix the slide "
              "(thesis Fig. 6.4)";
          continue;
        }
        RouteNode face;
        face.kind = RouteNode::Kind::kLookFace;
        face.index = static_cast<int>(k);
        const SymbolicRule* rule = symbolic_rule(RelType::kLin, SymbolicInput::kAgpe, false);
        cur = call(*rule, cur, add(face), static_cast<int>(k));
        cur_type = rule->result;
      } else {
        break;
      }
      used[k] = true;
      cl.used = true;
      cl.note.clear();
      progress = true;
      break;  // start again from the first unused LOOK
    }
  }
  route.reached = cur_type;
  for (std::size_t k = 0; k < pk.looks.size(); ++k) {
    if (!used[k] && cur_type == RelType::kFix && cp.looks[k].note.empty()) {
      cp.looks[k].note =
          "redundant: the body is fixed without it (its end points are not used "
          "by the thesis's reasoning; see the least-squares evaluation)";
    }
  }
  cp.fixable = cur >= 0 && cur_type == RelType::kFix;
  if (!cp.fixable) {
    if (cp.cannot_fix.empty()) {
      cp.cannot_fix = fmt::format(
          "after {} the position of '{}' is still a {} ({} translational, {} rotational "
          "freedoms): add an INVIOLATE or a LOOK of an edge that is not parallel to the "
          "INVIOLATE face normal and whose face does not contain the sliding direction",
          route_text(program, cp), bv, to_string(cur_type), dof(cur_type).translational,
          dof(cur_type).rotational);
    }
    diags.warning(pk.loc, fmt::format("cannot fix '{}' with this COMBINE package: {}; its camera "
                                      "commands will be ignored at run time (thesis §6.7)",
                                      bv, cp.cannot_fix));
  }
  return cp;
}

std::string route_text(const Program& program, const CompiledPackage& package) {
  const Route& route = package.route;
  if (route.nodes.empty()) {
    return "(none)";
  }
  const Package& pk = program.packages[static_cast<std::size_t>(package.index)];
  std::function<std::string(int)> text = [&](int i) -> std::string {
    const RouteNode& n = route.nodes[static_cast<std::size_t>(i)];
    switch (n.kind) {
      case RouteNode::Kind::kInviolate: {
        const InviolateDecl& inv = pk.inviolates[static_cast<std::size_t>(n.index)];
        return fmt::format("AGPP[{}, {}]", program.feature_name(inv.reference),
                           program.feature_name(inv.verified));
      }
      case RouteNode::Kind::kLookFace: {
        const LookDecl& look = pk.looks[static_cast<std::size_t>(n.index)];
        return fmt::format("face[LOOK {}, {}]", program.feature_name(look.edge),
                           program.cameras[static_cast<std::size_t>(look.camera)].name);
      }
      case RouteNode::Kind::kCall: {
        std::string out =
            fmt::format("{}({}, {}", to_string(n.function), text(n.arg0), text(n.arg1));
        if (n.edge_look >= 0) {
          out += ", " + program.feature_name(pk.looks[static_cast<std::size_t>(n.edge_look)].edge);
        }
        return out + ")";
      }
    }
    return "?";
  };
  const std::string body = text(static_cast<int>(route.nodes.size()) - 1);
  return route.reached == RelType::kFix ? "merge(" + body + ")" : body;
}

Result<Pose> evaluate_route(const Program& program,
                            const CompiledPackage& package,
                            const RouteInputs& in) {
  if (!package.fixable || package.route.nodes.empty()) {
    return Error{Errc::kInvalidArgument, "the package cannot fix its body"};
  }
  const Package& pk = program.packages[static_cast<std::size_t>(package.index)];
  const Matrix3d r_n = in.world_T_nominal.linear();
  const Vector3d t_n = in.world_T_nominal.translation();
  std::vector<Value> values(package.route.nodes.size());
  for (std::size_t i = 0; i < package.route.nodes.size(); ++i) {
    const RouteNode& n = package.route.nodes[i];
    Value& v = values[i];
    v.type = n.type;
    switch (n.kind) {
      case RouteNode::Kind::kInviolate: {
        const auto k = static_cast<std::size_t>(n.index);
        if (k >= in.world_T_reference.size()) {
          return Error{Errc::kInvalidArgument, "missing the pose of an INVIOLATE reference"};
        }
        v.agpp = agpp_geometry(program, pk.inviolates[k], in.world_T_reference[k]);
        break;
      }
      case RouteNode::Kind::kLookFace: {
        const auto k = static_cast<std::size_t>(n.index);
        const LookDecl& look = pk.looks[k];
        if (k >= in.readings.size() || !in.readings[k] || k >= in.cameras.size()) {
          return Error{Errc::kInvalidArgument, fmt::format("{}: no measurement (situation {})",
                                                           look_name(program, look), pk.situation)};
        }
        auto plane = face_from_image(in.cameras[k], in.readings[k]->first, in.readings[k]->second);
        if (!plane) {
          return with_context(plane.error(), look_name(program, look));
        }
        v.plane = *plane;
        break;
      }
      case RouteNode::Kind::kCall: {
        const Value& a = values[static_cast<std::size_t>(n.arg0)];
        const Value& b = values[static_cast<std::size_t>(n.arg1)];
        const Feature* edge =
            n.edge_look >= 0
                ? &program.feature(pk.looks[static_cast<std::size_t>(n.edge_look)].edge)
                : nullptr;
        const std::string where =
            edge != nullptr ? look_name(program, pk.looks[static_cast<std::size_t>(n.edge_look)])
                            : fmt::format("COMBINE at {}", to_string(pk.loc));
        switch (n.function) {
          case SymbolicFunction::kAgppAgppParallel:
            v.agpp = a.agpp;
            break;
          case SymbolicFunction::kAgppAgppLin: {
            v.r = rotation_from_pairs(a.agpp.m, b.agpp.m, -a.agpp.n0, -b.agpp.n0);
            v.t0 = two_planes(a.agpp.n0, a.agpp.c0, a.agpp.pf, b.agpp.n0, b.agpp.c0, b.agpp.pf, v.r,
                              t_n);
            v.d = a.agpp.n0.cross(b.agpp.n0).normalized();
            break;
          }
          case SymbolicFunction::kAgppAgpeLin: {
            const AgppGeometry& g = a.agpp;
            const Plane& face = b.plane;
            // Rotations with R m = -n0 are Rot(n0, th) * Ra; the edge must lie in the face.
            const Matrix3d ra = rotation_between(r_n * g.m, -g.n0) * r_n;
            const Vector3d u = ra * edge->axis();
            const Vector3d upar = u.dot(g.n0) * g.n0;
            const Vector3d uperp = u - upar;
            const double ca = uperp.dot(face.normal);
            const double cb = g.n0.cross(uperp).dot(face.normal);
            const double cc = upar.dot(face.normal);
            const double h = std::hypot(ca, cb);
            if (h < 1e-12) {
              return Error{Errc::kInvalidArgument,
                           where + ": the edge is parallel to the INVIOLATE face normal (ROTYLIN)"};
            }
            const double ratio = std::clamp(-cc / h, -1.0 - 1e-9, 1.0 + 1e-9);
            if (std::abs(ratio) > 1.0 + 1e-12) {
              return Error{Errc::kOutOfRange,
                           where +
                               ": no rotation about the INVIOLATE normal puts the edge in "
                               "the face seen by the camera (the measurement contradicts "
                               "the INVIOLATE)"};
            }
            const double base = std::atan2(cb, ca);
            const double delta = std::acos(std::clamp(ratio, -1.0, 1.0));
            // Two solutions (thesis Fig. 6.1): keep the one nearer the nominal orientation
            // (less than 90 degrees away, §6.5.1).
            double best = 1e9;
            for (const double th : {base + delta, base - delta}) {
              const Matrix3d rc = Eigen::AngleAxisd(th, g.n0).toRotationMatrix() * ra;
              const double ang = rotation_angle(r_n, rc);
              if (ang < best) {
                best = ang;
                v.r = rc;
              }
            }
            const Vector3d dvec = g.n0.cross(face.normal);
            if (dvec.norm() < 1e-9) {
              return Error{Errc::kOutOfRange,
                           where +
                               ": the face seen by the camera is parallel to the INVIOLATE "
                               "reference face (thesis Fig. 6.3)"};
            }
            v.d = dvec.normalized();
            v.t0 = two_planes(g.n0, g.c0, g.pf, face.normal, face.point, edge->origin(), v.r, t_n);
            break;
          }
          case SymbolicFunction::kLinAgpeFix:
          case SymbolicFunction::kLinAgppFix: {
            Vector3d normal;
            Vector3d point;
            Vector3d body_point;
            if (n.function == SymbolicFunction::kLinAgpeFix) {
              normal = b.plane.normal;
              point = b.plane.point;
              body_point = edge->origin();  // digest §3.3: the edge origin is put in the face
            } else {
              normal = b.agpp.n0;
              point = b.agpp.c0;
              body_point = b.agpp.pf;
            }
            const double denom = normal.dot(a.d);
            if (std::abs(denom) < 1e-9) {
              return Error{Errc::kOutOfRange,
                           where +
                               ": the face is parallel to the sliding direction of the LIN "
                               "(thesis Fig. 6.4)"};
            }
            const double s = -normal.dot(a.r * body_point + a.t0 - point) / denom;
            v.r = a.r;
            v.t0 = a.t0 + s * a.d;
            break;
          }
        }
        break;
      }
    }
  }
  const Value& root = values.back();
  Pose pv = Pose::Identity();
  pv.linear() = root.r;
  pv.translation() = root.t0;
  return pv;
}

}  // namespace cell::rapt
