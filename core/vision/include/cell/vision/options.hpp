#pragma once

#include <string>

#include "cell/common/result.hpp"
#include "cell/config/yaml.hpp"
#include "cell/vision/edge.hpp"
#include "cell/vision/locate.hpp"

/// Reading vision's options from YAML with core/config's strict reader (unknown keys and bad
/// values are errors with file:line:col), shared by the vision service (its `locate:` and
/// `edges:` sections, config/vision.yaml) and `cellctl locate --config`. Angles are given in
/// degrees (keys ending in _deg) and stored in radians.
///
///   locate:
///     pipeline: fast                  # fast | thesis
///     segmentation: {mode: adaptive, fixed_threshold: 150, adaptive_ratio: 0.55,
///                    block_px: 64, min_area_px: 40}
///     thesis: {threshold: 150, epsilon_px: 20, lookback_px: 66, merge_prefix_px: 11,
///              min_skeleton_px: 12, max_groups: 30, max_objects: 20, corner_exclusion_px: 14,
///              centre_px: [255, 241], part_height_mm: 3.81, camera_height_mm: 420,
///              aspect: 1.023, shape_tests: true}
///     class_tolerance_mm: 0.45
///     class_tolerance_rel: 0.04
///     default_top_mm: 3.81
///     default_base_mm: 0.51
///     edge_window_px: 3
///     crossing_stride: 2
///     max_fit_rms_px: 0.35
///     drop_border_parts: true
///     classes:                        # added to the built-in catalogue (core/world's)
///       - {name: washer, shape: circle, length_mm: 12, width_mm: 12, top_mm: 1.5}
///     grasps:
///       - class: dip14
///         finger_width_mm: 4
///         finger_height_mm: 8
///         area_tolerance_px: 4
///         outside_view: blocked       # blocked | clear
///         styles:
///           - {name: across, d_cg_mm: 0, alpha_deg: 0, rz_off_deg: 90, part_width_mm: 9.5}
///   edges:
///     weight_fraction: 0.35
///     min_weight: 60
///     end_search_px: 4
///     profile_half_px: 4
///     outlier_px: 1.0
namespace cell::vision {

/// Reads a `locate:` map into `out` (keys absent keep their value). Errors are recorded in
/// `map` (and reported by its finish()), including validate()'s verdicts and unknown classes
/// in `grasps`.
void read_locate_options(config::MapReader& map, LocateOptions& out);

/// Reads an `edges:` map into `out`, as above.
void read_edge_options(config::MapReader& map, EdgeFinderOptions& out);

/// Convenience: the `locate:` section of a vision config file (other sections ignored).
/// Errors: kConfig with file:line:col.
Result<LocateOptions> load_locate_options(const std::string& path);

/// The options one camera's frames are located with: the file's `locate:` section with the
/// `locate:` keys of its `cameras:` entry whose id is `camera_id` over it (config/vision.yaml;
/// no such entry: the section as it is).
Result<LocateOptions> load_locate_options(const std::string& path, const std::string& camera_id);

}  // namespace cell::vision
