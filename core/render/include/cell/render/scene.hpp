#pragma once

#include <cstdint>
#include <string>
#include <string_view>
#include <vector>

#include <Eigen/Geometry>

#include "cell/common/result.hpp"
#include "cell/render/lighting.hpp"

/// What the renderer draws: generic geometry, built by the camera service from the world
/// simulator's WorldState (idl/world.idl) or by tests directly. Pure data; no DDS.
///
/// Frames (idl/world.idl). "world" is the cell's fixed frame, z up. A part frame has its origin
/// at the centre of the part's footprint on its base, x along its length, y along its width, z
/// up out of its top. Units: mm, rad.
namespace cell::render {

/// The shape of a part (world.idl PartShape).
enum class Shape : std::uint8_t {
  kDip,         ///< DIP IC: black body length x width, its top at height (leads' seating plane
                ///< at z = 0), `pins` leads along both long sides
  kRectangle,   ///< flat prism length x width x height
  kSquare,      ///< flat prism length x length x height (width is ignored)
  kDisc,        ///< cylinder of diameter length, height
  kTriangle,    ///< equilateral prism of side length: one side parallel to x at y = -h/3, the
                ///< opposite vertex on +y (h = length * sqrt(3) / 2), centroid at the origin
  kBox,         ///< a 3-D box length x width x height (as kRectangle; named for RAPT blocks)
  kPolyhedron,  ///< polyhedron given by `mesh` in the part frame
};

/// "dip", "rectangle", "square", "disc", "triangle", "box", "polyhedron".
std::string_view to_string(Shape shape) noexcept;

/// A polyhedron in the part frame: vertices [mm] and faces, each a planar convex polygon listing
/// vertex indices counter-clockwise seen from outside (world.idl Mesh). The body may be
/// non-convex (RAPT's L-shaped block): such bodies are painted face by face, far to near.
struct Mesh {
  std::vector<Eigen::Vector3d> vertices_mm;
  std::vector<std::vector<std::uint32_t>> faces;
};

/// DIP package geometry seen from above (JEDEC MS-001 / MS-011 nominal values, mm; the same
/// conventions as core/world's DipPackage, since the world contract carries only the pin
/// count and sizes). Leads leave the body's long sides at mid-body height and reach out to the
/// pin rows: seen from above, a lead is its shoulder, `shoulder_width_mm` wide, from the body
/// side out to row_spacing/2 + lead_thickness/2.
struct DipLeads {
  double pitch_mm = 2.54;           ///< pin to pin along a row (shrunk to fit the body if needed)
  double row_spacing_mm = 7.62;     ///< pin-row centre lines ("0.3 inch" package)
  double shoulder_width_mm = 1.52;  ///< lead width seen from above (along x)
  double lead_thickness_mm = 0.25;  ///< sheet thickness (across y)
  double standoff_mm = 0.51;        ///< seating plane (part frame z = 0) to the body's bottom
  double reflectance = 0.6;         ///< tinned leads, diffuse part (the crest adds a highlight)

  /// The standard package for a body `width_mm` wide: rows 7.62 mm (<= 7.5 mm bodies), 10.16
  /// (<= 10 mm) or 15.24 mm apart, as core/world rebuilds a DIP from the contract.
  static DipLeads standard_for_width(double width_mm) noexcept;
};

/// One part.
struct Part {
  std::string id;          ///< unique in the scene ("p7")
  std::string class_name;  ///< "dip14", "rectangle", "block_a", ...
  Shape shape = Shape::kRectangle;
  double length_mm = 0.0;
  double width_mm = 0.0;
  double height_mm = 0.0;
  int pins = 0;               ///< DIP lead count (both sides together), 0 otherwise
  DipLeads leads;             ///< kDip only: package geometry
  double reflectance = 0.1;   ///< 0 black .. 1 white matte (Lambert)
  Eigen::Isometry3d world_T_part = Eigen::Isometry3d::Identity();
  /// Velocity of the part during the exposure, world frame [mm/s] (a part riding a belt):
  /// the exposure integrates its motion (motion blur). Zero for parts at rest.
  Eigen::Vector3d velocity_mm_s = Eigen::Vector3d::Zero();
  Mesh mesh;  ///< kPolyhedron only

  /// Ok, or kInvalidArgument naming the part and what is wrong: a non-finite or non-rigid
  /// pose, a size not > 0 (height may be 0 for a flat sticker: it is drawn as its top face),
  /// reflectance outside [0, 1], a negative or odd DIP pin count, a non-finite velocity, or for
  /// polyhedra an empty mesh, a face with fewer than 3 vertices or an index out of range.
  Status validate() const;
};

/// A conveyor belt's visible top surface (world.idl BeltState geometry).
struct Belt {
  std::string id;
  Eigen::Vector3d origin_mm = Eigen::Vector3d::Zero();  ///< centre line, upstream end (world)
  Eigen::Vector3d direction = Eigen::Vector3d::UnitX();  ///< unit vector of travel (world)
  double length_mm = 0.0;
  double width_mm = 0.0;
  double reflectance = 0.3;  ///< darker grey rubber

  /// Ok, or kInvalidArgument naming the belt and what is wrong.
  Status validate() const;
};

/// A chessboard calibration target: `squares_x` x `squares_y` alternating squares of side
/// `square_mm` on a white board with a `margin_mm` border, in the board frame: origin at the
/// outer corner of square (0, 0), x along the squares_x direction, y along squares_y, z out of
/// the printed face (the camera must look at it from +z). Square (i, j) is black when i + j is
/// even. Its inner corners, (squares_x - 1) x (squares_y - 1) of them, sit at
/// (i * square_mm, j * square_mm, 0) for i = 1..squares_x-1, j = 1..squares_y-1 (see
/// chessboard_corners). The printed face is the board frame's z = 0 plane; the board's body
/// lies behind it (z in [-thickness_mm, 0]), so a board lying on the table has its frame
/// thickness_mm above the table top.
struct Chessboard {
  std::string id;
  int squares_x = 9;
  int squares_y = 7;
  double square_mm = 15.0;
  double margin_mm = 10.0;
  double thickness_mm = 3.0;
  double white_reflectance = 0.85;
  double black_reflectance = 0.05;
  Eigen::Isometry3d world_T_board = Eigen::Isometry3d::Identity();

  /// Ok, or kInvalidArgument naming the target and what is wrong (fewer than 2 squares per
  /// side, sizes not > 0, reflectances outside [0, 1], a non-rigid pose).
  Status validate() const;
};

/// The inner corners of `board` in its own frame [mm], row by row (x fastest): the order
/// cv::findChessboardCorners reports for a board of pattern size (squares_x - 1, squares_y - 1)
/// seen without mirroring.
std::vector<Eigen::Vector3d> chessboard_corners(const Chessboard& board);

/// Everything in view for one frame.
struct Scene {
  double table_height_mm = 0.0;    ///< the table top's z in the world frame
  double table_reflectance = 0.9;  ///< white matte (digest 000 §3)
  std::vector<Belt> belts;
  std::vector<Part> parts;
  std::vector<Chessboard> targets;
  LightSwitches lights;
};

}  // namespace cell::render
