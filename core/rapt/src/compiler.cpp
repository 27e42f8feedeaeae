#include "cell/rapt/compiler.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <fstream>
#include <sstream>

#include "cell/rapt/parser.hpp"
#include "cell/rapt/sema.hpp"

namespace cell::rapt {

const Pose& CompiledProgram::nominal_pose(int body, int situation) const {
  static const Pose kIdentity = Pose::Identity();
  const std::optional<Pose>& p = nominal.pose(body, situation);
  return p ? *p : kIdentity;
}

LinkInput link_input(const Program& program, const std::vector<CompiledPackage>& packages) {
  LinkInput in;
  in.bodies = program.body_count();
  in.situations = program.situation_count();
  in.events.resize(static_cast<std::size_t>(in.situations));
  in.changes.resize(static_cast<std::size_t>(in.situations));
  for (int s = 2; s <= in.situations; ++s) {
    const Action& act = program.situation(s).action;
    LinkEvent& ev = in.events[static_cast<std::size_t>(s - 1)];
    ev.loc = act.loc;
    if ((act.kind == ActionKind::kMove || act.kind == ActionKind::kTurn) && act.body > 0) {
      ev.kind = LinkEvent::Kind::kMove;
      ev.body = act.body;
    } else if (act.kind == ActionKind::kVision && act.package >= 0 && act.body > 0) {
      const Package& pk = program.packages[static_cast<std::size_t>(act.package)];
      ev.kind = LinkEvent::Kind::kVision;
      ev.body = act.body;
      ev.package = act.package;
      ev.fixable = static_cast<std::size_t>(act.package) < packages.size() &&
                   packages[static_cast<std::size_t>(act.package)].fixable;
      for (const InviolateDecl& inv : pk.inviolates) {
        ev.inviolate_references.push_back(inv.reference.body);
      }
      for (const LookDecl& look : pk.looks) {
        const Camera& cam = program.cameras[static_cast<std::size_t>(look.camera)];
        if (cam.general) {
          ev.camera_bodies.push_back(cam.body);
        }
      }
    }
  }
  // Specified actions (thesis §7.3.2.2): a relation between X and Y in situation u specifies
  // the destination of whichever of the two moved last (not moving again until u), relative to
  // the other; if they last moved in the same action they are tied and the relation describes
  // the TIE, not a destination.
  std::vector<int> last(static_cast<std::size_t>(program.body_count() + 1), 1);
  for (int u = 1; u <= in.situations; ++u) {
    for (const int b : program.moved[static_cast<std::size_t>(u - 1)]) {
      last[static_cast<std::size_t>(b)] = u;
    }
    for (const RelationDecl& rel : program.situation(u).relations) {
      const int x = rel.a.body;
      const int y = rel.b.body;
      const int lx = last[static_cast<std::size_t>(x)];
      const int ly = last[static_cast<std::size_t>(y)];
      if (lx == ly) {
        continue;
      }
      const int mover = lx > ly ? x : y;
      const int reference = lx > ly ? y : x;
      LinkEvent& ev = in.events[static_cast<std::size_t>(std::max(lx, ly) - 1)];
      if (ev.kind != LinkEvent::Kind::kMove) {
        continue;
      }
      if (!ev.specified) {
        ev.specified = true;
        ev.referenced_member = mover;
      }
      ev.references.push_back(reference);
    }
  }
  // TIE and subassembly links.
  for (const Subassembly& sa : program.subassemblies) {
    if (!sa.permanent || sa.bodies.empty()) {
      continue;
    }
    for (std::size_t i = 1; i < sa.bodies.size(); ++i) {
      in.changes[0].push_back(LinkChange{true, sa.bodies.front(), sa.bodies[i], true});
    }
  }
  for (int s = 1; s <= in.situations; ++s) {
    const Situation& sit = program.situation(s);
    auto& changes = in.changes[static_cast<std::size_t>(s - 1)];
    for (const TieChange& c : sit.tie_changes) {
      changes.push_back(LinkChange{c.tied, c.a, c.b, false});
    }
    for (const SubassChange& c : sit.subass_changes) {
      const Subassembly& sa = program.subassemblies[static_cast<std::size_t>(c.subassembly)];
      for (std::size_t i = 1; i < sa.bodies.size(); ++i) {
        changes.push_back(LinkChange{c.on, sa.bodies.front(), sa.bodies[i], false});
      }
    }
  }
  return in;
}

Result<CompiledProgram> compile(std::string_view source,
                                const std::string& file,
                                Diagnostics& diags,
                                const CompileOptions& options) {
  const ast::Program tree = parse(source, diags);
  CompiledProgram out;
  out.program = analyze(tree, file, diags);
  if (diags.has_errors()) {
    return diags.to_error();
  }
  out.nominal = infer_nominal(out.program, diags, options.nominal);
  // Packages are compiled even after inference errors: a package whose INVIOLATE reference has
  // no determined position says so at the INVIOLATE ("not fixed in the world").
  for (int i = 0; i < static_cast<int>(out.program.packages.size()); ++i) {
    out.packages.push_back(compile_package(out.program, out.nominal, i, options.vision, diags));
  }
  if (diags.has_errors()) {
    return diags.to_error();
  }
  for (const Body& b : out.program.bodies) {
    out.body_names.push_back(b.name);
  }
  out.link = link(link_input(out.program, out.packages), out.body_names);
  for (const auto& [loc, message] : out.link.warnings) {
    diags.warning(loc, message);
  }
  for (const PackageScope& scope : out.link.scopes) {
    if (scope.package >= 0 && static_cast<std::size_t>(scope.package) < out.packages.size()) {
      out.packages[static_cast<std::size_t>(scope.package)].local = scope.local;
      out.packages[static_cast<std::size_t>(scope.package)].scope_reason = scope.reason;
    }
  }
  out.mf_before = out.link.array;
  out.mf_after = simplify(out.mf_before);
  return out;
}

Result<CompiledProgram> compile_file(const std::string& path,
                                     Diagnostics& diags,
                                     const CompileOptions& options) {
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    return Error{Errc::kIo, fmt::format("{}: cannot open the RAPT program", path)};
  }
  std::ostringstream text;
  text << in.rdbuf();
  return compile(text.str(), path, diags, options);
}

}  // namespace cell::rapt
