// Convex pieces of a robot's real geometry and the exact distance between two of them (the tight
// collision model's narrow phase).
//
// A ConvexPiece is a convex polytope in a link frame L, given by its vertices (the convex hull's
// vertices: every point of the piece is a convex combination of them) and the hull's edge graph
// (for hill-climbing support queries). The fitting (mesh_fit.hpp) makes each piece the convex hull
// of a cluster of a link's mesh triangles, so the union of a link's pieces contains its mesh and a
// distance between pieces is never above the distance between the meshes (conservative).
//
// computeConvexDistance is the GJK distance algorithm (Gilbert, Johnson, Keerthi 1988) with the
// signed-volume / Johnson sub-distance on the Minkowski difference A - B:
//   distance  the Euclidean distance between the two solids (0 when they touch or overlap, or are
//             closer than the tolerance below; then `penetrating` is true and the witness points are
//             one common point, distance 0)
//   p_B_a     the point of A closest to B, p_B_b the point of B closest to A, both in the base frame B,
//             so p_B_a - p_B_b has length `distance` and points from B towards A (distance.hpp's sign
//             convention: nhat = (p_a - p_b) / d).
// Allocation-free and noexcept: fixed-size simplex, hill-climbing support over the edge graph
// (falls back to a linear scan of the vertices when a piece has no graph); never returns NaN for
// finite inputs. Accuracy: |distance - exact| <= max(kConvexTolerance, 1e-9 * size) for pieces of
// finite size, where size is the largest |p_a - p_b| over the vertex pairs the search met (the pair's
// extent in B); the reported distance is never below the exact one by more than rounding, since the
// witness points are points of the pieces.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <array>
#include <limits>
#include <vector>

namespace reflex::control {

/// Absolute tolerance of computeConvexDistance's termination (m).
inline constexpr double kConvexTolerance = 1e-9;

/// A convex polytope in a link frame. Invariants: at least one vertex; neighbor_begin has
/// vertices_L.size() + 1 entries (empty when there is no edge graph); neighbors[neighbor_begin[i] ..
/// neighbor_begin[i+1]) are the vertices sharing a hull edge with vertex i; every vertex lies within
/// bound_radius of bound_center_L.
struct ConvexPiece {
  std::vector<Eigen::Vector3d> vertices_L;
  std::vector<int> neighbor_begin;
  std::vector<int> neighbors;
  Eigen::Vector3d bound_center_L = Eigen::Vector3d::Zero();
  double bound_radius = 0.0;
  /// Where a support query without a better start begins: the support vertex in each of the 14
  /// directions of kStartDirections (the six axes, the eight diagonals), so the climb is short. Any
  /// entry is correct (the climb finds the maximum from any vertex); these only make it fast.
  std::array<int, 14> start_vertex{};
};

/// The principal axes of a point set: the columns, by ascending variance, each signed so that its
/// largest component is positive (the same axes whichever eigen solver ran). Needs one point.
Eigen::Matrix3d principalAxes(const std::vector<Eigen::Vector3d>& pts);

/// The 14 directions of ConvexPiece::start_vertex (unnormalized: the axes and the cube's diagonals).
inline constexpr std::array<std::array<double, 3>, 14> kStartDirections = {{{1, 0, 0},
                                                                            {-1, 0, 0},
                                                                            {0, 1, 0},
                                                                            {0, -1, 0},
                                                                            {0, 0, 1},
                                                                            {0, 0, -1},
                                                                            {1, 1, 1},
                                                                            {1, 1, -1},
                                                                            {1, -1, 1},
                                                                            {1, -1, -1},
                                                                            {-1, 1, 1},
                                                                            {-1, 1, -1},
                                                                            {-1, -1, 1},
                                                                            {-1, -1, -1}}};

/// The vertex a support query of `piece` in direction d_L starts from: the start vertex of the
/// direction of kStartDirections nearest d_L (largest cosine). Allocation-free.
int startVertex(const ConvexPiece& piece, const Eigen::Vector3d& d_L) noexcept;

/// Builds a ConvexPiece from its hull vertices and the hull's triangles (indices into `vertices`):
/// the edge graph from the triangles' edges, the bounding sphere (centre: the vertices' box centre).
/// Triangles may be empty: a flat set of at least 4 points (a mesh's planar face, which a hull program
/// refuses; within 1e-12 m of one plane) keeps only its polygon's corners, each joined to the next;
/// any other set gets no graph (support queries scan every vertex). Throws std::invalid_argument
/// for no vertex, a non-finite vertex or a triangle index out of range.
ConvexPiece makeConvexPiece(const std::vector<Eigen::Vector3d>& vertices,
                            const std::vector<std::array<int, 3>>& triangles);

/// The result of computeConvexDistance (see the opening block).
struct ConvexDistance {
  double distance = 0.0;
  Eigen::Vector3d p_B_a = Eigen::Vector3d::Zero();
  Eigen::Vector3d p_B_b = Eigen::Vector3d::Zero();
  bool penetrating = false;
  /// The search stopped once it proved the distance above `stop_above`: `distance` is then a lower
  /// bound of it (a separating plane's gap less the tolerance, > stop_above), the witness points are
  /// not computed.
  bool above = false;
  int iterations = 0;  ///< GJK iterations: support queries after the initial point (at most 64)
};

/// Per-call scratch that survives between calls (warm start): the last support vertices of each
/// piece, so a query on slowly moving pieces starts near its answer. One per (piece a, piece b)
/// pair, or one shared (then without benefit). Plain data: copying never allocates.
struct ConvexWarmStart {
  int vertex_a = 0;
  int vertex_b = 0;
};

/// What a pair of pieces remembers for its next search (computeConvexDistance's `hint`). Only the
/// work depends on it: a computed distance is the same bits with or without it.
struct ConvexHint {
  /// A direction that proved the pair far (A's link frame, from A towards B; zero: none).
  Eigen::Vector3d axis = Eigen::Vector3d::Zero();
  /// A's and B's support vertices along the last search's first direction (-1: none): the next
  /// search's first climbs start there.
  int vertex_a = -1;
  int vertex_b = -1;
};

/// The distance between piece A placed by X_B_A (L_A -> B) and piece B placed by X_B_B. See the
/// opening block. `warm` may be nullptr (each piece's climb then starts at its start_vertex, in the
/// direction `towards_b` (frame B, from A towards B; zero: from A's bounding centre to B's), a good
/// guess of the separating direction shortening the search). With a finite `stop_above` the search ends as soon as a separating
/// plane proves the distance above it (ConvexDistance::above): a caller that only needs the pieces
/// closer than a bound (the closest of several, a pruning distance) skips most of the work on the
/// others. A distance at most stop_above is computed exactly as without it (the same operations).
/// `hint` (may be nullptr) is what the last search of this pair of pieces left. A cold search with a
/// finite stop_above climbs to its first support pair from the hint's vertices (pieces that moved a
/// little: a step or none); if that pair does not prove the distance above stop_above, it tries the
/// hint's axis (any direction's gap is a lower bound), then goes on exactly as without a hint (the
/// first support pair climbed again from the start vertices): a computed distance is the same bits
/// with or without it, only the lower bound of a pair proven far may differ. On return the hint
/// holds the direction that proved the distance above stop_above (zero: a distance computed, or
/// contact) and the first support pair. Allocation-free; never throws.
ConvexDistance computeConvexDistance(const ConvexPiece& a, const Eigen::Isometry3d& X_B_A, const ConvexPiece& b,
                                     const Eigen::Isometry3d& X_B_B, ConvexWarmStart* warm = nullptr,
                                     double stop_above = std::numeric_limits<double>::infinity(),
                                     const Eigen::Vector3d& towards_b = Eigen::Vector3d::Zero(),
                                     ConvexHint* hint = nullptr) noexcept;

/// The support point of `piece` in direction d_L (link frame): the vertex maximising d_L . v. `start`
/// is the vertex index to hill-climb from (clamped); returns the index found.
int supportVertex(const ConvexPiece& piece, const Eigen::Vector3d& d_L, int start) noexcept;

}  // namespace reflex::control
