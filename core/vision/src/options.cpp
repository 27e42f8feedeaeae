#include "cell/vision/options.hpp"

#include <fmt/format.h>

#include <array>

namespace cell::vision {
namespace {

void read_segmentation(config::MapReader& r, SegmentationOptions& s) {
  std::string mode(to_string(s.mode));
  r.optional("mode", mode);
  if (mode == "fixed") {
    s.mode = ThresholdMode::kFixed;
  } else if (mode == "adaptive") {
    s.mode = ThresholdMode::kAdaptive;
  } else {
    r.fail("mode", fmt::format("must be fixed or adaptive, got '{}'", mode));
  }
  r.optional("fixed_threshold", s.fixed_threshold);
  r.optional("adaptive_ratio", s.adaptive_ratio);
  r.optional("block_px", s.block_px);
  r.optional("min_area_px", s.min_area_px);
  if (auto st = s.validate(); !st) {
    r.fail("", st.error().message);
  }
}

void read_thesis(config::MapReader& r, ThesisOptions& t) {
  r.optional("threshold", t.threshold);
  r.optional("epsilon_px", t.epsilon_px);
  r.optional("lookback_px", t.lookback_px);
  r.optional("merge_prefix_px", t.merge_prefix_px);
  r.optional("min_skeleton_px", t.min_skeleton_px);
  r.optional("max_groups", t.max_groups);
  r.optional("max_objects", t.max_objects);
  r.optional("corner_exclusion_px", t.corner_exclusion_px);
  r.optional("first_row", t.first_row);
  r.optional("last_row", t.last_row);
  std::array<int, 2> centre{t.centre_px.x(), t.centre_px.y()};
  r.optional("centre_px", centre);
  t.centre_px = Eigen::Vector2i(centre[0], centre[1]);
  r.optional("part_height_mm", t.part_height_mm);
  r.optional("camera_height_mm", t.camera_height_mm);
  r.optional("aspect", t.aspect);
  r.optional("circle_spread", t.circle_spread);
  r.optional("square_tolerance", t.square_tolerance);
  r.optional("rectangle_tolerance", t.rectangle_tolerance);
  r.optional("triangle_line_px", t.triangle_line_px);
  r.optional("triangle_corner_px", t.triangle_corner_px);
  r.optional("shape_tests", t.shape_tests);
  if (auto st = t.validate(); !st) {
    r.fail("", st.error().message);
  }
}

std::optional<ShapeKind> shape_named(const std::string& text) {
  for (ShapeKind s :
       {ShapeKind::kRectangle, ShapeKind::kSquare, ShapeKind::kCircle, ShapeKind::kTriangle}) {
    if (text == to_string(s)) {
      return s;
    }
  }
  return std::nullopt;
}

}  // namespace

void read_locate_options(config::MapReader& map, LocateOptions& out) {
  std::string pipeline(to_string(out.pipeline));
  map.optional("pipeline", pipeline);
  if (auto p = pipeline_from_string(pipeline)) {
    out.pipeline = *p;
  } else {
    map.fail("pipeline", p.error().message);
  }
  if (map.has("segmentation")) {
    config::MapReader seg = map.child("segmentation", false);
    read_segmentation(seg, out.segmentation);
    map.absorb(seg);
  }
  if (map.has("thesis")) {
    config::MapReader th = map.child("thesis", false);
    read_thesis(th, out.thesis);
    map.absorb(th);
  }
  map.optional("class_tolerance_mm", out.class_tolerance_mm);
  map.optional("class_tolerance_rel", out.class_tolerance_rel);
  map.optional("default_top_mm", out.default_top_mm);
  map.optional("default_base_mm", out.default_base_mm);
  map.optional("edge_window_px", out.edge_window_px);
  map.optional("crossing_stride", out.crossing_stride);
  map.optional("max_fit_rms_px", out.max_fit_rms_px);
  map.optional("drop_border_parts", out.drop_border_parts);
  const auto classes = map.sequence("classes", false);
  for (std::size_t i = 0; i < classes.size(); ++i) {
    config::MapReader c = map.element(classes[i], fmt::format("classes[{}]", i));
    PartSpec spec;
    std::string shape = "rectangle";
    c.required("name", spec.name);
    c.required("shape", shape);
    c.required("length_mm", spec.length_mm);
    spec.width_mm = spec.length_mm;
    c.optional("width_mm", spec.width_mm);
    c.required("top_mm", spec.top_mm);
    c.optional("base_mm", spec.base_mm);
    c.optional("pins", spec.pins);
    if (auto s = shape_named(shape)) {
      spec.shape = *s;
      if (*s == ShapeKind::kTriangle && !c.has("width_mm")) {
        spec.width_mm = spec.length_mm * std::sqrt(3.0) / 2.0;
      }
      if (auto st = out.classes.add(spec); !st) {
        c.fail("", st.error().message);
      }
    } else {
      c.fail("shape",
             fmt::format("must be rectangle, square, circle or triangle, got '{}'", shape));
    }
    map.absorb(c);
  }
  // Given, the grasp models replace `out`'s (a camera's own list replaces the global one).
  const auto grasps = map.sequence("grasps", false);
  if (map.has("grasps")) {
    out.grasps.clear();
  }
  for (std::size_t i = 0; i < grasps.size(); ++i) {
    config::MapReader g = map.element(grasps[i], fmt::format("grasps[{}]", i));
    GraspModel model;
    g.required("class", model.class_name);
    g.required("finger_width_mm", model.finger_width_mm);
    g.required("finger_height_mm", model.finger_height_mm);
    g.optional("area_tolerance_px", model.area_tolerance_px);
    std::string outside = "blocked";
    g.optional("outside_view", outside);
    if (outside == "blocked") {
      model.outside = OutsideView::kBlocked;
    } else if (outside == "clear") {
      model.outside = OutsideView::kClear;
    } else {
      g.fail("outside_view", fmt::format("must be blocked or clear, got '{}'", outside));
    }
    const auto styles = g.sequence("styles", true);
    for (std::size_t k = 0; k < styles.size(); ++k) {
      config::MapReader s = g.element(styles[k], fmt::format("styles[{}]", k));
      GraspStyle style;
      style.name = fmt::format("style{}", k);
      s.optional("name", style.name);
      s.optional("d_cg_mm", style.d_cg_mm);
      s.optional_deg("alpha_deg", style.alpha_rad);
      s.optional_deg("rz_off_deg", style.rz_off_rad);
      s.required("part_width_mm", style.part_width_mm);
      model.styles.push_back(style);
      g.absorb(s);
    }
    if (!model.class_name.empty() && out.classes.find(model.class_name) == nullptr &&
        shape_named(model.class_name) == std::nullopt) {
      g.fail("class", fmt::format("unknown class '{}'", model.class_name));
    }
    if (auto st = model.validate(); !st && !styles.empty()) {
      g.fail("", st.error().message);
    }
    out.grasps.push_back(std::move(model));
    map.absorb(g);
  }
  if (auto st = out.validate(); !st) {
    map.fail("", st.error().message);
  }
}

void read_edge_options(config::MapReader& map, EdgeFinderOptions& out) {
  map.optional("weight_fraction", out.weight_fraction);
  map.optional("min_weight", out.min_weight);
  map.optional("end_search_px", out.end_search_px);
  map.optional("profile_half_px", out.profile_half_px);
  map.optional("outlier_px", out.outlier_px);
  if (auto st = out.validate(); !st) {
    map.fail("", st.error().message);
  }
}

namespace {

/// The `locate:` section of a parsed vision config, with the `locate:` keys of the `cameras:`
/// entry whose id is `camera_id` over it (nullptr: the section alone).
Result<LocateOptions> locate_options_of(const config::Document& doc, const std::string* camera_id) {
  LocateOptions out;
  config::MapReader root(doc, doc.root, "");
  const YAML::Node section = doc.root["locate"];
  if (section.IsDefined() && !section.IsNull()) {
    config::MapReader locate = root.child("locate", false);
    read_locate_options(locate, out);
    CELL_TRY(locate.finish());
  }
  const YAML::Node cameras = doc.root["cameras"];
  if (camera_id == nullptr || !cameras.IsSequence()) {
    return out;
  }
  for (std::size_t i = 0; i < cameras.size(); ++i) {
    const YAML::Node entry = cameras[i];
    if (!entry.IsMap() || !entry["id"] || entry["id"].as<std::string>("") != *camera_id ||
        !entry["locate"]) {
      continue;
    }
    config::MapReader e = root.element(entry, fmt::format("cameras[{}]", i));
    config::MapReader locate = e.child("locate", false);
    read_locate_options(locate, out);
    CELL_TRY(locate.finish());
  }
  return out;
}

}  // namespace

Result<LocateOptions> load_locate_options(const std::string& path) {
  auto doc = config::load_file(path);
  if (!doc) {
    return doc.error();
  }
  return locate_options_of(*doc, nullptr);
}

Result<LocateOptions> load_locate_options(const std::string& path, const std::string& camera_id) {
  auto doc = config::load_file(path);
  if (!doc) {
    return doc.error();
  }
  return locate_options_of(*doc, &camera_id);
}

}  // namespace cell::vision
