#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <map>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "cell/common/result.hpp"

/// Part classes of the simulated cell: what a part is (shape, size, reflectance, grasp), not
/// where it is. See core/world/README.md for the catalogue and its sources.
///
/// **Part frame** (every class, every shape; the IDL's `WorldPart` uses the same): origin at the
/// centre of the part's footprint on its base (the plane it rests on: the seating plane of a
/// DIP's leads, the bottom face of a block), x along the part's length, y across it, z up out of
/// its top. Millimetres. A part resting flat on a surface at height h with yaw psi therefore
/// has world_T_part = Trans(x, y, h) * Rz(psi).
///
/// **Grasp frame** (`part_T_grasp`): where the gripper's tool point must be to take the part.
/// Default for every built-in class: the top centre, Trans(0, 0, height_mm), axes parallel to
/// the part frame (z UP, like the tool frame of the cell's SCARAs, core/kinematics scara.hpp).
/// Capture (core/world world.hpp) compares tool POINTS with the grasp point (distance) and the
/// tool's x axis, as yaw about the vertical, with the grasp x axis turned by each of the class's
/// `grasp_yaws_rad` (a parallel-jaw gripper takes a DIP across its body at 0 or on its ends at
/// 90 deg), each modulo the class's `yaw_symmetry`; the best of them counts. The tool's z axis
/// may point up (SCARA) or down (a 6-axis arm's approach vector), so it is not compared beyond a
/// tilt tolerance from the vertical.
namespace cell::world {

/// Shape family of a part class (mirrors the IDL enum cell_world_PartShape).
enum class Shape : std::uint8_t {
  kDip,         ///< DIP IC: black body, pins along both long sides
  kRectangle,   ///< flat rectangle length x width x height
  kSquare,      ///< flat square, length == width
  kDisc,        ///< flat disc, length == width == diameter
  kTriangle,    ///< flat equilateral triangle, length = side, width = its height
  kBox,         ///< 3-D box length x width x height
  kPolyhedron,  ///< polyhedron given by a mesh (RAPT blocks)
};

/// "dip", "rectangle", "square", "disc", "triangle", "box", "polyhedron".
std::string_view to_string(Shape shape) noexcept;

/// Inverse of to_string. Errors: kInvalidArgument naming the text and the known shapes.
Result<Shape> shape_from_string(std::string_view text);

/// Package geometry of a dual in-line IC (JEDEC MS-001 for 0.3" rows, MS-011 for 0.6"; values
/// nominal, mm). Pins are numbered counter-clockwise seen from above, pin 1 at the -x end (the
/// notch end) on the -y row: pins 1..n/2 along -y at increasing x, n/2+1..n along +y at
/// decreasing x.
struct DipPackage {
  int pins = 0;                     ///< total pin count, even, 4..64
  double pitch_mm = 2.54;           ///< pin to pin along a row
  double row_spacing_mm = 7.62;     ///< pin-row centre line to centre line ("0.3 inch" package)
  double lead_width_mm = 0.46;      ///< width of a lead below the shoulder (along x)
  double shoulder_width_mm = 1.52;  ///< width of a lead's upper, wide part (along x)
  double lead_thickness_mm = 0.25;  ///< sheet thickness of a lead (across y)
  double standoff_mm = 0.51;        ///< seating plane (the part frame's z = 0) to body bottom
  double body_thickness_mm = 3.30;  ///< body bottom to body top
  double lead_reflectance = 0.6;    ///< tinned leads, seen from above

  /// Centre of pin `pin` (1-based) at the seating plane, in the part frame [mm]. Precondition:
  /// 1 <= pin <= pins (otherwise the origin is returned).
  Eigen::Vector2d pin_centre(int pin) const noexcept;
  /// Across-rows extent of the leads seen from above: row_spacing_mm + lead_thickness_mm.
  double lead_span_mm() const noexcept { return row_spacing_mm + lead_thickness_mm; }
};

/// A polyhedron in the part frame [mm]: faces list vertex indices counter-clockwise seen from
/// outside. Every face is a planar CONVEX polygon (a renderer may fan-triangulate it); the body
/// itself may be non-convex (the RAPT block b3 is an L).
struct Mesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::vector<std::uint32_t>> faces;

  bool empty() const noexcept { return vertices.empty(); }
  /// Ok, or kInvalidArgument naming the face: fewer than 3 vertices, an index out of range, a
  /// non-planar face (> 0.01 mm off its plane), a face whose normal points into the body
  /// (clockwise seen from outside, checked against the centroid), a non-finite vertex.
  Status validate() const;
};

/// An immutable part class. Built by the make_* functions below or from a scene's `classes:`
/// section; shared by parts through std::shared_ptr<const PartClass>. Thread-safe to share.
struct PartClass {
  std::string name;         ///< unique key: "dip14", "ic_7x30", "rapt_b3", ...
  std::string description;  ///< one line for people, with its source
  Shape shape = Shape::kRectangle;
  double length_mm = 0.0;    ///< along part x (disc: diameter; triangle: side)
  double width_mm = 0.0;     ///< along part y (DIP: body width, leads excluded)
  double height_mm = 0.0;    ///< base to top (DIP: standoff + body thickness)
  double reflectance = 0.5;  ///< diffuse reflectance of the top, 0 black .. 1 white matte
  DipPackage dip;            ///< kDip only (dip.pins == 0 otherwise)
  Mesh mesh;                 ///< kPolyhedron only, in the part frame
  /// kPolyhedron: the model's own frame (e.g. the RAPT body frame of digest 003 App. V) in the
  /// part frame, so that v_part = part_T_model * v_model. Identity otherwise.
  Eigen::Isometry3d part_T_model = Eigen::Isometry3d::Identity();
  /// Where the tool point goes to take the part (see the namespace comment).
  Eigen::Isometry3d part_T_grasp = Eigen::Isometry3d::Identity();
  /// n-fold symmetry about the part's z axis for the capture yaw test: 2 (DIP, rectangle, box:
  /// a parallel-jaw grip is the same turned by 180 deg), 4 (square), 3 (triangle), 0 (disc: any
  /// yaw), 1 (polyhedra: none).
  int yaw_symmetry = 1;
  /// Yaws about the part's z axis [rad], in the part frame, at which the cell's grippers can
  /// take the part, each relative to part_T_grasp's own yaw (the tool's x axis turned by it
  /// from the grasp x axis); each also counts at its `yaw_symmetry` copies. Capture takes the
  /// one nearest the tool's yaw. The grippers' opening is not modelled (a 90 deg grasp of a
  /// long part is accepted whatever the jaws' stroke). Built-in defaults: {0, pi/2} for DIPs
  /// (across the body, on its ends), rectangles and boxes with length != width; {0} for
  /// squares and square boxes (yaw_symmetry 4 covers 90 deg), discs, triangles and polyhedra.
  /// Scene key `grasp_yaws_deg`.
  /// Never empty (validate()).
  std::vector<double> grasp_yaws_rad = {0.0};
  /// Outline seen from above (convex hull of the part projected on its base plane, leads
  /// included), counter-clockwise, part frame [mm]. Filled by finalize().
  std::vector<Eigen::Vector2d> footprint;
  /// Points whose convex hull contains the part (box corners, prism vertices, mesh vertices),
  /// part frame [mm]: projected to get the footprint of a tilted part. Filled by finalize().
  std::vector<Eigen::Vector3d> hull_points;

  /// Ok, or kInvalidArgument naming the class and the offending field: a non-finite or
  /// non-positive size, reflectance outside [0, 1], a square/disc with length != width, a DIP
  /// with an odd pin count or pins that do not fit the body length, a polyhedron with a bad
  /// mesh, a grasp pose that is not rigid, an empty or non-finite grasp_yaws_rad.
  Status validate() const;

  /// Fills footprint and hull_points from the shape and sizes (idempotent). The make_*
  /// functions call it; call it after changing sizes by hand.
  void finalize();
};

/// A DIP class: body `length_mm` x `width_mm`, `pins` at 2.54 mm pitch, pin rows
/// `row_spacing_mm` apart (7.62 for the 0.3" package, 10.16 for 0.4", 15.24 for 0.6"; the body
/// is 3.30 mm thick, 3.81 mm from 0.6" on, over a 0.51 mm standoff). Reflectance 0.1 (black
/// epoxy). Grasp: top centre of the body, across it or on its ends (grasp_yaws_rad
/// {0, pi/2}). validate() fails unless pins is even and the pin
/// rows, shoulders included, fit the body length.
PartClass make_dip(std::string name,
                   int pins,
                   double length_mm,
                   double width_mm,
                   double row_spacing_mm,
                   std::string description = {});

/// A flat or 3-D prism class of shape kRectangle, kSquare, kDisc, kTriangle or kBox (for a
/// disc `length_mm` is the diameter and `width_mm` is ignored; for a triangle `length_mm` is
/// the side and width is derived; for a square width is set to length). Grasp: top centre;
/// grasp_yaws_rad {0, pi/2} for a rectangle (of any sides: its yaw_symmetry is 2) or a box
/// with length != width, {0} otherwise (a square box has yaw_symmetry 4).
PartClass make_prism(std::string name,
                     Shape shape,
                     double length_mm,
                     double width_mm,
                     double height_mm,
                     double reflectance,
                     std::string description = {});

/// A polyhedron from a mesh given in its model frame: the part frame is placed at the centre
/// of the mesh's bounding box at its lowest z (the model rests on the plane z = min z), x and y
/// along the model's. length/width/height are the bounding box. Reflectance as given.
PartClass make_polyhedron(std::string name,
                          const Mesh& mesh_model,
                          double reflectance,
                          std::string description = {});

/// A named set of part classes. Copyable; lookups are O(log n). Not thread-safe to modify;
/// const access from several threads is fine.
class Catalogue {
 public:
  /// Every built-in class (README "Catalogue"): dip8 .. dip40 (0.3" and 0.6" packages), the
  /// thesis's ic_6x19 and ic_7x30, generic rectangle/square/disc/triangle/box, and the RAPT
  /// blocks rapt_b1, rapt_b2, rapt_b3 and rapt_case (digest 003 App. V and VI).
  static Catalogue standard();

  /// Adds `cls` (validated, finalized). Errors: kInvalidArgument when invalid or when a class
  /// of that name exists already.
  Status add(PartClass cls);

  /// The class called `name`, or nullptr.
  std::shared_ptr<const PartClass> find(std::string_view name) const;

  /// Every name, sorted.
  std::vector<std::string> names() const;

  /// Names joined by ", " (for error messages).
  std::string list() const;

  std::size_t size() const noexcept { return classes_.size(); }

 private:
  std::map<std::string, std::shared_ptr<const PartClass>, std::less<>> classes_;
};

}  // namespace cell::world
