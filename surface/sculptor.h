#pragma once
// Incremental sculpting of a 2-manifold surface in a 3D Delaunay triangulation (Litvinov and
// Lhuillier, BMVC 2013, sections 3–5). The input is the keyframe stream of DESIGN.md §4; the
// output is δO, the border of the carved free space O, as a triangle mesh oriented towards O.

#include <Eigen/Core>
#include <memory>
#include <string>
#include <vector>

#include "calib/ids.h"
#include "calib/ply.h"
#include "surface/delaunay.h"

namespace omni {

// A ray of a point: the keyframe that observed it and the optical centre it starts from
// (the keyframe centre in central mode, the observing camera's centre otherwise).
struct SurfaceRay {
  KeyframeId keyframe;
  Eigen::Vector3d origin = Eigen::Vector3d::Zero();
};

struct SurfacePoint {
  PointId id;
  Eigen::Vector3d position = Eigen::Vector3d::Zero();
  std::vector<SurfaceRay> rays;
};

// The only sfm→surface contract (DESIGN.md §4): the points P_t of keyframe t.
struct SurfaceKeyframe {
  KeyframeId id;
  Eigen::Vector3d centre = Eigen::Vector3d::Zero();  // c_t
  std::vector<SurfacePoint> points;
};

// The enclosing set E of paper §4.1, which O is shrunk out of before the new points go in.
enum class EnclosingMode {
  kBall,           // the paper: the cells inside B_{r+l}(c_{t+1})
  kConflictZones,  // the paper's future work (§6): the union D of the conflict zones of the new
                   // points (found without inserting them) plus enclosing_margin rings of cells
};

struct SculptorOptions {
  // s, the mean distance between consecutive keyframe centres; 0: measured on the first
  // init_keyframes keyframes (paper §5.1).
  double scale = 0.0;
  // Step of the Steiner grid in units of s (paper §5.1: 15 s). The tetrahedra diameter bound
  // l of §3.3 is the voxel diagonal.
  double steiner_step_factor = 15.0;
  // r of §3.3 in units of s: points farther than r from their keyframe centre are filtered
  // out (paper §5.1: ‖p − c_t‖ ≤ 15 s).
  double max_ray_length_factor = 15.0;
  // Point filters of §5.1.
  bool filter_points = true;
  double below_ground_factor = 3.0;  // reject (p − c_t)·up < −3 s
  double min_aperture_deg = 10.0;    // keep points with two rays forming more than 10°
  Eigen::Vector3d up = Eigen::Vector3d::UnitZ();  // the vertical direction v of §5.1
  // The first init_keyframes keyframes measure s; with batch_init they are sculpted at once
  // (paper §5.1: T_40, F_40, O_40), otherwise one by one like the others.
  int init_keyframes = 40;
  bool batch_init = true;
  EnclosingMode enclosing = EnclosingMode::kBall;
  int enclosing_margin = 2;  // kConflictZones: rings of neighbouring cells added around D
  // Stop re-traced old rays (§4.4) after the last point where they can meet a new cell, instead
  // of walking them whole; the counters are the same either way.
  bool clip_old_rays = true;
  // With clip_old_rays, also start each re-traced old ray at the cell holding a point just
  // before the first new cell's box it meets (located with CGAL from that cell) instead of at
  // its point's vertex; exact (same counters), but measured slower on the street benchmark
  // (locating costs more than the skipped part of these short walks), hence off.
  bool locate_old_ray_start = false;
  // Several-at-once passes (paper §4.5, §4.7): at most this many sweeps over the vertices of
  // the enclosing set per keyframe.
  int max_vertex_passes = 4;

  std::string Check() const;
};

// One row per processed keyframe (the batch initialisation is one row, batch = true).
struct KeyframeStats {
  KeyframeId keyframe;
  bool batch = false;
  size_t points_in = 0;         // points received
  size_t points_filtered = 0;   // removed by the §5.1 filters
  size_t points_added = 0;      // inserted in T
  size_t points_rejected = 0;   // conflict zone met O (§4.3)
  size_t points_duplicate = 0;  // equal to an existing vertex
  size_t steiner_added = 0;
  size_t rays_new = 0;                           // rays of the new points, traced fully
  size_t rays_old = 0;                           // older rays re-traced over N (§4.4)
  size_t cells_e = 0;                            // |E|
  size_t cells_n = 0;                            // |N|
  size_t o_left_in_e = 0;                        // |O ∩ E| after shrinking
  size_t cells_t = 0, cells_f = 0, cells_o = 0;  // finite cells of T, F, O after the keyframe
  size_t triangles = 0;                          // triangles of δO
  double ms_steiner = 0, ms_enclose = 0, ms_shrink = 0, ms_insert = 0, ms_rays = 0, ms_grow = 0,
         ms_total = 0;
};

std::string KeyframeStatsCsvHeader();
std::string KeyframeStatsCsvRow(const KeyframeStats& stats);

class IncrementalSculptor {
 public:
  explicit IncrementalSculptor(const SculptorOptions& options = {});
  ~IncrementalSculptor();

  // Takes the next keyframe. The first init_keyframes are buffered until s is known; returns
  // the stats of the keyframes this call processed (none while buffering).
  std::vector<KeyframeStats> AddKeyframe(const SurfaceKeyframe& keyframe);
  // Processes what is still buffered (a stream shorter than init_keyframes).
  std::vector<KeyframeStats> Finish();

  // δO, triangles counter-clockwise seen from the free space.
  TriangleMesh ExtractMesh() const;
  const DelaunayMesh& triangulation() const;
  double scale() const;  // s, 0 until known
  size_t NumProcessedKeyframes() const;

  // Invariants for tests and debugging: O ⊆ F, no infinite cell in O, the incremental counts
  // of O, F and δO equal recounts, T valid (expensive). Empty when all hold.
  std::string CheckInvariants(bool check_triangulation = true) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace omni
