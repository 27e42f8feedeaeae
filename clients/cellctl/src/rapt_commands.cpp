// `cellctl rapt check|compile|run`: the RAPT compiler and run time (core/rapt), locally (no bus).
// Poses in the output are 4x4 matrices in the column-vector convention: the columns are the
// body's X, Y, Z axes in world coordinates and its translation (mm), i.e. world_T_body; the
// thesis prints their transposes.
#include <fmt/format.h>

#include <memory>
#include <nlohmann/json.hpp>
#include <string>

#include "cell/rapt/compiler.hpp"
#include "cell/rapt/runtime.hpp"
#include "commands.hpp"

namespace cell::cellctl {
namespace {

using nlohmann::json;

struct RaptArgs {
  std::string file;
  std::string readings;
  bool lsq = false;
};

json matrix(const rapt::Pose& pose) {
  json rows = json::array();
  for (int r = 0; r < 4; ++r) {
    json row = json::array();
    for (int c = 0; c < 4; ++c) {
      const double v = pose.matrix()(r, c);
      row.push_back(std::abs(v) < 1e-12 ? 0.0 : v);  // no "-0" or 1e-17 noise
    }
    rows.push_back(row);
  }
  return rows;
}

json point(const Eigen::Vector2d& p) { return json::array({p.x(), p.y()}); }

json window(const rapt::Window& w) {
  return json{{"p1", point(w.p1)},
              {"p2", point(w.p2)},
              {"p3", point(w.p3)},
              {"half_width", w.half_width},
              {"guaranteed", w.guaranteed}};
}

json diagnostics_json(const rapt::Diagnostics& diags) {
  json out = json::array();
  for (const rapt::Diagnostic& d : diags.items()) {
    out.push_back({{"severity", d.severity == rapt::Severity::kError ? "error" : "warning"},
                   {"line", d.loc.line},
                   {"column", d.loc.column},
                   {"message", d.message}});
  }
  return out;
}

const char* action_kind(rapt::ActionKind k) {
  switch (k) {
    case rapt::ActionKind::kStart:
      return "start";
    case rapt::ActionKind::kMove:
      return "move";
    case rapt::ActionKind::kTurn:
      return "turn";
    case rapt::ActionKind::kVision:
      return "vision";
  }
  return "?";
}

json mf_json(const rapt::CompiledProgram& cp, const rapt::MfArray& a) {
  json rows = json::array();
  for (int b = 1; b <= a.bodies(); ++b) {
    json entries = json::array();
    json named = json::array();
    for (int s = 1; s <= a.situations(); ++s) {
      entries.push_back(a.notation(b, s));
      named.push_back(a.named(b, s, cp.body_names));
    }
    rows.push_back({{"body", cp.body_names[static_cast<std::size_t>(b - 1)]},
                    {"number", b},
                    {"entries", entries},
                    {"named", named}});
  }
  return rows;
}

json compile_json(const rapt::CompiledProgram& cp, const rapt::Diagnostics& diags) {
  const rapt::Program& p = cp.program;
  json out;
  out["file"] = p.file;
  out["conventions"] = {
      {"pose",
       "4x4, column-vector convention: columns are the body's X, Y, Z axes in world "
       "coordinates, translation in the last column (mm): world_T_body. The thesis "
       "prints the transpose (rows X, Y, Z, translation)."},
      {"fm",
       "modifying factor in the body's nominal frame: world_T_actual = world_T_nominal * "
       "FM (the thesis's PV = FM ** PN)"},
      {"image", "image coordinates (y, z) in the unit of the camera's FOCUS (mm)"},
      {"mf_notation",
       "I identity; P verified position; B,S pointer to body B in situation S; "
       "[B,S] on body A in situation S: the triple [(A,S-1),(B,S-1),(B,S)]"}};
  json bodies = json::array();
  for (const rapt::Body& b : p.bodies) {
    json features = json::array();
    for (const rapt::Feature& f : b.features) {
      json feature{{"name", f.name},
                   {"type", rapt::to_string(f.type)},
                   {"body_T_feature", matrix(f.body_T_feature)}};
      if (f.radius > 0.0) {
        feature["radius_mm"] = f.radius;
      }
      if (f.length > 0.0) {
        feature["length_mm"] = f.length;
      }
      features.push_back(feature);
    }
    bodies.push_back({{"number", b.number}, {"name", b.name}, {"features", features}});
  }
  out["bodies"] = bodies;
  json situations = json::array();
  for (const rapt::Situation& s : p.situations) {
    json sit{{"number", s.number}, {"action", action_kind(s.action.kind)}};
    if (s.action.body > 0) {
      sit["body"] = p.body(s.action.body).name;
    }
    json moved = json::array();
    for (const int b : p.moved[static_cast<std::size_t>(s.number - 1)]) {
      moved.push_back(p.body(b).name);
    }
    sit["moved"] = moved;
    json ties = json::array();
    for (const auto& [a, b] : p.ties_after[static_cast<std::size_t>(s.number - 1)]) {
      ties.push_back(json::array({p.body(a).name, p.body(b).name}));
    }
    sit["ties_after"] = ties;
    situations.push_back(sit);
  }
  out["situations"] = situations;
  json nominal = json::array();
  for (const rapt::Body& b : p.bodies) {
    json per = json::array();
    for (int s = 1; s <= p.situation_count(); ++s) {
      per.push_back({{"situation", s}, {"world_T_body", matrix(cp.nominal_pose(b.number, s))}});
    }
    nominal.push_back({{"body", b.name}, {"number", b.number}, {"situations", per}});
  }
  out["nominal"] = nominal;
  out["mf_array"] = {{"before_simplification", mf_json(cp, cp.mf_before)},
                     {"after_simplification", mf_json(cp, cp.mf_after)}};
  json looks = json::array();
  json packages = json::array();
  for (const rapt::CompiledPackage& pkg : cp.packages) {
    packages.push_back({{"index", pkg.index},
                        {"situation", pkg.situation},
                        {"body", p.body(pkg.body).name},
                        {"fixable", pkg.fixable},
                        {"cannot_fix", pkg.cannot_fix},
                        {"route", rapt::route_text(p, pkg)},
                        {"scope", pkg.local ? "local" : "global"},
                        {"scope_reason", pkg.scope_reason},
                        {"tolerance_mm", pkg.tolerance_mm},
                        {"tolerance_source", pkg.tolerance_source},
                        {"combined_tolerance_mm",
                         json::array({pkg.combined_tolerance_mm.x(), pkg.combined_tolerance_mm.y(),
                                      pkg.combined_tolerance_mm.z()})}});
    for (const rapt::CompiledLook& look : pkg.looks) {
      looks.push_back(
          {{"package", pkg.index},
           {"situation", pkg.situation},
           {"body", p.body(look.decl.edge.body).name},
           {"edge", p.feature(look.decl.edge).name},
           {"camera", p.cameras[static_cast<std::size_t>(look.decl.camera)].name},
           {"line", look.decl.loc.line},
           {"used", look.used},
           {"note", look.note},
           {"predicted", json::array({point(look.predicted[0]), point(look.predicted[1])})},
           {"window", window(look.window)}});
    }
  }
  out["packages"] = packages;
  out["looks"] = looks;
  out["diagnostics"] = diagnostics_json(diags);
  return out;
}

/// The thesis's table layout of an MF array ("B\S 1 2 3 ...").
void print_mf(std::ostream& os, const rapt::CompiledProgram& cp, const rapt::MfArray& a) {
  os << fmt::format("{:>8}", "B\\S");
  for (int s = 1; s <= a.situations(); ++s) {
    os << fmt::format("{:>8}", s);
  }
  os << "\n";
  for (int b = 1; b <= a.bodies(); ++b) {
    os << fmt::format("{:>8}", cp.body_names[static_cast<std::size_t>(b - 1)]);
    for (int s = 1; s <= a.situations(); ++s) {
      os << fmt::format("{:>8}", a.notation(b, s));
    }
    os << "\n";
  }
}

std::string pose_text(const rapt::Pose& pose) {
  rapt::Pose p = pose;
  p.matrix() = p.matrix().unaryExpr([](double v) { return std::abs(v) < 1e-9 ? 0.0 : v; });
  const Eigen::Matrix3d r = p.linear();
  return fmt::format(
      "T ({:.6g}, {:.6g}, {:.6g}) mm, X ({:.7g}, {:.7g}, {:.7g}), Y ({:.7g}, {:.7g}, "
      "{:.7g}), Z ({:.7g}, {:.7g}, {:.7g})",
      p.translation().x(), p.translation().y(), p.translation().z(), r(0, 0), r(1, 0), r(2, 0),
      r(0, 1), r(1, 1), r(2, 1), r(0, 2), r(1, 2), r(2, 2));
}

/// Compiles args.file, printing diagnostics on stderr. Returns nullptr (after printing) on
/// failure and sets `code`.
std::unique_ptr<rapt::CompiledProgram> compile(Session& session,
                                               const std::string& file,
                                               rapt::Diagnostics& diags,
                                               int& code) {
  auto cp = rapt::compile_file(file, diags);
  for (const rapt::Diagnostic& d : diags.items()) {
    session.err() << diags.format(d) << "\n";
  }
  if (!cp) {
    if (cp.error().code == Errc::kIo) {
      code = session.fail(cp.error().message, kExitUsage);
    } else {
      code = session.fail(fmt::format("{}: {} error(s)", file, diags.error_count()));
    }
    return nullptr;
  }
  return std::make_unique<rapt::CompiledProgram>(std::move(*cp));
}

int check(Session& session, const RaptArgs& args) {
  rapt::Diagnostics diags(args.file);
  int code = kExitOk;
  auto cp = compile(session, args.file, diags, code);
  if (session.json()) {
    session.out() << json{{"file", args.file},
                          {"ok", cp != nullptr},
                          {"diagnostics", diagnostics_json(diags)}}
                         .dump(2)
                  << "\n";
  }
  return cp ? kExitOk : code;
}

int compile_cmd(Session& session, const RaptArgs& args) {
  rapt::Diagnostics diags(args.file);
  int code = kExitOk;
  auto cp = compile(session, args.file, diags, code);
  if (!cp) {
    if (session.json()) {
      session.out() << json{{"file", args.file}, {"diagnostics", diagnostics_json(diags)}}.dump(2)
                    << "\n";
    }
    return code;
  }
  if (session.json()) {
    session.out() << compile_json(*cp, diags).dump(2) << "\n";
    return kExitOk;
  }
  std::ostream& os = session.out();
  os << fmt::format("{}: {} bodies, {} situations, {} vision packages\n", args.file,
                    cp->program.body_count(), cp->program.situation_count(), cp->packages.size());
  for (const rapt::CompiledPackage& pkg : cp->packages) {
    os << fmt::format("situation {}: {} {} ({}, tolerance {} mm {})\n  {}\n", pkg.situation,
                      cp->program.body(pkg.body).name,
                      pkg.fixable ? "can be fixed" : "CANNOT be fixed: " + pkg.cannot_fix,
                      pkg.local ? "local" : "global", pkg.tolerance_mm, pkg.tolerance_source,
                      rapt::route_text(cp->program, pkg));
    for (const rapt::CompiledLook& look : pkg.looks) {
      os << fmt::format("  LOOK {} of {}, {}: ({:.7g}, {:.7g}) - ({:.7g}, {:.7g}){}\n",
                        cp->program.feature(look.decl.edge).name,
                        cp->program.body(look.decl.edge.body).name,
                        cp->program.cameras[static_cast<std::size_t>(look.decl.camera)].name,
                        look.predicted[0].x(), look.predicted[0].y(), look.predicted[1].x(),
                        look.predicted[1].y(), look.used ? "" : " [" + look.note + "]");
    }
  }
  os << "MF array before simplification:\n";
  print_mf(os, *cp, cp->mf_before);
  os << "MF array after simplification:\n";
  print_mf(os, *cp, cp->mf_after);
  return kExitOk;
}

int run_cmd(Session& session, const RaptArgs& args) {
  rapt::Diagnostics diags(args.file);
  int code = kExitOk;
  auto cp = compile(session, args.file, diags, code);
  if (!cp) {
    return code;
  }
  auto readings = rapt::load_readings(args.readings);
  if (!readings) {
    return session.fail(readings.error().message,
                        readings.error().code == Errc::kIo ? kExitUsage : kExitFailure);
  }
  rapt::RunOptions options;
  options.least_squares = args.lsq;
  auto result = rapt::run(*cp, *readings, options);
  if (!result) {
    if (session.json()) {
      session.out() << json{{"file", args.file}, {"error", result.error().message}}.dump(2) << "\n";
    }
    return session.fail(result.error().message);
  }
  const rapt::Program& p = cp->program;
  if (session.json()) {
    json out = compile_json(*cp, diags);
    out["readings"] = args.readings;
    for (std::size_t i = 0; i < result->packages.size(); ++i) {
      const rapt::PackageOutcome& po = result->packages[i];
      json& pkg = out["packages"][i];
      pkg["evaluated"] = po.evaluated;
      pkg["note"] = po.note;
      if (!po.evaluated) {
        continue;
      }
      pkg["verified_world_T_body"] = matrix(po.verified);
      pkg["fm"] = matrix(po.fm);
      json predicted = json::array();
      json windows = json::array();
      for (std::size_t k = 0; k < po.predicted.size(); ++k) {
        predicted.push_back(json::array({point(po.predicted[k][0]), point(po.predicted[k][1])}));
        windows.push_back(window(po.windows[k]));
      }
      pkg["run_time_predicted"] = predicted;
      pkg["run_time_window"] = windows;
      if (po.lsq) {
        const rapt::LsqReport& l = *po.lsq;
        json residuals = json::array();
        for (const auto& r : l.residuals) {
          residuals.push_back(json::array({r[0], r[1]}));
        }
        pkg["least_squares"] = {{"verified_world_T_body", matrix(l.verified)},
                                {"free_parameters", l.free_parameters},
                                {"residual_count", l.residual_count},
                                {"initial_rms", l.initial_rms},
                                {"final_rms", l.final_rms},
                                {"max_abs_residual", l.max_abs},
                                {"residuals", residuals},
                                {"shift_mm", l.shift_mm},
                                {"shift_rad", l.shift_rad},
                                {"converged", l.converged},
                                {"summary", l.brief()}};
      }
    }
    json actual = json::array();
    for (const rapt::Body& b : p.bodies) {
      json per = json::array();
      for (int s = 1; s <= p.situation_count(); ++s) {
        per.push_back({{"situation", s},
                       {"world_T_body", matrix(result->actual_pose(b.number, s))},
                       {"fm", matrix(result->fm_of(b.number, s))}});
      }
      actual.push_back({{"body", b.name}, {"number", b.number}, {"situations", per}});
    }
    out["actual"] = actual;
    json actions = json::array();
    for (const rapt::ActionOutcome& a : result->actions) {
      actions.push_back({{"situation", a.situation},
                         {"body", p.body(a.body).name},
                         {"nominal", matrix(a.nominal)},
                         {"actual", matrix(a.actual)},
                         {"method1_correction", matrix(a.correction)},
                         {"method2_intermediate", matrix(a.intermediate)},
                         {"method2_step1", matrix(a.step1)},
                         {"method2_step2", matrix(a.step2)}});
    }
    out["actions"] = actions;
    out["actions_convention"] =
        "motions in world axes, left-multiplying: world_T_after = motion * world_T_before "
        "(nominal TN, actual TA = one step, method 1: TA = TN * correction, method 2: step2 * "
        "step1)";
    session.out() << out.dump(2) << "\n";
    return kExitOk;
  }
  std::ostream& os = session.out();
  for (const rapt::PackageOutcome& po : result->packages) {
    const rapt::CompiledPackage& pkg = cp->packages[static_cast<std::size_t>(po.package)];
    if (!po.evaluated) {
      os << fmt::format("situation {}: {}\n", pkg.situation, po.note);
      continue;
    }
    os << fmt::format("situation {}: {} nominal  {}\n", pkg.situation, p.body(pkg.body).name,
                      pose_text(cp->nominal_pose(pkg.body, pkg.situation)));
    os << fmt::format("{:>13} verified {}\n", "", pose_text(po.verified));
    if (po.lsq) {
      os << fmt::format("{:>13} least squares: {}\n", "", po.lsq->brief());
    }
  }
  for (const rapt::ActionOutcome& a : result->actions) {
    const Eigen::Vector3d d = (a.actual.translation() - a.nominal.translation());
    os << fmt::format(
        "action into situation {}: {} corrected by ({:.4g}, {:.4g}, {:.4g}) mm, "
        "{:.4g} deg\n",
        a.situation, p.body(a.body).name, d.x(), d.y(), d.z(),
        rapt::rotation_angle(a.actual.linear(), a.nominal.linear()) * 180.0 / M_PI);
  }
  return kExitOk;
}

}  // namespace

void add_rapt_commands(CLI::App& app, Commands& commands) {
  auto args = std::make_shared<RaptArgs>();
  CLI::App* rapt = app.add_subcommand("rapt", "the RAPT compiler and run time (local)");
  rapt->require_subcommand(1);
  CLI::App* check_cmd = rapt->add_subcommand("check", "report the errors of a RAPT program");
  check_cmd->add_option("file", args->file, "RAPT program")->required();
  CLI::App* compile_sub =
      rapt->add_subcommand("compile", "nominal positions, MF array, LOOK predictions");
  compile_sub->add_option("file", args->file, "RAPT program")->required();
  CLI::App* run_sub = rapt->add_subcommand("run", "verified and actual positions from readings");
  run_sub->add_option("file", args->file, "RAPT program")->required();
  run_sub->add_option("--readings", args->readings, "readings YAML (image end points per LOOK)")
      ->required();
  run_sub->add_flag("--lsq", args->lsq,
                    "also evaluate every package by least squares over all its LOOKs");
  commands.add(check_cmd, [args](Session& s) { return check(s, *args); });
  commands.add(compile_sub, [args](Session& s) { return compile_cmd(s, *args); });
  commands.add(run_sub, [args](Session& s) { return run_cmd(s, *args); });
}

}  // namespace cell::cellctl
