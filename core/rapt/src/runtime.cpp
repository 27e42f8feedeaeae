#include "cell/rapt/runtime.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cctype>
#include <fstream>
#include <map>
#include <sstream>

#include "cell/config/yaml.hpp"

namespace cell::rapt {

const Pose& RunResult::fm_of(int body, int situation) const {
  return fm.at(static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(situations) +
               static_cast<std::size_t>(situation - 1));
}

const Pose& RunResult::actual_pose(int body, int situation) const {
  return actual.at(static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(situations) +
                   static_cast<std::size_t>(situation - 1));
}

namespace {

/// Run-time values of the MF array, resolved situation by situation (pointers only point to
/// the same or earlier situations, so a package's inputs from s-1 are known when it runs).
class Resolver {
 public:
  Resolver(const CompiledProgram& cp, const std::vector<PackageOutcome>& packages)
      : cp_(cp),
        packages_(packages),
        s_(cp.program.situation_count()),
        fm_(static_cast<std::size_t>(cp.program.body_count()) * static_cast<std::size_t>(s_)),
        state_(fm_.size(), 0) {}

  Result<Pose> fm(int body, int situation) {
    const auto i = static_cast<std::size_t>(body - 1) * static_cast<std::size_t>(s_) +
                   static_cast<std::size_t>(situation - 1);
    if (state_[i] == 2) {
      return fm_[i];
    }
    if (state_[i] == 1) {
      return Error{Errc::kInvalidArgument,
                   fmt::format("the modifying factor of {} in situation {} refers to itself",
                               cp_.body_names[static_cast<std::size_t>(body - 1)], situation)};
    }
    state_[i] = 1;
    auto value = compute(body, situation);
    if (!value) {
      state_[i] = 0;
      return value;
    }
    fm_[i] = *value;
    state_[i] = 2;
    return fm_[i];
  }

  /// FM * PN: the actual world_T_body.
  Result<Pose> actual(int body, int situation) {
    auto f = fm(body, situation);
    if (!f) {
      return f;
    }
    return Pose(cp_.nominal_pose(body, situation) * *f);
  }

 private:
  Result<Pose> compute(int body, int situation) {
    const MfEntry& e = cp_.mf_after.at(body, situation);
    const Pose& pn = cp_.nominal_pose(body, situation);
    switch (e.kind) {
      case MfEntry::Kind::kIdentity:
        return Pose::Identity();
      case MfEntry::Kind::kVerified: {
        const PackageOutcome& po = packages_.at(static_cast<std::size_t>(e.package));
        if (!po.evaluated) {
          return Error{Errc::kInvalidArgument,
                       fmt::format("the package of situation {} was not evaluated", situation)};
        }
        return po.fm;  // (7.2)
      }
      case MfEntry::Kind::kPointer: {
        auto target = fm(e.pointer.body, e.pointer.situation);
        if (!target) {
          return target;
        }
        if (e.pointer.body == body) {
          return *target;  // same body, earlier situation: equality (7.6)
        }
        // Another body: (7.11), with both nominal positions in the pointer's situation.
        return mf_equations::specified(cp_.nominal_pose(body, e.pointer.situation),
                                       cp_.nominal_pose(e.pointer.body, e.pointer.situation),
                                       *target);
      }
      case MfEntry::Kind::kTriple: {
        const auto& t = e.triple;
        auto f1 = fm(t[0].body, t[0].situation);
        auto f2 = fm(t[1].body, t[1].situation);
        auto f3 = fm(t[2].body, t[2].situation);
        if (!f1 || !f2 || !f3) {
          return !f1 ? f1 : (!f2 ? f2 : f3);
        }
        return mf_equations::triple(*f1, cp_.nominal_pose(t[0].body, t[0].situation), *f2,
                                    cp_.nominal_pose(t[1].body, t[1].situation), *f3,
                                    cp_.nominal_pose(t[2].body, t[2].situation), pn);  // (8.11)
      }
    }
    return Pose::Identity();
  }

  const CompiledProgram& cp_;
  const std::vector<PackageOutcome>& packages_;
  int s_;
  std::vector<Pose> fm_;
  std::vector<std::uint8_t> state_;  ///< 0 unknown, 1 in progress, 2 done
};

}  // namespace

Result<RunResult> run(const CompiledProgram& cp,
                      const std::vector<Reading>& readings,
                      const RunOptions& options) {
  const Program& program = cp.program;
  const int last = options.through_situation > 0
                       ? std::min(options.through_situation, program.situation_count())
                       : program.situation_count();
  // Match every reading to a LOOK.
  std::vector<std::vector<std::optional<std::pair<ImagePoint, ImagePoint>>>> measured(
      cp.packages.size());
  for (std::size_t i = 0; i < cp.packages.size(); ++i) {
    measured[i].resize(cp.packages[i].looks.size());
  }
  std::vector<std::string> problems;
  for (const Reading& r : readings) {
    bool found = false;
    std::string available;
    for (std::size_t i = 0; i < cp.packages.size() && !found; ++i) {
      const CompiledPackage& pkg = cp.packages[i];
      if (pkg.situation != r.situation) {
        continue;
      }
      for (std::size_t k = 0; k < pkg.looks.size(); ++k) {
        const LookDecl& look = pkg.looks[k].decl;
        const std::string body = program.body(look.edge.body).name;
        const std::string edge = program.feature(look.edge).name;
        const std::string cam = program.cameras[static_cast<std::size_t>(look.camera)].name;
        available +=
            fmt::format("{}{} of {} with {}", available.empty() ? "" : ", ", edge, body, cam);
        if (body == r.body && edge == r.edge && cam == r.camera) {
          if (measured[i][k]) {
            problems.push_back(
                fmt::format("{}: a second reading for LOOK {} of {} with {} in "
                            "situation {}",
                            r.where, edge, body, cam, r.situation));
          }
          measured[i][k] = std::pair{r.p1, r.p2};
          found = true;
        }
      }
    }
    if (!found) {
      problems.push_back(fmt::format("{}: no LOOK of {} of {} with camera {} in situation {}{}",
                                     r.where, r.edge, r.body, r.camera, r.situation,
                                     available.empty()
                                         ? std::string(" (that situation has no vision package)")
                                         : " (its LOOKs are: " + available + ")"));
    }
  }
  for (std::size_t i = 0; i < cp.packages.size(); ++i) {
    const CompiledPackage& pkg = cp.packages[i];
    if (!pkg.fixable || pkg.situation > last) {
      continue;
    }
    for (std::size_t k = 0; k < pkg.looks.size(); ++k) {
      if (pkg.looks[k].used && !measured[i][k]) {
        const LookDecl& look = pkg.looks[k].decl;
        problems.push_back(fmt::format(
            "{}:{}: no reading for LOOK/{}, {} in situation {} (the package needs it)",
            program.file, to_string(look.loc), program.feature_name(look.edge),
            program.cameras[static_cast<std::size_t>(look.camera)].name, pkg.situation));
      }
    }
  }
  if (!problems.empty()) {
    std::string all;
    for (const std::string& p : problems) {
      all += (all.empty() ? "" : "\n") + p;
    }
    return Error{Errc::kInvalidArgument, all};
  }

  RunResult out;
  out.bodies = program.body_count();
  out.situations = program.situation_count();
  out.packages.resize(cp.packages.size());
  Resolver resolver(cp, out.packages);
  for (int s = 1; s <= last; ++s) {
    for (std::size_t i = 0; i < cp.packages.size(); ++i) {
      const CompiledPackage& pkg = cp.packages[i];
      if (pkg.situation != s) {
        continue;
      }
      PackageOutcome& po = out.packages[i];
      po.package = static_cast<int>(i);
      if (!pkg.fixable) {
        po.note = "ignored: the package cannot fix its body (" + pkg.cannot_fix + ")";
        continue;
      }
      const Package& decl = program.packages[i];
      RouteInputs in;
      in.world_T_nominal = cp.nominal_pose(pkg.body, s);
      for (const InviolateDecl& inv : decl.inviolates) {
        auto ref = resolver.actual(inv.reference.body, s - 1);  // (7.20): FM * PN before
        if (!ref) {
          return ref.error();
        }
        in.world_T_reference.push_back(*ref);
      }
      auto body_before = resolver.actual(pkg.body, s - 1);
      if (!body_before) {
        return body_before.error();
      }
      for (std::size_t k = 0; k < pkg.looks.size(); ++k) {
        const Camera& cam = program.cameras[static_cast<std::size_t>(pkg.looks[k].decl.camera)];
        CameraModel model{cam.world_T_camera, cam.focus};
        if (cam.general) {
          auto pose = resolver.actual(cam.body, s - 1);
          if (!pose) {
            return pose.error();
          }
          model.world_T_camera = *pose;
        }
        in.cameras.push_back(model);
        in.readings.push_back(measured[i][k]);
        // Run-time window at FM*PN of the body and the camera (thesis §7.7).
        const Feature& edge = program.feature(pkg.looks[k].decl.edge);
        const auto [e1, e2] = edge.edge_end_points();
        const Eigen::Vector3d q1 = *body_before * e1;
        const Eigen::Vector3d q2 = *body_before * e2;
        auto p1 = model.project(q1);
        auto p2 = model.project(q2);
        if (p1 && p2) {
          po.predicted.push_back({*p1, *p2});
        } else {
          po.predicted.push_back({ImagePoint::Constant(NAN), ImagePoint::Constant(NAN)});
        }
        auto w = suggest_window(model, q1, q2, pkg.combined_tolerance_mm);
        po.windows.push_back(w ? *w : Window{});
      }
      auto pv = evaluate_route(program, pkg, in);
      if (!pv) {
        return with_context(pv.error(), fmt::format("situation {}", s));
      }
      po.evaluated = true;
      po.verified = *pv;
      po.fm = mf_equations::from_verified(in.world_T_nominal, *pv);
      if (options.least_squares) {
        auto lsq = least_squares(program, pkg, in, *pv);
        if (lsq) {
          po.lsq = *lsq;
        } else {
          po.note = "least squares not evaluated: " + lsq.error().message;
        }
      }
    }
    for (int b = 1; b <= out.bodies; ++b) {
      auto f = resolver.fm(b, s);
      if (!f) {
        return f.error();
      }
    }
  }
  out.fm.resize(static_cast<std::size_t>(out.bodies) * static_cast<std::size_t>(out.situations));
  out.actual.resize(out.fm.size());
  for (int b = 1; b <= out.bodies; ++b) {
    for (int s = 1; s <= out.situations; ++s) {
      const auto i = static_cast<std::size_t>(b - 1) * static_cast<std::size_t>(out.situations) +
                     static_cast<std::size_t>(s - 1);
      out.fm[i] = s <= last ? *resolver.fm(b, s) : Pose::Identity();
      out.actual[i] = cp.nominal_pose(b, s) * out.fm[i];
    }
  }
  // Actions (thesis §7.5), in world axes: world_T_after = motion * world_T_before.
  for (int s = 2; s <= last; ++s) {
    for (const int b : program.moved[static_cast<std::size_t>(s - 1)]) {
      const Pose& pn0 = cp.nominal_pose(b, s - 1);
      const Pose& pn1 = cp.nominal_pose(b, s);
      const Pose& fm0 = out.fm_of(b, s - 1);
      const Pose& fm1 = out.fm_of(b, s);
      const Pose pv0 = pn0 * fm0;
      const Pose pv1 = pn1 * fm1;
      ActionOutcome a;
      a.situation = s;
      a.body = b;
      a.nominal = pn1 * pn0.inverse();                           // (7.12)
      a.actual = pv1 * pv0.inverse();                            // (7.13)
      a.correction = pn0 * fm1 * fm0.inverse() * pn0.inverse();  // (7.15); TA = TN * TC
      a.intermediate = pv1 * pn1.inverse() * pn0;                // (7.17)
      a.step1 = a.intermediate * pv0.inverse();                  // Ta1
      a.step2 = pv1 * a.intermediate.inverse();                  // (7.18)
      out.actions.push_back(a);
    }
  }
  return out;
}

Result<std::vector<Reading>> parse_readings(const std::string& text, const std::string& origin) {
  auto doc = config::load_string(text, origin);
  if (!doc) {
    return doc.error();
  }
  config::MapReader root(*doc, doc->root, "");
  std::vector<Reading> out;
  const std::vector<YAML::Node> items = root.sequence("readings");
  for (std::size_t i = 0; i < items.size(); ++i) {
    const std::string name = fmt::format("readings[{}]", i);
    config::MapReader r = root.element(items[i], name);
    Reading reading;
    std::array<double, 2> p1{};
    std::array<double, 2> p2{};
    r.required("situation", reading.situation);
    r.required("body", reading.body);
    r.required("edge", reading.edge);
    r.required("camera", reading.camera);
    r.required("p1_mm", p1);
    r.required("p2_mm", p2);
    if (reading.situation < 1) {
      r.fail("situation", fmt::format("must be >= 1, got {}", reading.situation));
    }
    for (std::string* s : {&reading.body, &reading.edge, &reading.camera}) {
      std::transform(s->begin(), s->end(), s->begin(),
                     [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
    }
    reading.p1 = ImagePoint(p1[0], p1[1]);
    reading.p2 = ImagePoint(p2[0], p2[1]);
    reading.where = config::location(origin, items[i]);
    root.absorb(r);
    out.push_back(std::move(reading));
  }
  if (auto s = root.finish(); !s) {
    return s.error();
  }
  return out;
}

Result<std::vector<Reading>> load_readings(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Error{Errc::kIo, fmt::format("{}: cannot open the readings file", path)};
  }
  std::ostringstream text;
  text << in.rdbuf();
  return parse_readings(text.str(), path);
}

}  // namespace cell::rapt
