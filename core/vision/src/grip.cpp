#include "cell/vision/grip.hpp"

#include <fmt/format.h>

#include <cmath>
#include <numbers>

namespace cell::vision {

Status GraspModel::validate() const {
  auto bad = [&](const std::string& what) {
    return Error{Errc::kInvalidArgument, fmt::format("grasp model of '{}': {}", class_name, what)};
  };
  if (class_name.empty()) {
    return Error{Errc::kInvalidArgument, "a grasp model needs the class it applies to"};
  }
  if (!(std::isfinite(finger_width_mm) && finger_width_mm > 0.0 &&
        std::isfinite(finger_height_mm) && finger_height_mm > 0.0)) {
    return bad(fmt::format("finger_width_mm and finger_height_mm must be > 0, got {} and {}",
                           finger_width_mm, finger_height_mm));
  }
  if (!(area_tolerance_px >= 0.0)) {
    return bad(fmt::format("area_tolerance_px must be >= 0, got {}", area_tolerance_px));
  }
  if (styles.empty()) {
    return bad("needs at least one grasp style");
  }
  for (const GraspStyle& s : styles) {
    if (!(std::isfinite(s.d_cg_mm) && s.d_cg_mm >= 0.0 && std::isfinite(s.alpha_rad) &&
          std::isfinite(s.rz_off_rad) && std::isfinite(s.part_width_mm) &&
          s.part_width_mm >= 0.0)) {
      return bad(
          fmt::format("style '{}': d_cg_mm and part_width_mm must be >= 0 and the angles "
                      "finite",
                      s.name));
    }
  }
  return ok_status();
}

FingerprintPlacement place_fingerprints(const Eigen::Vector2d& c,
                                        double angle_aim_rad,
                                        const GraspStyle& style,
                                        double finger_width_mm,
                                        double finger_height_mm) {
  FingerprintPlacement f;
  f.beta_rad = angle_aim_rad + style.alpha_rad;                                               // (5)
  f.grasp = c - style.d_cg_mm * Eigen::Vector2d(std::cos(f.beta_rad), std::sin(f.beta_rad));  // (6)
  f.grasp_angle_rad = f.beta_rad + style.rz_off_rad;
  f.dg_mm = style.part_width_mm / 2.0 + finger_width_mm / 2.0;
  const Eigen::Vector2d xg(std::cos(f.grasp_angle_rad), std::sin(f.grasp_angle_rad));
  const Eigen::Vector2d yg(-xg.y(), xg.x());
  f.cw1 = f.grasp - f.dg_mm * xg;  // (7)
  f.cw2 = f.grasp + f.dg_mm * xg;
  const Eigen::Vector2d hx = 0.5 * finger_width_mm * xg;
  const Eigen::Vector2d hy = 0.5 * finger_height_mm * yg;
  f.window1 = {f.cw1 - hx - hy, f.cw1 + hx - hy, f.cw1 + hx + hy, f.cw1 - hx + hy};
  f.window2 = {f.cw2 - hx - hy, f.cw2 + hx - hy, f.cw2 + hx + hy, f.cw2 - hx + hy};
  return f;
}

double fingerprint_area_px(double finger_width_mm,
                           double finger_height_mm,
                           double mm_per_px_x,
                           double mm_per_px_y) noexcept {
  return finger_width_mm * finger_height_mm / (mm_per_px_x * mm_per_px_y);
}

bool fingerprints_clear(double ar1, double ar2, double fngprt_ar, double err) noexcept {
  return std::abs(ar1 - fngprt_ar) <= err && std::abs(ar2 - fngprt_ar) <= err;
}

std::string_view to_string(GripVerdict verdict) noexcept {
  switch (verdict) {
    case GripVerdict::kNotTested:
      return "not_tested";
    case GripVerdict::kClear:
      return "clear";
    case GripVerdict::kBlocked:
      return "blocked";
  }
  return "not_tested";
}

GripResult test_clear_grip(const GraspModel& model,
                           const Eigen::Vector2d& c,
                           double angle_aim_rad,
                           const WindowToPixels& to_pixels,
                           const WindowCounter& count) {
  GripResult result;
  std::string detail;
  auto add = [&](const std::string& clause) { detail += (detail.empty() ? "" : "; ") + clause; };
  for (std::size_t k = 0; k < model.styles.size(); ++k) {
    const GraspStyle& style = model.styles[k];
    const FingerprintPlacement f =
        place_fingerprints(c, angle_aim_rad, style, model.finger_width_mm, model.finger_height_mm);
    std::array<WindowCount, 2> counts;
    bool mapped = true;
    for (int w = 0; w < 2 && mapped; ++w) {
      const auto& window = w == 0 ? f.window1 : f.window2;
      std::array<Eigen::Vector2d, 4> px;
      for (std::size_t i = 0; i < 4 && mapped; ++i) {
        const auto p = to_pixels(window[i]);
        mapped = p.has_value();
        if (mapped) {
          px[i] = *p;
        }
      }
      if (mapped) {
        counts[static_cast<std::size_t>(w)] = count(px);
      }
    }
    const std::string name = fmt::format("style {} '{}'", k, style.name);
    if (!mapped) {
      add(name + ": a fingerprint cannot be mapped into the image");
      continue;
    }
    bool clear = true;
    for (int w = 0; w < 2; ++w) {
      const WindowCount& wc = counts[static_cast<std::size_t>(w)];
      if (!wc.inside_image && model.outside == OutsideView::kBlocked) {
        add(fmt::format("{}: fingerprint {} is not wholly in the image", name, w + 1));
        clear = false;
        break;
      }
      if (wc.expected_px <= 0.0) {
        if (model.outside == OutsideView::kBlocked) {
          add(fmt::format("{}: fingerprint {} is outside the image", name, w + 1));
          clear = false;
          break;
        }
        continue;  // invisible and assumed free
      }
      if (std::abs(wc.free_px - wc.expected_px) > model.area_tolerance_px) {
        add(fmt::format(
            "{}: fingerprint {} has {:.0f} of {:.0f} px taken by another part "
            "(tolerance {:.0f})",
            name, w + 1, wc.expected_px - wc.free_px, wc.expected_px, model.area_tolerance_px));
        clear = false;
        break;
      }
    }
    if (clear) {
      if (result.clear.empty()) {
        result.verdict = GripVerdict::kClear;
        result.style = static_cast<int>(k);
        result.style_name = style.name;
        result.detail = detail;  // only the styles before the first clear one
      }
      // The fingers close along the tool's y axis and x_g joins them: tool x at grasp.angle -
      // pi/2 (ClearGrasp, grip.hpp).
      result.clear.push_back(ClearGrasp{static_cast<int>(k), style.name, f.grasp,
                                        f.grasp_angle_rad - std::numbers::pi / 2.0});
    }
  }
  if (result.clear.empty()) {
    result.verdict = GripVerdict::kBlocked;
    result.detail = detail.empty() ? "no grasp style" : detail;
  }
  return result;
}

}  // namespace cell::vision
