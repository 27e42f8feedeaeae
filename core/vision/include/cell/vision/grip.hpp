#pragma once

#include <Eigen/Core>
#include <array>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"

/// The fingerprint clear-grip test of the conveyor-tracking chapter (digest 002 §3): for each
/// recognised part, k grasp styles of a p = 2 finger gripper; each style puts two rectangular
/// fingerprint windows beside the part; a style is authorised only when both windows are free
/// of other parts; the first clear style wins (`CF(Gs_m_i, O)`), and the result says why the
/// styles before it failed. Every clear style is also listed with where the tool goes
/// (ClearGrasp), so a picker can choose among them (e.g. the one needing the least roll).
///
/// Frames and units. The geometry (eq. 5-7) works in any planar frame in which the part's
/// centroid C and angle.aim (its major axis, MIA) are given, in mm and rad: vision uses its
/// plane frame (pixel_mapper.hpp) and maps the windows to pixels.
namespace cell::vision {

/// One taught grasp style `Gs_m_i` = GP_m(G, O) = {d.cg, alpha, z_off, rz_off} (z_off is the
/// robot's business, not the image's) plus the part width the fingers close on.
struct GraspStyle {
  std::string name;            ///< "across", "ends", ...
  double d_cg_mm = 0.0;        ///< d.cg: distance from the centroid C to the grasp point G
  double alpha_rad = 0.0;      ///< alpha: angle(MIA, dir(C, G))
  double rz_off_rad = 0.0;     ///< rz.off: angle(x_g, dir(C, G)); x_g joins the two fingers
  double part_width_mm = 0.0;  ///< wd_LA: the part's width between the fingers (leads included)
};

/// Where to open the fingers if `outside` fingerprints are not in the image.
enum class OutsideView : std::uint8_t {
  kBlocked,  ///< a fingerprint not wholly in view is not clear (default: nothing is assumed)
  kClear,    ///< the part of a fingerprint outside the image counts as free
};

/// The extended grasping model of one class: finger shape, styles (tried in order), tolerance.
struct GraspModel {
  std::string class_name;          ///< vision class it applies to ("dip14", "rectangle", ...)
  double finger_width_mm = 0.0;    ///< wd_g: finger size along x_g (the closing direction)
  double finger_height_mm = 0.0;   ///< ht_g: finger size across x_g
  std::vector<GraspStyle> styles;  ///< k >= 1 styles, first clear wins
  /// err: how many pixels of a window may be taken by other parts (or noise) and still count
  /// as free: |ar - fngprt.ar| <= err.
  double area_tolerance_px = 4.0;
  OutsideView outside = OutsideView::kBlocked;

  /// Ok, or kInvalidArgument naming the class and field (no styles, sizes not > 0, a
  /// negative tolerance or part width, non-finite angles).
  Status validate() const;
};

/// The two fingerprint windows of one style for one part instance (eq. 5-7).
struct FingerprintPlacement {
  double beta_rad = 0.0;                            ///< (5) beta = angle.aim + alpha
  Eigen::Vector2d grasp = Eigen::Vector2d::Zero();  ///< (6) G = C - d.cg (cos beta, sin beta)
  double grasp_angle_rad = 0.0;                     ///< grasp.angle = beta + rz.off
  double dg_mm = 0.0;                               ///< dg = wd_LA / 2 + wd_g / 2
  Eigen::Vector2d cw1 = Eigen::Vector2d::Zero();    ///< (7) G - dg (cos, sin)(grasp.angle)
  Eigen::Vector2d cw2 = Eigen::Vector2d::Zero();    ///< (7) G + dg (cos, sin)(grasp.angle)
  /// Window corners (cw +- wd_g/2 along x_g, +- ht_g/2 across), counter-clockwise.
  std::array<Eigen::Vector2d, 4> window1{};
  std::array<Eigen::Vector2d, 4> window2{};
};

/// Equations (5)-(7) of digest 002 §3.3 for a part at centroid `c` with major axis at
/// `angle_aim_rad`, in the frame of `c`.
FingerprintPlacement place_fingerprints(const Eigen::Vector2d& c,
                                        double angle_aim_rad,
                                        const GraspStyle& style,
                                        double finger_width_mm,
                                        double finger_height_mm);

/// fngprt.ar = wd_g * ht_g / (mm_per_px_x * mm_per_px_y): the pixels of a free window
/// (digest 002 §3.3, with mm/px stored explicitly for both axes as the digest recommends).
double fingerprint_area_px(double finger_width_mm,
                           double finger_height_mm,
                           double mm_per_px_x,
                           double mm_per_px_y) noexcept;

/// The decision for one style: |ar1 - fngprt.ar| <= err AND |ar2 - fngprt.ar| <= err (the
/// text's "[ar - fngprt.ar] <= err" would always pass, since ar <= fngprt.ar).
bool fingerprints_clear(double ar1, double ar2, double fngprt_ar, double err) noexcept;

/// What the image says about one window: free pixels (`ar`) against a free window's
/// (`expected`), and whether all of it was inside the image.
struct WindowCount {
  double free_px = 0.0;      ///< ar: pixels of the window not covered by another part
  double expected_px = 0.0;  ///< fngprt.ar for this window as it lies in the image
  bool inside_image = true;
};

/// Counts one window given as a polygon in pixels: supplied by the caller (vision's locator
/// rasterises the window and asks its segmentation which pixels belong to other parts).
using WindowCounter = std::function<WindowCount(const std::array<Eigen::Vector2d, 4>& window_px)>;

/// Maps a window corner from the model's frame to pixels (nullopt when it cannot be mapped).
using WindowToPixels = std::function<std::optional<Eigen::Vector2d>(const Eigen::Vector2d&)>;

enum class GripVerdict : std::uint8_t { kNotTested, kClear, kBlocked };

/// "not_tested", "clear", "blocked".
std::string_view to_string(GripVerdict verdict) noexcept;

/// One clear grasp style of a part: where the tool goes and how it is turned, in the frame of
/// the part's centroid `c` given to test_clear_grip (vision: the plane frame), mm and rad.
///
/// Tool convention: the cell's parallel grippers close their fingers along the TOOL's y axis.
/// In the grip model x_g joins the two fingers and grasp.angle = beta + rz.off
/// (FingerprintPlacement), so the tool's yaw (its x axis) is grasp.angle - pi/2 and the tool
/// point is the grasp point G (eq. 6). For "across" (alpha 0, rz.off 90 deg, d.cg 0) the tool
/// yaw is the part's major-axis angle (tool x along the part's length); for "ends" (rz.off 0)
/// it is that angle - 90 deg.
struct ClearGrasp {
  int style = -1;    ///< index of the style in GraspModel::styles
  std::string name;  ///< its name ("across", "ends", ...)
  /// G = C - d.cg (cos beta, sin beta) (eq. 6), in the frame of `c` [mm].
  Eigen::Vector2d grasp = Eigen::Vector2d::Zero();
  /// grasp.angle - pi/2 = angle.aim + alpha + rz.off - pi/2, same frame [rad]; neither wrapped
  /// nor folded to the part's or the gripper's symmetry.
  double tool_yaw_rad = 0.0;
};

/// The clear-grip result of one part.
struct GripResult {
  GripVerdict verdict = GripVerdict::kNotTested;
  int style = -1;          ///< index of the first clear style, -1 when none
  std::string style_name;  ///< its name
  /// One clause per style tried before the first clear one (and, when blocked, every style):
  /// "style 0 'across': fingerprint 2 has 37 of 140 px taken by another part (tolerance 4)".
  /// Empty when style 0 is clear; styles after the first clear one are not explained here.
  std::string detail;
  /// Every clear style, in style order (the first is `style`); empty unless kClear.
  std::vector<ClearGrasp> clear;
};

/// Runs every style of `model` for a part at (c, angle.aim): `verdict`, `style`, `style_name`
/// name the first clear one (or kBlocked with every reason) and `clear` lists all the clear
/// ones with their tool poses. `to_pixels` maps window corners to the image, `count` measures a
/// window there (both called for every style). No errors: an unmappable window blocks its
/// style. Thread-safe as far as the callbacks are.
GripResult test_clear_grip(const GraspModel& model,
                           const Eigen::Vector2d& c,
                           double angle_aim_rad,
                           const WindowToPixels& to_pixels,
                           const WindowCounter& count);

}  // namespace cell::vision
