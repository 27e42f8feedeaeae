// rapt_bench: the cost of the RAPT compiler and run time (core/rapt) on the thesis's programs.
//
//   rapt_bench [--benchmark_filter=REGEX] [--benchmark_format=json] ...   (Google Benchmark)
//
// Programs: config/rapt/appendix_v.rapt (4 bodies, 16 situations, 4 vision packages) and
// appendix_vi.rapt, readings config/rapt/appendix_v_readings.yaml, all read once before timing.
//   Compile/*        whole compile: lex, parse, semantic analysis, cycle finder, packages
//                    (predictions, windows, symbolic routes), MF linking and simplification
//   Stage/*          the front-end stages alone (Appendix V)
//   Evaluate/<sit>   one package's symbolic route at run time (face generator + rule functions
//                    + merge), the thesis's "run-time evaluation per package"
//   Run/AppendixV    a whole run: every package, the MF array resolved for 4 x 16 instances,
//                    actual positions and corrected actions
//   LeastSquares/<sit>  the Ceres evaluation over every end point (beyond the thesis)
#include <benchmark/benchmark.h>

#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>

#include "cell/rapt/compiler.hpp"
#include "cell/rapt/parser.hpp"
#include "cell/rapt/runtime.hpp"
#include "cell/rapt/sema.hpp"

namespace {

using namespace cell::rapt;

std::string read(const std::string& relative) {
  std::ifstream in(std::filesystem::path(CELL_SOURCE_DIR) / relative);
  std::ostringstream s;
  s << in.rdbuf();
  return s.str();
}

const std::string& appendix_v_text() {
  static const std::string text = read("config/rapt/appendix_v.rapt");
  return text;
}

const CompiledProgram& appendix_v() {
  static const CompiledProgram cp = [] {
    Diagnostics d;
    return *compile(appendix_v_text(), "appendix_v.rapt", d);
  }();
  return cp;
}

const std::vector<Reading>& readings() {
  static const std::vector<Reading> r =
      *load_readings(CELL_SOURCE_DIR "/config/rapt/appendix_v_readings.yaml");
  return r;
}

/// The run-time inputs of package `index` with the thesis's readings (nominal references and
/// cameras: the state the thesis's run had for these packages).
RouteInputs inputs(const CompiledProgram& cp, int index) {
  const CompiledPackage& pkg = cp.packages[static_cast<std::size_t>(index)];
  const Package& decl = cp.program.packages[static_cast<std::size_t>(index)];
  RouteInputs in;
  in.world_T_nominal = cp.nominal_pose(pkg.body, pkg.situation);
  for (const InviolateDecl& inv : decl.inviolates) {
    in.world_T_reference.push_back(cp.nominal_pose(inv.reference.body, pkg.situation - 1));
  }
  for (const LookDecl& look : decl.looks) {
    const Camera& cam = cp.program.cameras[static_cast<std::size_t>(look.camera)];
    in.cameras.push_back(CameraModel{cam.world_T_camera, cam.focus});
    std::optional<std::pair<ImagePoint, ImagePoint>> reading;
    for (const Reading& r : readings()) {
      if (r.situation == pkg.situation && r.edge == cp.program.feature(look.edge).name &&
          r.camera == cam.name) {
        reading = std::pair{r.p1, r.p2};
      }
    }
    in.readings.push_back(reading);
  }
  return in;
}

void BM_Compile(benchmark::State& state, const std::string& file) {
  const std::string text = read(file);
  for (auto _ : state) {
    Diagnostics d;
    auto cp = compile(text, file, d);
    benchmark::DoNotOptimize(cp);
    if (!cp) {
      state.SkipWithError("does not compile");
      break;
    }
  }
}
BENCHMARK_CAPTURE(BM_Compile, AppendixV, std::string("config/rapt/appendix_v.rapt"))
    ->Unit(benchmark::kMicrosecond);
BENCHMARK_CAPTURE(BM_Compile, AppendixVI, std::string("config/rapt/appendix_vi.rapt"))
    ->Unit(benchmark::kMicrosecond);

void BM_StageParse(benchmark::State& state) {
  for (auto _ : state) {
    Diagnostics d;
    benchmark::DoNotOptimize(parse(appendix_v_text(), d));
  }
}
BENCHMARK(BM_StageParse)->Name("Stage/LexParse")->Unit(benchmark::kMicrosecond);

void BM_StageSema(benchmark::State& state) {
  Diagnostics d0;
  const ast::Program tree = parse(appendix_v_text(), d0);
  for (auto _ : state) {
    Diagnostics d;
    benchmark::DoNotOptimize(analyze(tree, "appendix_v.rapt", d));
  }
}
BENCHMARK(BM_StageSema)->Name("Stage/Semantics")->Unit(benchmark::kMicrosecond);

void BM_StageNominal(benchmark::State& state) {
  const Program& p = appendix_v().program;
  for (auto _ : state) {
    Diagnostics d;
    benchmark::DoNotOptimize(infer_nominal(p, d));
  }
}
BENCHMARK(BM_StageNominal)->Name("Stage/CycleFinder")->Unit(benchmark::kMicrosecond);

void BM_StageLink(benchmark::State& state) {
  const CompiledProgram& cp = appendix_v();
  const LinkInput in = link_input(cp.program, cp.packages);
  for (auto _ : state) {
    benchmark::DoNotOptimize(simplify(link(in, cp.body_names).array));
  }
}
BENCHMARK(BM_StageLink)->Name("Stage/MfLinkAndSimplify")->Unit(benchmark::kMicrosecond);

void BM_Evaluate(benchmark::State& state) {
  const CompiledProgram& cp = appendix_v();
  const int index = static_cast<int>(state.range(0));
  const RouteInputs in = inputs(cp, index);
  const CompiledPackage& pkg = cp.packages[static_cast<std::size_t>(index)];
  for (auto _ : state) {
    auto pv = evaluate_route(cp.program, pkg, in);
    benchmark::DoNotOptimize(pv);
  }
  state.SetLabel("situation " + std::to_string(pkg.situation));
}
BENCHMARK(BM_Evaluate)->Name("Evaluate")->DenseRange(0, 3)->Unit(benchmark::kMicrosecond);

void BM_Run(benchmark::State& state) {
  const CompiledProgram& cp = appendix_v();
  for (auto _ : state) {
    auto r = run(cp, readings());
    benchmark::DoNotOptimize(r);
  }
}
BENCHMARK(BM_Run)->Name("Run/AppendixV")->Unit(benchmark::kMicrosecond);

void BM_LeastSquares(benchmark::State& state) {
  const CompiledProgram& cp = appendix_v();
  const int index = static_cast<int>(state.range(0));
  const RouteInputs in = inputs(cp, index);
  const CompiledPackage& pkg = cp.packages[static_cast<std::size_t>(index)];
  const Pose start = *evaluate_route(cp.program, pkg, in);
  for (auto _ : state) {
    auto r = least_squares(cp.program, pkg, in, start);
    benchmark::DoNotOptimize(r);
  }
  state.SetLabel("situation " + std::to_string(pkg.situation));
}
BENCHMARK(BM_LeastSquares)->Name("LeastSquares")->DenseRange(0, 3)->Unit(benchmark::kMicrosecond);

}  // namespace

BENCHMARK_MAIN();
