// Collision meshes to capsules: loading a link's collision meshes, fitting
// sphere-swept lines (capsules) and spheres that ENCLOSE every vertex, and the fit overlay
// (`<urdf stem>.fit.yaml`) that caches the result next to the robot. README: "Meshes".
//
// The guarantee: every vertex of every mesh and box element of a fitted link (in the link frame,
// with the element's origin and scale) lies inside one of the link's fitted primitives, and every
// triangle lies inside one primitive (a capsule is convex; triangles are assigned whole to a
// cluster, long ones subdivided first). A box element is fitted on its own (fitBox): a grid of
// cells, each inside its own capsule, so the whole box is inside. So a pair distance computed on the fitted primitives never
// exceeds the true mesh distance: the fit is conservative.
//
// Mesh files are read with assimp (STL, OBJ, DAE and whatever else assimp reads): triangulated, the
// node hierarchy pre-transformed, COLLADA <unit> applied (metres) and COLLADA <up_axis> IGNORED, as
// ROS tools do (RViz, MoveIt's geometric_shapes): a DAE authored Z_UP comes out in the URDF's frame,
// unrotated. Units: metres everywhere.
//
// Extending: a new primitive kind needs a fit (fitCluster in mesh_fit.cpp), a volume, a surface
// sampler for the gap, and an overlay key.
#pragma once

#include "reflex/control/model.hpp"

#include <array>
#include <cstdint>
#include <functional>
#include <map>
#include <string>
#include <vector>

namespace reflex::control {

/// A triangle mesh in one frame (metres).
struct TriangleMesh {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;  ///< indices into vertices
};

/// Where `package://NAME/...` URIs are looked up: `packages` first (NAME -> folder, from
/// --package-path NAME=DIR), then the folders of ROS_PACKAGE_PATH (colon-separated) when
/// `use_ros_package_path`: a folder there, or one of its direct children, that is named NAME or whose
/// package.xml has <name>NAME</name>.
struct PackagePaths {
  std::map<std::string, std::string> packages;
  bool use_ros_package_path = true;
};

/// Resolves a URDF mesh filename to a file path: `package://NAME/rel` (PackagePaths), `file:///abs`,
/// an absolute path, or a path relative to `urdf_dir`. Returns "" and sets `why` (naming the package
/// or the path tried) when it cannot; does not check that the file is readable.
std::string resolveMeshFilename(const std::string& filename, const std::string& urdf_dir, const PackagePaths& paths,
                                std::string* why);

/// Reads a mesh file with assimp (see the opening block) and multiplies every vertex by `scale`.
/// Throws ModelError naming the file and assimp's reason (unreadable, not a mesh, no triangles).
TriangleMesh loadMeshFile(const std::string& path, const Eigen::Vector3d& scale);

/// loadMeshFile's limits: more triangles in one file, or a vertex coordinate (after scale) beyond this
/// or not finite, is a ModelError naming the file (and the vertex).
inline constexpr std::size_t kMaxMeshTriangles = 200000;
inline constexpr double kMaxMeshCoordinate = 10.0;  ///< m, as every URDF length (kMaxUrdfLength)

/// Fitting options. The defaults are what reflex_fit uses.
struct FitOptions {
  int max_primitives = 6;  ///< per link's meshes (greedy cuts), and per box element (fitBox)
  /// Split a link's cluster while (sum of fitted volumes) / (convex-hull volume) is above this...
  double split_ratio = 1.3;
  /// ...and a split reduces the summed fitted volume by at least this fraction of it.
  double min_split_gain = 0.05;
  double quantum = 1e-6;                ///< m: written coordinates are multiples of it, radii rounded up
  int gap_samples_per_primitive = 600;  ///< surface samples per primitive for the worst gap
  /// The tight model (fitConvexPieces): a link's mesh is cut into at most this many convex pieces...
  int max_pieces = 16;
  /// ...while a piece's surface stands off the mesh surface by more than this (m, its worst gap).
  double piece_gap = 0.004;
  /// Beyond max_pieces, a piece whose gap is above large_gap is still cut, up to this many pieces:
  /// the few links (a shell open at the neck, a deep concavity) where 16 pieces leave centimetres.
  int max_pieces_large_gap = 48;
  double large_gap = 0.020;  ///< m
};

/// Per-link numbers of a fit (what the overlay records and reflex_fit prints).
struct FitStats {
  int vertices = 0;           ///< mesh + box vertices of the link (after scale and origin)
  int vertices_enclosed = 0;  ///< of those, inside a fitted primitive (re-checked after rounding)
  int triangles = 0;
  double hull_volume = 0.0;    ///< m^3, convex hull of all vertices (qhull); 0 for a flat set
  double fitted_volume = 0.0;  ///< m^3, sum of the primitives' volumes (an upper bound of their union)
  double volume_ratio = 0.0;   ///< fitted / hull; 0 when the hull volume is 0
  double worst_gap = 0.0;      ///< m, largest distance from a sampled point of the primitives'
                               ///< outer surface (not inside another primitive) to the mesh
};

/// One convex piece of a link (the tight model, convex.hpp): the convex hull of a cluster of the
/// link's mesh triangles (or a box element), and the capsule that encloses it (the broad phase's
/// bound). `vertices` are the hull's vertices (mesh vertices, never rounded: the hull contains the
/// cluster exactly), `triangles` its facets (indices into vertices; empty for a flat or tiny piece).
struct PieceFit {
  std::vector<Eigen::Vector3d> vertices;
  std::vector<std::array<int, 3>> triangles;
  Primitive capsule;
};

/// Cuts `mesh` (link frame) into convex pieces whose union contains it, until every piece's worst gap
/// is at most options.piece_gap or there are options.max_pieces (then on while a gap is above
/// options.large_gap, up to options.max_pieces_large_gap; mesh_fit.cpp, "Convex pieces", says how). `worst_gap` (if set): the largest remaining gap (m). Deterministic. Throws ModelError for an
/// empty mesh, a bad index or a non-finite vertex.
std::vector<PieceFit> fitConvexPieces(const TriangleMesh& mesh, const FitOptions& options, double* worst_gap);

/// The smallest capsule (or sphere) found that encloses every point, end points rounded to
/// options.quantum and the radius rounded up so that it still does. Throws ModelError for no point.
Primitive enclosingCapsule(const std::vector<Eigen::Vector3d>& points, const FitOptions& options);

/// The numbers of FitStats for `pieces` fitted to `mesh`: vertices enclosed (inside a piece's hull
/// within 1 nm), the mesh's hull volume, the pieces' summed hull volume and its ratio, `worst_gap` as
/// fitConvexPieces measured it.
FitStats measurePieces(const TriangleMesh& mesh, const std::vector<PieceFit>& pieces, double worst_gap);

/// A box element (edge lengths `size`, pose X_L_B in the link frame) as one exact convex piece.
PieceFit boxPiece(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B, const FitOptions& options);

/// Fits primitives (link frame) enclosing every vertex and triangle of `mesh`. Deterministic: the
/// same mesh and options give the same primitives, bit for bit. Throws ModelError for an empty mesh.
std::vector<Primitive> fitPrimitives(const TriangleMesh& mesh, const FitOptions& options, FitStats* stats);

/// The numbers of FitStats for `prims` fitted to `mesh` (vertices enclosed, volumes, worst gap).
/// `hull_volume` < 0: the convex hull of the mesh's vertices is computed (qhull).
FitStats measureFit(const TriangleMesh& mesh, const std::vector<Primitive>& prims, const FitOptions& options,
                    double hull_volume = -1.0);

/// The 8 corners and 12 triangles of a box of edge lengths `size` (m) centred on the origin of frame
/// B, in frame L.
TriangleMesh boxMesh(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B);

/// Fits a box (edge lengths `size` in m, centred on frame B, X_L_B its pose in the link frame L) with
/// primitives in L that enclose it whole: the box is cut into a grid of n1 x n2 equal cells across one
/// of its axes (all three tried, n1 * n2 <= options.max_primitives), one capsule (or sphere) per cell
/// along that axis, its radius and core length chosen for the least volume (a larger radius shortens
/// the core). From one cell up, the step to more cells that saves the most volume per added primitive
/// is taken while it saves at least options.min_split_gain of the volume (none once the volume is
/// within options.split_ratio of the box's). End points are rounded to
/// options.quantum and each radius recomputed from its cell's 8 corners and rounded up, so every
/// cell, and so the box, is inside. A flat box (a foot sole) gets several capsules side by side where
/// its single enclosing capsule would be 3 to 4.5 times its volume. Deterministic. Throws ModelError
/// for a size that is not positive and finite.
std::vector<Primitive> fitBox(const Eigen::Vector3d& size, const Eigen::Isometry3d& X_L_B, const FitOptions& options);

/// Distance from p to the primitive's surface (negative inside).
double signedDistanceToPrimitive(const Primitive& prim, const Eigen::Vector3d& p);

/// One fitted link of the overlay.
struct LinkFit {
  std::string link;
  std::string inputs;  ///< hash of the inputs (fitInputsHash)
  int elements = 0;    ///< mesh and box elements fitted
  FitStats stats;
  std::vector<Primitive> primitives;  ///< link frame
  /// The tight model (format 2 overlays): pieces[i] is the convex piece primitives[i] encloses (the
  /// same count); empty for a capsule-only fit (format 1).
  std::vector<PieceFit> pieces;
};

/// A fit overlay: every link with mesh or box collision elements, fitted.
struct FitOverlay {
  std::string urdf;                             ///< as written (relative to the overlay's folder)
  std::string urdf_dir;                         ///< resolved, for relative mesh paths
  std::map<std::string, std::string> packages;  ///< NAME -> folder (resolved when read)
  FitOptions options;
  std::vector<LinkFit> links;
  std::string source;  ///< the overlay file, for messages
};

/// "dir/robot.urdf" -> "dir/robot.fit.yaml".
std::string defaultFitOverlayPath(const std::string& urdf_path);

/// Fits every link of the URDF with mesh or box collision elements. Throws ModelError naming every
/// unresolved or unreadable mesh in one message. `progress` (if set) gets one line per link.
FitOverlay fitRobot(const std::string& urdf_path, const PackagePaths& paths, const FitOptions& options,
                    const std::function<void(const std::string&)>& progress = {});

/// Every link's mesh and box collision elements as one triangle mesh in the link frame (the input
/// fitRobot fits), read the same way. Throws ModelError as fitRobot does.
std::map<std::string, TriangleMesh> linkCollisionMeshes(const std::string& urdf_path, const PackagePaths& paths);

/// Whether two meshes (placed by X_B_A and X_B_B) intersect: a triangle of one crosses a triangle of
/// the other, or a vertex of one lies inside the other (generalized winding number >= 0.95, as for a
/// closed mesh). Errs towards "apart" (coplanar overlaps are not seen), never towards "intersecting".
bool meshesIntersect(const TriangleMesh& a, const Eigen::Isometry3d& X_B_A, const TriangleMesh& b,
                     const Eigen::Isometry3d& X_B_B);

/// The overlay's text (YAML). Reproducible: same overlay, same bytes. Paths are written relative to
/// the folder of `overlay_path`.
std::string fitOverlayText(const FitOverlay& overlay, const std::string& overlay_path);

/// Reads an overlay written by fitOverlayText. Throws ModelError naming the file and the bad entry.
FitOverlay loadFitOverlay(const std::string& overlay_path);

}  // namespace reflex::control
