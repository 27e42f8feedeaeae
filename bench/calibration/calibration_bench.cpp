// calibration_bench: core/calibration against OpenCV on the same data, on renders through the
// simulator's TRUE cameras (config/cameras/): accuracy over seeded trials and time per call.
//   intrinsics: the belt camera (1024 x 1024) and the 7545's (512 x 484), 20 views, 0.2 px of
//     corner noise: Ceres vs cv::calibrateCamera (five coefficients, and k3 fixed);
//   hand-eye: the Excalibur eye-in-hand (0.05 deg and 0.1 mm of robot noise per axis, 0.2 px):
//     Ceres's joint refinement vs OpenCV's Tsai, Park, Daniilidis (and the rest);
//   detection, the planar model's refinement, the belt fit: time per call.
// bench/README.md, section calibration, explains the runs and the numbers.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <exception>
#include <functional>
#include <numbers>
#include <random>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>
#include <fmt/format.h>
#include <nlohmann/json.hpp>
#include <opencv2/calib3d.hpp>

#include "cell/calibration/belt_calibration.hpp"
#include "cell/calibration/board.hpp"
#include "cell/calibration/hand_eye.hpp"
#include "cell/calibration/intrinsics.hpp"
#include "cell/calibration/planar_model.hpp"
#include "cell/geometry/angles.hpp"
#include "sim_views.hpp"

namespace cell::bench {
namespace {

namespace cal = cell::calibration;
using nlohmann::json;
using Clock = std::chrono::steady_clock;
using geometry::kDeg;

struct Stats {
  std::vector<double> v;
  void add(double x) { v.push_back(x); }
  double median() const {
    std::vector<double> s = v;
    std::sort(s.begin(), s.end());
    return s.empty() ? 0.0 : s[s.size() / 2];
  }
  double max() const { return v.empty() ? 0.0 : *std::max_element(v.begin(), v.end()); }
  double mean() const {
    double s = 0;
    for (double x : v) {
      s += x;
    }
    return v.empty() ? 0.0 : s / static_cast<double>(v.size());
  }
  double rms() const {
    double s = 0;
    for (double x : v) {
      s += x * x;
    }
    return v.empty() ? 0.0 : std::sqrt(s / static_cast<double>(v.size()));
  }
  double fraction_below(double limit) const {
    return v.empty() ? 0.0
                     : static_cast<double>(std::count_if(v.begin(), v.end(),
                                                         [&](double x) { return x < limit; })) /
                           static_cast<double>(v.size());
  }
};

double ms_since(Clock::time_point t0) {
  return std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
}

/// Median time of `fn` over `reps` runs [ms].
double time_ms(int reps, const std::function<void()>& fn) {
  Stats s;
  for (int i = 0; i < reps; ++i) {
    const auto t0 = Clock::now();
    fn();
    s.add(ms_since(t0));
  }
  return s.median();
}

struct CvFit {
  render::CameraModel camera;
  double rms = 0.0;
};

CvFit opencv_calibrate(const std::vector<cal::BoardView>& views, const std::vector<bool>& use,
                       int w, int h, int flags) {
  std::vector<std::vector<cv::Point3f>> object;
  std::vector<std::vector<cv::Point2f>> image;
  for (std::size_t i = 0; i < views.size(); ++i) {
    if (!use[i]) {
      continue;
    }
    std::vector<cv::Point3f> o;
    std::vector<cv::Point2f> m;
    for (std::size_t k = 0; k < views[i].observation.size(); ++k) {
      const auto& p = views[i].observation.object_points[k];
      const auto& q = views[i].observation.image_points[k];
      o.emplace_back(static_cast<float>(p.x()), static_cast<float>(p.y()), 0.0F);
      m.emplace_back(static_cast<float>(q.x()), static_cast<float>(q.y()));
    }
    object.push_back(o);
    image.push_back(m);
  }
  cv::Mat k;
  cv::Mat d;
  std::vector<cv::Mat> rv;
  std::vector<cv::Mat> tv;
  const double rms = cv::calibrateCamera(object, image, cv::Size(w, h), k, d, rv, tv, flags);
  auto cam = render::CameraModel::create(
      w, h, k.at<double>(0, 0), k.at<double>(1, 1), k.at<double>(0, 2), k.at<double>(1, 2),
      {d.at<double>(0), d.at<double>(1), d.at<double>(2), d.at<double>(3), d.at<double>(4)});
  return {cam.value_or(render::CameraModel{}), rms};
}

struct IntrinsicErrors {
  Stats fx_rel, fy_rel, cx, cy, rms, time_ms;
  int within_issue = 0;  // fx, fy within 0.2 %, cx, cy within 1 px
  void add(const render::CameraModel& truth, const render::CameraModel& fit, double rms_px,
           double t_ms) {
    const double efx = std::abs(fit.fx_px() - truth.fx_px()) / truth.fx_px();
    const double efy = std::abs(fit.fy_px() - truth.fy_px()) / truth.fy_px();
    const double ecx = std::abs(fit.cx_px() - truth.cx_px());
    const double ecy = std::abs(fit.cy_px() - truth.cy_px());
    fx_rel.add(efx);
    fy_rel.add(efy);
    cx.add(ecx);
    cy.add(ecy);
    rms.add(rms_px);
    time_ms.add(t_ms);
    within_issue += (efx < 0.002 && efy < 0.002 && ecx < 1.0 && ecy < 1.0) ? 1 : 0;
  }
  json to_json(int trials) const {
    return json{{"fx_err_pct_median", 100 * fx_rel.median()}, {"fx_err_pct_max", 100 * fx_rel.max()},
                {"fy_err_pct_median", 100 * fy_rel.median()}, {"fy_err_pct_max", 100 * fy_rel.max()},
                {"cx_err_px_rms", cx.rms()},                  {"cx_err_px_max", cx.max()},
                {"cy_err_px_rms", cy.rms()},                  {"cy_err_px_max", cy.max()},
                {"rms_px_mean", rms.mean()},                  {"time_ms_median", time_ms.median()},
                {"within_issue_bounds", fmt::format("{}/{}", within_issue, trials)}};
  }
  std::string row(const std::string& name, int trials) const {
    return fmt::format("| {:<24} | {:.3f} / {:.3f} | {:.3f} / {:.3f} | {:.2f} / {:.2f} | {:.2f} / "
                       "{:.2f} | {:.4f} | {:>2}/{:<2} | {:.1f} |",
                       name, 100 * fx_rel.median(), 100 * fx_rel.max(), 100 * fy_rel.median(),
                       100 * fy_rel.max(), cx.rms(), cx.max(), cy.rms(), cy.max(), rms.mean(),
                       within_issue, trials, time_ms.median());
  }
};

json intrinsics_bench(const std::string& file, const cal::BoardSpec& board, double depth,
                      int trials) {
  const render::CameraDescription camera = cal::testing::camera_file(file);
  const render::CameraModel& truth = camera.truth.model;
  // Render and detect once; each trial adds its own corner noise (0.2 px per coordinate).
  const auto clean = cal::testing::intrinsics_views(camera, board, 20, depth, 0.0, 7);
  IntrinsicErrors ceres;
  IntrinsicErrors cv5;
  IntrinsicErrors cv4;
  std::mt19937_64 rng(99);
  for (int t = 0; t < trials; ++t) {
    std::vector<cal::BoardView> views = clean;
    for (auto& v : views) {
      cal::testing::add_corner_noise(v.observation, 0.2, rng);
    }
    auto t0 = Clock::now();
    auto r = cal::calibrate_intrinsics(views, truth.width_px(), truth.height_px());
    const double t_ceres = ms_since(t0);
    if (!r) {
      std::fprintf(stderr, "calibration_bench: error: %s\n", r.error().message.c_str());
      continue;
    }
    ceres.add(truth, r->camera, r->rms_px, t_ceres);
    std::vector<bool> use;
    for (const auto& v : r->views) {
      use.push_back(v.used);
    }
    t0 = Clock::now();
    const CvFit a = opencv_calibrate(views, use, truth.width_px(), truth.height_px(), 0);
    cv5.add(truth, a.camera, a.rms, ms_since(t0));
    t0 = Clock::now();
    const CvFit b = opencv_calibrate(views, use, truth.width_px(), truth.height_px(),
                                     cv::CALIB_FIX_K3);
    cv4.add(truth, b.camera, b.rms, ms_since(t0));
  }
  std::printf("\nintrinsics, %s: %d trials, 20 views (16 fitted), %s, 0.2 px noise\n",
              file.c_str(), trials, board.describe().c_str());
  std::printf("| %-24s | fx err %% med/max | fy err %% med/max | cx err px rms/max | cy err px "
              "rms/max | RMS px | within | ms |\n",
              "solver");
  std::printf("|---|---|---|---|---|---|---|---|\n");
  std::printf("%s\n%s\n%s\n", ceres.row("cell (Ceres, k3 = 0)", trials).c_str(),
              cv5.row("cv::calibrateCamera", trials).c_str(),
              cv4.row("cv::calibrateCamera FIX_K3", trials).c_str());
  return json{{"camera", file},
              {"trials", trials},
              {"ceres", ceres.to_json(trials)},
              {"opencv", cv5.to_json(trials)},
              {"opencv_fix_k3", cv4.to_json(trials)}};
}

struct HandEyeSettings {
  int poses = 30;
  double min_elevation_deg = 25.0;  // views from this far above the table ...
  double max_elevation_deg = 65.0;  // ... up to this
  bool exact_robot = false;  // fit with the robot poses taken as exact (no correction prior)
  double rotation_sigma_deg = 0.05;
  double translation_sigma_mm = 0.1;
};

json hand_eye_bench(int trials, const HandEyeSettings& settings) {
  // Poses, renders and detections once; each trial adds robot and corner noise.
  const cal::testing::HandEyeScenario clean =
      cal::testing::excalibur_eye_in_hand(settings.poses, 0, 0, 0, 11,
                                          settings.min_elevation_deg, settings.max_elevation_deg);
  cal::HandEyeOptions options = clean.options;
  options.robot_rotation_sigma_deg = settings.exact_robot ? 0.0 : settings.rotation_sigma_deg;
  options.robot_translation_sigma_mm = settings.exact_robot ? 0.0 : settings.translation_sigma_mm;
  struct Method {
    std::string name;
    Stats rot, trans, time;
  };
  std::vector<Method> methods = {{"cell (Ceres joint)", {}, {}, {}}};
  for (const cal::HandEyeMethod m :
       {cal::HandEyeMethod::kTsai, cal::HandEyeMethod::kPark, cal::HandEyeMethod::kHoraud,
        cal::HandEyeMethod::kAndreff, cal::HandEyeMethod::kDaniilidis, cal::HandEyeMethod::kShah,
        cal::HandEyeMethod::kLi}) {
    methods.push_back({std::string("OpenCV ") + std::string(cal::to_string(m)), {}, {}, {}});
  }
  std::mt19937_64 rng(5);
  int within = 0;
  for (int t = 0; t < trials; ++t) {
    std::vector<cal::HandEyeSample> samples = clean.samples;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      samples[i].base_T_mount = cal::testing::noisy_pose(
          clean.true_mount[i], settings.rotation_sigma_deg, settings.translation_sigma_mm, false,
          rng);
      cal::testing::add_corner_noise(samples[i].observation, 0.2, rng);
    }
    auto t0 = Clock::now();
    auto r = cal::calibrate_hand_eye(samples, clean.camera, options);
    const double t_ms = ms_since(t0);
    if (!r) {
      std::fprintf(stderr, "calibration_bench: error: %s\n", r.error().message.c_str());
      continue;
    }
    const double rot = cal::testing::rotation_error_rad(r->camera_extrinsics.linear(),
                                                        clean.truth_extrinsics.linear()) / kDeg;
    const double trans =
        (r->camera_extrinsics.translation() - clean.truth_extrinsics.translation()).norm();
    methods[0].rot.add(rot);
    methods[0].trans.add(trans);
    methods[0].time.add(t_ms);
    within += (rot < 0.05 && trans < 0.2) ? 1 : 0;
    // OpenCV on the fitted samples (the same corners and poses), timed alone.
    std::vector<cal::HandEyeSample> fitted;
    for (std::size_t i = 0; i < samples.size(); ++i) {
      if (r->samples[i].used) {
        fitted.push_back(samples[i]);
      }
    }
    for (std::size_t m = 0; m < 7; ++m) {
      t0 = Clock::now();
      auto x = cal::opencv_hand_eye(fitted, clean.camera, clean.options.setup,
                                    static_cast<cal::HandEyeMethod>(m));
      const double tm = ms_since(t0);
      if (!x) {
        continue;
      }
      methods[m + 1].rot.add(cal::testing::rotation_error_rad(x->linear(),
                                                              clean.truth_extrinsics.linear()) /
                             kDeg);
      methods[m + 1].trans.add((x->translation() - clean.truth_extrinsics.translation()).norm());
      methods[m + 1].time.add(tm);
    }
  }
  std::printf("\nhand-eye, Excalibur eye-in-hand: %d trials, %d poses seen from %.0f-%.0f deg "
              "above the table, robot noise %.3f deg + %.3f mm per axis, 0.2 px%s\n",
              trials, settings.poses, settings.min_elevation_deg, settings.max_elevation_deg,
              settings.rotation_sigma_deg, settings.translation_sigma_mm,
              settings.exact_robot ? " (fit with the robot taken as exact)" : "");
  std::printf("| method | rotation deg median / max | translation mm median / max | ms |\n");
  std::printf("|---|---|---|---|\n");
  json out = json::array();
  for (const Method& m : methods) {
    std::printf("| %s | %.4f / %.4f | %.3f / %.3f | %.2f |\n", m.name.c_str(), m.rot.median(),
                m.rot.max(), m.trans.median(), m.trans.max(), m.time.median());
    out.push_back(json{{"method", m.name},
                       {"rotation_deg_median", m.rot.median()},
                       {"rotation_deg_max", m.rot.max()},
                       {"translation_mm_median", m.trans.median()},
                       {"translation_mm_max", m.trans.max()},
                       {"time_ms_median", m.time.median()}});
  }
  std::printf("cell within the issue's bounds (0.05 deg, 0.2 mm): %d/%d trials\n", within, trials);
  return json{{"trials", trials},
              {"poses", settings.poses},
              {"elevation_deg", {settings.min_elevation_deg, settings.max_elevation_deg}},
              {"rotation_sigma_deg", settings.rotation_sigma_deg},
              {"translation_sigma_mm", settings.translation_sigma_mm},
              {"exact_robot", settings.exact_robot},
              {"methods", out},
              {"within_issue_bounds", within}};
}

json timings(int reps) {
  json out;
  // Detection: a 9x6 board in the 7545's frame (white table around it) and a 25x17 in the
  // belt camera's.
  const render::CameraDescription eye = cal::testing::camera_file("ibm7545_eye.yaml");
  cal::BoardSpec b96;
  b96.columns = 9;
  b96.rows = 6;
  b96.square_mm = 10.0;
  render::Scene scene;
  scene.table_height_mm = -5000.0;
  scene.lights.fluorescent_on = false;
  scene.targets.push_back(cal::testing::chessboard_target(
      b96, cal::testing::board_facing_camera(b96, {0, 0, 420}, 0.2, 0.3, -0.2)));
  render::Lighting light;
  light.ambient = 0.7;
  const cv::Mat image = cal::testing::render_view(eye.truth.model, light, scene,
                                                  Eigen::Isometry3d::Identity(), 1.0, 1);
  const double detect = time_ms(reps, [&] { (void)cal::detect_board(image, b96); });
  out["detect_chessboard_9x6_512x484_ms"] = detect;
  // The planar model: 40 views of 48 points.
  cal::PlanarParameters p;
  p.c_x_px_per_mm = 3.56;
  p.c_y_px_per_mm = 3.48;
  p.ref_u_px = 3;
  p.ref_v_px = 457;
  p.center_u_px = 255;
  p.center_v_px = 241;
  p.d_t_c_mm = 81.8;
  p.b_angl_rad = 137.7 * kDeg;
  p.angl_err_rad = 1.8 * kDeg;
  p.link1_mm = 400;
  p.link2_mm = 250;
  std::vector<cal::PlanarView> views;
  std::mt19937_64 rng(3);
  std::normal_distribution<double> n(0.0, 0.2);
  for (int v = 0; v < 40; ++v) {
    cal::PlanarView view;
    view.id = std::to_string(v);
    view.j1_rad = 45 * kDeg + 0.1 * std::sin(v);
    view.j2_rad = 105 * kDeg + 0.12 * std::cos(1.3 * v);
    for (int i = 0; i < 8; ++i) {
      for (int j = 0; j < 6; ++j) {
        const Eigen::Vector2d q(90.0 + 6 * i, 470.0 + 6 * j);
        view.pixels.push_back(cal::planar_base_to_pixel(p, view.j1_rad, view.j2_rad, q) +
                              Eigen::Vector2d(n(rng), n(rng)));
        view.target_points_mm.push_back(q);
      }
    }
    views.push_back(view);
  }
  cal::PlanarOptions po;
  po.target_in_base = true;
  out["planar_refine_40_views_ms"] = time_ms(reps, [&] { (void)cal::refine_planar(p, views, po); });
  // The belt: 30 samples of 3 parts.
  std::vector<cal::BeltObservation> belt;
  for (int part = 0; part < 3; ++part) {
    for (int k = 0; k < 10; ++k) {
      const std::int64_t c = 1000 + 1000 * k;
      belt.push_back({fmt::format("{}-{}", part, k), std::to_string(part), c, 0,
                      Eigen::Vector3d(300.0 + 50.0 * part, 200.0 - 0.03835 * static_cast<double>(c), -195.0) +
                          Eigen::Vector3d(n(rng), n(rng), 0) * 0.05});
    }
  }
  out["belt_fit_30_samples_ms"] = time_ms(reps, [&] { (void)cal::calibrate_belt(belt, "b", "r"); });
  std::printf("\ntimes (median of %d): board detection (9x6, 512x484) %.2f ms; planar refinement "
              "(40 views x 48 points) %.2f ms; belt fit (30 samples) %.3f ms\n",
              reps, detect, out["planar_refine_40_views_ms"].get<double>(),
              out["belt_fit_30_samples_ms"].get<double>());
  return out;
}

}  // namespace
}  // namespace cell::bench

static int main_body(int argc, char** argv) {
  CLI::App app("calibration_bench: core/calibration against OpenCV on renders with known truth");
  bool quick = false;
  bool as_json = false;
  int trials = 30;
  app.add_flag("--quick", quick, "a few trials (the ctest smoke run)");
  app.add_flag("--json", as_json, "results as JSON on stdout");
  app.add_option("--trials", trials, "seeded trials per comparison (default 30)");
  cell::bench::HandEyeSettings he;
  app.add_option("--hand-eye-poses", he.poses, "poses per hand-eye data set (default 30)");
  app.add_option("--min-elevation-deg", he.min_elevation_deg, "lowest view above the table");
  app.add_option("--max-elevation-deg", he.max_elevation_deg, "highest view above the table");
  app.add_flag("--hand-eye-exact-robot", he.exact_robot,
               "fit hand-eye with the robot poses as exact (no correction prior)");
  app.add_option("--robot-rotation-sigma-deg", he.rotation_sigma_deg,
                 "robot rotation noise per axis (default 0.05)");
  app.add_option("--robot-translation-sigma-mm", he.translation_sigma_mm,
                 "robot translation noise per axis (default 0.1)");
  bool only_hand_eye = false;
  app.add_flag("--hand-eye-only", only_hand_eye, "only the hand-eye comparison");
  CLI11_PARSE(app, argc, argv);
  if (quick) {
    trials = 2;
  }
  if (trials < 1) {
    std::fprintf(stderr, "calibration_bench: error: --trials must be >= 1\n");
    return 2;
  }
  using cell::calibration::BoardSpec;
  BoardSpec belt_board;
  belt_board.columns = 25;
  belt_board.rows = 17;
  belt_board.square_mm = 15.0;
  BoardSpec eye_board;
  eye_board.columns = 17;
  eye_board.rows = 12;
  eye_board.square_mm = 6.0;
  nlohmann::json out;
  if (!only_hand_eye) {
    out["intrinsics"] = {
        cell::bench::intrinsics_bench("belt_cam.yaml", belt_board, 1000.0, trials),
        cell::bench::intrinsics_bench("ibm7545_eye.yaml", eye_board, 420.0, trials)};
  }
  out["hand_eye"] = {cell::bench::hand_eye_bench(trials, he)};
  if (!only_hand_eye) {
    // The cap straight above the board, 20 poses: where every closed form works.
    cell::bench::HandEyeSettings cap = he;
    cap.poses = 20;
    cap.min_elevation_deg = 50.0;
    cap.max_elevation_deg = 88.0;
    out["hand_eye"].push_back(cell::bench::hand_eye_bench(trials, cap));
  }
  if (!only_hand_eye) {
    out["times"] = cell::bench::timings(quick ? 3 : 20);
  }
  if (as_json) {
    std::printf("%s\n", out.dump(2).c_str());
  }
  return 0;
}

// Nothing escapes main: an exception is printed and fails the run.
int main(int argc, char** argv) {
  try {
    return main_body(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "calibration_bench: %s\n", e.what());
  } catch (...) {
    std::fprintf(stderr, "calibration_bench: an exception not derived from std::exception\n");
  }
  return 1;
}
