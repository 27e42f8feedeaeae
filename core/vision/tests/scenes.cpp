#include "scenes.hpp"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <numbers>
#include <stdexcept>

#include "cell/geometry/angles.hpp"
#include "cell/kinematics/robot_config.hpp"
#include "cell/render/mount.hpp"
#include "cell/render/renderer.hpp"
#include "cell/world/scene.hpp"
#include "cell/world/world.hpp"

#ifndef CELL_SOURCE_DIR
#define CELL_SOURCE_DIR "."
#endif

namespace cell::vision::testing {
namespace {

using geometry::kDeg;

std::string home() {
  const char* env = std::getenv("CELL_SOURCE_DIR");
  return env != nullptr && *env != '\0' ? std::string(env) : std::string(CELL_SOURCE_DIR);
}

template <typename T>
T must(Result<T> r, const char* what) {
  if (!r) {
    throw std::runtime_error(std::string(what) + ": " + r.error().message);
  }
  return std::move(r).value();
}

int symmetry_of(const world::PartClass& cls) {
  switch (cls.shape) {
    case world::Shape::kSquare:
      return 4;
    case world::Shape::kDisc:
      return 0;
    case world::Shape::kTriangle:
      return 3;
    default:
      return 2;
  }
}

}  // namespace

const char* to_string(Lights lights) { return lights == Lights::kTubes ? "tubes" : "tubes+lamp"; }

const Cell& Cell::get() {
  static const Cell cell;
  return cell;
}

Cell::Cell()
    : home_(home()),
      camera_(must(render::load_camera(home_ + "/config/cameras/ibm7545_eye.yaml"), "camera")),
      robot_(must(kinematics::load_robot(home_ + "/config/robots/ibm7545.yaml"), "robot")) {
  world_T_base_ = camera_.robot.world_T_base;
  const double plane_z = table_z_mm() - world_T_base_.translation().z();
  nominal_ = must(calibration::nominal_calibration(camera_, "", world_T_base_, plane_z),
                  "nominal calibration");
  render::CameraDescription truth = camera_;
  truth.nominal = camera_.truth;
  true_ =
      must(calibration::nominal_calibration(truth, "", world_T_base_, plane_z), "true calibration");
  true_.source = "the simulator's true camera (a perfect calibration)";
  true_.version = "truth";
  catalogue_ = world::Catalogue::standard();
}

std::vector<double> Cell::aligned_joints() const { return {45.0 * kDeg, 135.0 * kDeg, 0.0, 0.0}; }

std::vector<double> Cell::grab_joints() const {
  // The thesis's grab pose in counts (digest 000 §1.3): 39249 / 872.2222, 46662 / 444.4444.
  return {39249.0 / 872.2222 * kDeg, 46662.0 / 444.4444 * kDeg, 0.0, 0.0};
}

Eigen::AlignedBox2d Cell::window(double margin_mm) const {
  const auto joints = aligned_joints();
  kinematics::JointVector q(4);
  for (int i = 0; i < 4; ++i) {
    q[i] = joints[static_cast<std::size_t>(i)];
  }
  const auto mount = must(render::base_T_mount(robot_, camera_.robot.frame, q), "mount");
  const Eigen::Isometry3d w_T_c = camera_.world_T_camera(camera_.truth, mount);
  const auto& m = camera_.truth.model;
  std::vector<Eigen::Vector2d> corners;
  for (const Eigen::Vector2d& px : {Eigen::Vector2d(0, 0), Eigen::Vector2d(m.width_px() - 1, 0),
                                    Eigen::Vector2d(0, m.height_px() - 1),
                                    Eigen::Vector2d(m.width_px() - 1, m.height_px() - 1)}) {
    const Eigen::Vector3d ray = w_T_c.linear() * must(m.unproject(px), "unproject");
    const double s = (table_z_mm() - w_T_c.translation().z()) / ray.z();
    corners.push_back((w_T_c.translation() + s * ray).head<2>());
  }
  std::vector<double> xs;
  std::vector<double> ys;
  for (const auto& c : corners) {
    xs.push_back(c.x());
    ys.push_back(c.y());
  }
  std::sort(xs.begin(), xs.end());
  std::sort(ys.begin(), ys.end());
  // The inscribed box: inside the two innermost values of each axis.
  return Eigen::AlignedBox2d(Eigen::Vector2d(xs[1] + margin_mm, ys[1] + margin_mm),
                             Eigen::Vector2d(xs[2] - margin_mm, ys[2] - margin_mm));
}

render::Part Cell::part(const std::string& id,
                        const world::PartClass& cls,
                        const Eigen::Isometry3d& world_T_part,
                        bool pins) const {
  render::Part p;
  p.id = id;
  p.class_name = cls.name;
  p.length_mm = cls.length_mm;
  p.width_mm = cls.width_mm;
  p.height_mm = cls.height_mm;
  p.reflectance = cls.reflectance;
  p.world_T_part = world_T_part;
  switch (cls.shape) {
    case world::Shape::kDip:
      p.shape = render::Shape::kDip;
      p.pins = pins ? cls.dip.pins : 0;
      p.leads.pitch_mm = cls.dip.pitch_mm;
      p.leads.row_spacing_mm = cls.dip.row_spacing_mm;
      p.leads.shoulder_width_mm = cls.dip.shoulder_width_mm;
      p.leads.lead_thickness_mm = cls.dip.lead_thickness_mm;
      p.leads.standoff_mm = cls.dip.standoff_mm;
      p.leads.reflectance = cls.dip.lead_reflectance;
      break;
    case world::Shape::kRectangle:
      p.shape = render::Shape::kRectangle;
      break;
    case world::Shape::kSquare:
      p.shape = render::Shape::kSquare;
      break;
    case world::Shape::kDisc:
      p.shape = render::Shape::kDisc;
      break;
    case world::Shape::kTriangle:
      p.shape = render::Shape::kTriangle;
      break;
    default:
      p.shape = render::Shape::kBox;
      break;
  }
  return p;
}

render::Part Cell::part(const std::string& id,
                        const std::string& class_name,
                        double x_mm,
                        double y_mm,
                        double yaw_rad,
                        bool pins) const {
  const auto cls = catalogue_.find(class_name);
  if (!cls) {
    throw std::runtime_error("unknown class " + class_name);
  }
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = Eigen::Vector3d(x_mm, y_mm, table_z_mm());
  pose.linear() = Eigen::AngleAxisd(yaw_rad, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return part(id, *cls, pose, pins);
}

std::vector<Cell::ClearGraspScene> Cell::clear_grasp_scenes() const {
  const Eigen::Vector2d c = window(30.0).center();
  const double yaw = 25.0 * std::numbers::pi / 180.0;
  const Eigen::Vector2d n1 = c + 9.5 * Eigen::Vector2d(-std::sin(yaw), std::cos(yaw));
  return {{{part("ic", "dip14", c.x(), c.y(), yaw, true)}, {"across", "ends"}},
          {{part("ic", "dip14", c.x(), c.y(), yaw, true),
            part("n1", "dip8", n1.x(), n1.y(), yaw, true)},
           {"ends"}}};
}

GraspModel dip14_grasp_model() {
  GraspModel model;
  model.class_name = "dip14";
  model.finger_width_mm = 3.0;
  model.finger_height_mm = 8.0;
  model.styles = {GraspStyle{"across", 0.0, 0.0, 90.0 * kDeg, 9.0},
                  GraspStyle{"ends", 0.0, 0.0, 0.0, 21.0}};
  return model;
}

calibration::CameraCalibration Cell::ideal_calibration() const {
  calibration::CameraCalibration c = true_;
  c.pinhole.distortion = render::Distortion{};
  c.version = "truth, no lens";
  return c;
}

RenderedScene Cell::render(std::string name,
                           std::vector<render::Part> parts,
                           const std::vector<double>& joints,
                           Lights lights,
                           std::uint64_t noise_seed,
                           bool ideal_lens) const {
  RenderedScene out;
  out.name = std::move(name);
  out.joints = joints;
  out.scene.table_height_mm = table_z_mm();
  out.scene.table_reflectance = 0.9;
  out.scene.parts = std::move(parts);
  out.scene.lights.fluorescent_on = true;
  out.scene.lights.lamp_on = lights == Lights::kTubesAndLamp;
  kinematics::JointVector q(static_cast<int>(joints.size()));
  for (std::size_t i = 0; i < joints.size(); ++i) {
    q[static_cast<int>(i)] = joints[i];
  }
  const auto mount = must(render::base_T_mount(robot_, camera_.robot.frame, q), "mount");
  out.world_T_camera = camera_.world_T_camera(camera_.truth, mount);
  const auto& m = camera_.truth.model;
  const render::CameraModel model =
      ideal_lens ? must(render::CameraModel::create(m.width_px(), m.height_px(), m.fx_px(),
                                                    m.fy_px(), m.cx_px(), m.cy_px(), {}),
                        "ideal lens")
                 : m;
  auto renderer = must(render::Renderer::create(model, camera_.lighting), "renderer");
  render::RenderOptions options;
  options.exposure_s = 0.0;
  options.noise_sigma = 2.0;
  options.seed = noise_seed;
  const auto stats = renderer.render(out.scene, out.world_T_camera, options, out.image);
  if (!stats || stats->parts_skipped > 0) {
    throw std::runtime_error("render failed or skipped parts");
  }
  for (auto& t : render::ground_truth(out.scene, model, out.world_T_camera)) {
    if (t.visible_fraction >= 0.999) {
      out.truth.push_back(std::move(t));
    }
  }
  return out;
}

RenderedScene Cell::scatter(const ScatterRequest& request) const {
  // Margin: the largest half-diagonal of the classes, leads included, plus 2 mm.
  double margin = 0.0;
  for (const auto& name : request.classes) {
    const auto cls = catalogue_.find(name);
    for (const auto& p : cls->footprint) {
      margin = std::max(margin, p.norm());
    }
  }
  const Eigen::AlignedBox2d box = window(margin + 2.0);
  world::Scene scene;
  scene.name = "vision_scatter";
  scene.table.height_mm = table_z_mm();
  world::ScatterSpec spec;
  spec.count = static_cast<std::uint32_t>(request.count);
  spec.classes = request.classes;
  spec.x_min_mm = box.min().x();
  spec.x_max_mm = box.max().x();
  spec.y_min_mm = box.min().y();
  spec.y_max_mm = box.max().y();
  spec.min_separation_mm = request.min_separation_mm;
  spec.seed = request.seed;
  spec.max_attempts_per_part = 5000;
  scene.scatter.push_back(spec);
  world::WorldOptions options;
  auto world = must(world::World::create(scene, catalogue_, options), "scatter");
  std::vector<render::Part> parts;
  for (const auto& p : world.parts()) {
    parts.push_back(part(p.id, *p.cls, p.world_T_part, request.pins));
  }
  return render(fmt::format("{} ICs {} {} seed {}", request.count,
                            request.pins ? "with pins" : "without pins", to_string(request.lights),
                            request.seed),
                std::move(parts), aligned_joints(), request.lights, request.seed * 7919 + 1,
                request.ideal_lens);
}

RenderedScene Cell::table_ics(bool pins, Lights lights) const {
  auto scene = must(world::load_scene_file(home_ + "/config/scenes/table_ics.yaml", catalogue_),
                    "table_ics.yaml");
  world::WorldOptions options;
  auto world = must(world::World::create(scene, catalogue_, options), "table_ics world");
  std::vector<render::Part> parts;
  for (const auto& p : world.parts()) {
    parts.push_back(part(p.id, *p.cls, p.world_T_part, pins));
  }
  return render(
      fmt::format("table_ics {} {}", pins ? "with pins" : "without pins", to_string(lights)),
      std::move(parts), grab_joints(), lights, 1994);
}

PixelMapper Cell::mapper(const calibration::CameraCalibration& calibration,
                         const std::vector<double>& joints) const {
  return must(PixelMapper::create(calibration, &robot_, joints), "mapper");
}

void Score::add(const Score& o) {
  parts += o.parts;
  found += o.found;
  missed += o.missed;
  false_parts += o.false_parts;
  wrong_class += o.wrong_class;
  sum_centre2_px += o.sum_centre2_px;
  sum_angle2_rad += o.sum_angle2_rad;
  max_centre_px = std::max(max_centre_px, o.max_centre_px);
  max_angle_rad = std::max(max_angle_rad, o.max_angle_rad);
  sum_world2_mm += o.sum_world2_mm;
  max_world_mm = std::max(max_world_mm, o.max_world_mm);
  world_compared += o.world_compared;
  notes.insert(notes.end(), o.notes.begin(), o.notes.end());
}

double Score::centre_rms_px() const { return found > 0 ? std::sqrt(sum_centre2_px / found) : 0.0; }
double Score::angle_rms_deg() const {
  return found > 0 ? std::sqrt(sum_angle2_rad / found) / kDeg : 0.0;
}
double Score::world_rms_mm() const {
  return world_compared > 0 ? std::sqrt(sum_world2_mm / world_compared) : 0.0;
}

Score score(const std::vector<Detection>& detections,
            const RenderedScene& frame,
            bool compare_class,
            const Eigen::Isometry3d* world_T_base) {
  Score s;
  s.parts = static_cast<int>(frame.truth.size());
  std::vector<bool> used(detections.size(), false);
  const auto& catalogue = Cell::get().catalogue();
  for (const auto& t : frame.truth) {
    int best = -1;
    double best_d = 4.0;
    for (std::size_t i = 0; i < detections.size(); ++i) {
      const double d = (detections[i].center_px - t.center_px).norm();
      if (!used[i] && d < best_d) {
        best_d = d;
        best = static_cast<int>(i);
      }
    }
    if (best < 0) {
      ++s.missed;
      s.notes.push_back(fmt::format("{}: missed {} at ({:.1f}, {:.1f})", frame.name, t.part_id,
                                    t.center_px.x(), t.center_px.y()));
      continue;
    }
    used[static_cast<std::size_t>(best)] = true;
    const Detection& d = detections[static_cast<std::size_t>(best)];
    ++s.found;
    const auto cls = catalogue.find(t.class_name);
    const int order = cls ? symmetry_of(*cls) : 2;
    double ae = angle_error(d.angle_rad, t.angle_rad, order);
    if ((order == 3 || order == 4) && d.corners_px.size() == static_cast<std::size_t>(order)) {
      // The truth's angle is one particular side's (the part's x axis); in the image the sides
      // of a square or triangle are not exactly 90 or 120 degrees apart (pixels are 3 % taller
      // than wide, perspective): compare with the detected side that runs that way.
      ae = 1e9;
      for (int k = 0; k < order; ++k) {
        const Eigen::Vector2d side = d.corners_px[static_cast<std::size_t>((k + 1) % order)] -
                                     d.corners_px[static_cast<std::size_t>(k)];
        ae = std::min(ae,
                      angle_error(std::atan2(side.y(), side.x()), t.angle_rad, order == 3 ? 1 : 2));
      }
    }
    s.sum_centre2_px += best_d * best_d;
    s.sum_angle2_rad += ae * ae;
    s.max_centre_px = std::max(s.max_centre_px, best_d);
    s.max_angle_rad = std::max(s.max_angle_rad, ae);
    if (compare_class && d.class_name != t.class_name) {
      ++s.wrong_class;
      s.notes.push_back(fmt::format("{}: {} ({}) classified as {} ({:.2f} x {:.2f} mm)", frame.name,
                                    t.part_id, t.class_name, d.class_name, d.length_mm,
                                    d.width_mm));
    }
    if (world_T_base != nullptr && d.has_base_pose) {
      const Eigen::Vector3d base = world_T_base->inverse() * t.world_T_part.translation();
      const double e = std::hypot(d.base_pose.x_mm - base.x(), d.base_pose.y_mm - base.y());
      s.sum_world2_mm += e * e;
      s.max_world_mm = std::max(s.max_world_mm, e);
      ++s.world_compared;
    }
  }
  for (std::size_t i = 0; i < detections.size(); ++i) {
    if (!used[i]) {
      ++s.false_parts;
      s.notes.push_back(fmt::format("{}: false part {} at ({:.1f}, {:.1f})", frame.name,
                                    detections[i].class_name, detections[i].center_px.x(),
                                    detections[i].center_px.y()));
    }
  }
  return s;
}

}  // namespace cell::vision::testing
